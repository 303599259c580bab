"""The two-point task: two points on a line, sequential or parallel by a context feature.

``task`` (:class:`SyntheticTask`: the world, its demonstrator and closed loop), ``policy``
(:class:`TwoPointFeaturePolicy`, the scripted policy that reads only the features),
``registered`` (:class:`TwoPointWorld`, the task behind :class:`~cpmp.worlds.protocol.World`).
"""

from cpmp.worlds.two_point.policy import TwoPointFeaturePolicy
from cpmp.worlds.two_point.task import (
    FEATURE_NAMES,
    VARIABLES,
    SyntheticTask,
    TwoPointEpisode,
    TwoPointRollout,
    curved_trajectories,
    evaluate,
    make_demonstrations,
)

__all__ = [
    "FEATURE_NAMES",
    "VARIABLES",
    "SyntheticTask",
    "TwoPointEpisode",
    "TwoPointFeaturePolicy",
    "TwoPointRollout",
    "curved_trajectories",
    "evaluate",
    "make_demonstrations",
]
