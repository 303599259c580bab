"""Task configuration of the simulated pick-and-place evaluation (paper Sec. IV).

:class:`TaskConfig` is defined in :mod:`cpmp.config.task` (the schema of ``conf/task/``, which
holds no values of its own) so that it can be read without importing MuJoCo; this module
re-exports it for the simulator.
"""

from __future__ import annotations

from cpmp.config.task import TaskConfig

__all__ = ["TaskConfig"]
