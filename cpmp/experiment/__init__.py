"""Experiment outputs: rerun recordings of episodes (:mod:`cpmp.experiment.recording`) and the
paper's figures (:mod:`cpmp.experiment.plots`).

Both submodules import their heavy dependencies (rerun, matplotlib) lazily or on import of the
submodule itself, so ``import cpmp.experiment`` stays cheap.
"""
