"""The predictor comparison (``cpmp-compare``), a job of its own beside the main one.

Progress predictors and the sequencing baselines run on the same demonstrations, seeds and
episodes in several worlds, plus a support-count axis; every number comes with a bootstrap
interval and every difference between rows with a paired one. ``settings`` (the ``compare``
config node and its schema), ``worlds`` (the simulator's variants and the synthetic worlds),
``rows`` (which configurations are compared, and their fits), ``runs`` (one (world, seed,
row, D) job and the scheduler), ``stats`` (bootstrap intervals and paired differences),
``pooling`` (rows, pairs and claims with their intervals: ``compare.json``), ``report``
(``compare.md``), ``figures`` (its figures), ``job`` (:func:`~cpmp.compare.job.run_compare`,
all of them in turn).

Submodules import their dependencies themselves: ``import cpmp.compare.settings`` costs Hydra,
OmegaConf and the synthetic worlds only (the command line registers the schema with it),
``cpmp.compare.job`` costs torch, MuJoCo and matplotlib.
"""
