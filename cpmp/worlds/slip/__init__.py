"""The slip task: a pick that may slip mid-lift and is retried, into a drawer held open.

``world`` (:class:`SlipTask`, the options and dynamics; :class:`SlipRun`, a run),
``demonstrator`` (the feature-guarded demonstrator and its demonstrations), ``policy`` (the
feature-only scripted policy), ``registered`` (:class:`SlipWorld`, the
:class:`~cpmp.worlds.protocol.World`).
"""

from cpmp.worlds.slip.demonstrator import demonstrate, make_contexts, make_demonstrations
from cpmp.worlds.slip.policy import ScriptedSlipPolicy
from cpmp.worlds.slip.registered import SlipWorld
from cpmp.worlds.slip.world import (
    FEATURE_NAMES,
    MPS,
    STRATEGIES,
    VARIABLES,
    SlipContext,
    SlipRun,
    SlipState,
    SlipTask,
)

__all__ = [
    "FEATURE_NAMES",
    "MPS",
    "STRATEGIES",
    "VARIABLES",
    "ScriptedSlipPolicy",
    "SlipContext",
    "SlipRun",
    "SlipState",
    "SlipTask",
    "SlipWorld",
    "demonstrate",
    "make_contexts",
    "make_demonstrations",
]
