"""Offline evaluation of a fitted sequencer on recorded demonstrations.

Progress error against eq. 1 (Fig. 6), switch distances (Table Ib) and open-loop replay of
demonstrations (``offline``), and loading any sequencer checkpoint to evaluate it
(``checkpoints``).
"""

from cpmp.evaluation.checkpoints import load_sequencer
from cpmp.evaluation.offline import (
    ActivationProgress,
    DemoReplay,
    OfflineEvaluation,
    ProgressCurves,
    ProgressErrors,
    ReplaySummary,
    VariableReplay,
    activation_progress,
    continuous_features,
    evaluate_offline,
    progress_curves,
    progress_errors,
    replay_demonstrations,
    stream_progress,
    switch_distances,
)

__all__ = [
    "ActivationProgress",
    "DemoReplay",
    "OfflineEvaluation",
    "ProgressCurves",
    "ProgressErrors",
    "ReplaySummary",
    "VariableReplay",
    "activation_progress",
    "continuous_features",
    "evaluate_offline",
    "load_sequencer",
    "progress_curves",
    "progress_errors",
    "replay_demonstrations",
    "stream_progress",
    "switch_distances",
]
