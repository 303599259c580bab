"""Sequencing baselines that need no learned progress predictor.

:class:`GoalNearestSequencer` (``goal_nearest``) switches a variable once its MP has converged
and picks the successor whose demonstrated entry states lie nearest the current features
(Pastor et al. / Niekum et al. style); ``nearest_progress`` holds its nearest-neighbour progress.
They share the sequencer's ``reset`` / ``step`` / ``save`` / ``load`` surface.
"""

from cpmp.baselines.goal_nearest import GoalNearestSequencer
from cpmp.baselines.nearest_progress import NearestProgress

__all__ = ["GoalNearestSequencer", "NearestProgress"]
