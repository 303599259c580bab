"""The relay task: a hand-over in the plane between a carrier and a receiver with a gripper.

``world`` (:class:`RelayTask`, the closed-loop world), ``demonstrator`` (the scripted
demonstrator and :func:`make_demonstrations`), ``evaluation`` (rollouts and their outcomes),
``varied`` (the task with MPs at varied speeds and holds mid-MP, :func:`varied.paced_relay`).
"""

from cpmp.worlds.relay.demonstrator import ScriptedPolicy, demonstrate, make_demonstrations
from cpmp.worlds.relay.evaluation import OUTCOMES, RolloutResult, evaluate, rollout
from cpmp.worlds.relay.world import FEATURE_NAMES, STRATEGIES, VARIABLES, RelayTask

__all__ = [
    "FEATURE_NAMES",
    "OUTCOMES",
    "STRATEGIES",
    "VARIABLES",
    "RelayTask",
    "RolloutResult",
    "ScriptedPolicy",
    "demonstrate",
    "evaluate",
    "make_demonstrations",
    "rollout",
]
