"""The predictor comparison (``cpmp-compare``), a job of its own beside the main one.

Every progress predictor and the sequencing baselines run on the same demonstrations, seeds
and boxes, plus a support-density sweep. ``settings`` (the ``compare`` config node and its
schema), ``rows`` (which configurations are compared, and their fits), ``runs`` (one (seed,
row, D) fit-and-reproduce and the scheduler), ``report`` (pooled rows, ``compare.md`` and its
figures), ``job`` (:func:`~cpmp.compare.job.run_compare`, all of them in turn).

Submodules import their dependencies themselves: ``import cpmp.compare.settings`` costs Hydra
and OmegaConf only (the command line registers the schema with it), ``cpmp.compare.job``
costs torch, MuJoCo and matplotlib.
"""
