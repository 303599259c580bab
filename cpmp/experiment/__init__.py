"""The main job (``cpmp-experiment``): the paper's evaluation with the simulator in front.

One module per stage, run in turn by ``jobs``: ``collection`` (scripted demonstrations and
splits), ``fitting`` (a sequencer per training size), offline progress error
(:mod:`cpmp.evaluation`), ``reproduction`` (closed-loop episodes, Table I), ``strategies``
(the start-strategy map, Fig. 7), ``report`` (seeds pooled, ``report.json`` / ``report.md``,
figures from ``plots``). ``settings`` says what a job is, ``config`` registers the schemas
with Hydra and types a composed config, ``executors`` runs the seeds and sizes (in this
process, spawned processes or submitit jobs: local or SLURM), ``checkpoint_jobs`` are
``cpmp-train`` / ``cpmp-evaluate`` for your own data.

Submodules import their heavy dependencies themselves, so ``import cpmp.experiment`` is cheap.
"""

from cpmp.errors import require as _require

_require("hydra", "jobs", "cpmp.experiment (the main job)")
_require("matplotlib", "jobs", "cpmp.experiment (the main job)")
_require("tqdm", "jobs", "cpmp.experiment (the main job)")
