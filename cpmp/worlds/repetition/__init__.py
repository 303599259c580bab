"""The repetition task: a cycle run once, twice or three times, as a quantity in the state says.

A ladle's ``scoop -> pour`` cycle repeats while soup remains to pour; a helper waits holding
the bowl across every repetition.

``world`` (:class:`RepetitionTask`, the closed-loop world), ``demonstrator`` (the scripted
demonstrator and :func:`make_demonstrations`), ``evaluation`` (rollouts and their outcomes).
"""

from cpmp.worlds.repetition.demonstrator import ScriptedPolicy, demonstrate, make_demonstrations
from cpmp.worlds.repetition.evaluation import OUTCOMES, RolloutResult, evaluate, rollout
from cpmp.worlds.repetition.world import (
    FEATURE_NAMES,
    REPETITIONS,
    STRATEGIES,
    VARIABLES,
    RepetitionEpisode,
    RepetitionState,
    RepetitionTask,
)

__all__ = [
    "FEATURE_NAMES",
    "OUTCOMES",
    "REPETITIONS",
    "STRATEGIES",
    "VARIABLES",
    "RepetitionEpisode",
    "RepetitionState",
    "RepetitionTask",
    "RolloutResult",
    "ScriptedPolicy",
    "demonstrate",
    "evaluate",
    "make_demonstrations",
    "rollout",
]
