"""Alias of :mod:`cpmp.worlds.two_point`, kept so that code written against cpmp 0.1 still runs.

New code imports the synthetic tasks from :mod:`cpmp.worlds`
(``from cpmp.worlds.two_point import make_demonstrations``).
"""

from cpmp.worlds.two_point import (
    FEATURE_NAMES,
    VARIABLES,
    SyntheticTask,
    curved_trajectories,
    evaluate,
    make_demonstrations,
)

__all__ = [
    "FEATURE_NAMES",
    "VARIABLES",
    "SyntheticTask",
    "curved_trajectories",
    "evaluate",
    "make_demonstrations",
]
