"""The predictor comparison (``cpmp-compare``): every progress predictor and the sequencing
baselines on the same demonstrations, seeds and boxes, plus a support-density sweep.

``settings`` (the ``compare`` config node), ``job`` (the rows and :func:`run_compare`),
``runs`` (one (seed, row, D) fit-and-reproduce and the scheduler), ``report`` (pooled rows,
``compare.md`` and its figures).
"""
