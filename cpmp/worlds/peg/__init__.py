"""The peg task: a reactive peg-in-hole insertion retrying after jams, a helper holding the base.

``world`` (:class:`PegTask`: options, contexts, dynamics, features), ``demonstrator`` (the
scripted demonstrator's switches and demonstrations), ``policy`` (the feature-only scripted
policy), ``registered`` (:class:`PegWorld`, the :class:`~cpmp.worlds.protocol.World`).
"""

from cpmp.worlds.peg.demonstrator import demonstrate, switches
from cpmp.worlds.peg.policy import FeaturePolicy
from cpmp.worlds.peg.registered import PegRun, PegWorld
from cpmp.worlds.peg.world import (
    FEATURE_NAMES,
    MPS,
    STRATEGIES,
    VARIABLES,
    PegContext,
    PegState,
    PegTask,
)

__all__ = [
    "FEATURE_NAMES",
    "MPS",
    "STRATEGIES",
    "VARIABLES",
    "FeaturePolicy",
    "PegContext",
    "PegRun",
    "PegState",
    "PegTask",
    "PegWorld",
    "demonstrate",
    "switches",
]
