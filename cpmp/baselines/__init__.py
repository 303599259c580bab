"""Sequencing baselines that need no learned progress predictor.

:class:`GoalNearestSequencer` (``goal_nearest``) switches a variable once its MP has converged
and picks the successor whose demonstrated entry states lie nearest the current features
(Pastor et al. / Niekum et al. style); :class:`GoalNearestBatch` (``batch``) runs ``N`` of its
episodes with the batched interface of the learned sequencer; :class:`NearestProgress`
(``nearest_progress``) is its nearest-neighbour progress, for offline evaluation. They share the
sequencer's ``reset`` / ``step`` / ``save`` / ``load`` surface, as does :class:`BCSequencer`
(``bc``), behaviour cloning: per variable and MP a kernel classifier of stay / successor
trained on every demonstrated tick.
"""

from cpmp.baselines.batch import GoalNearestBatch, SingleEpisodePolicy
from cpmp.baselines.bc import BCSequencer
from cpmp.baselines.goal_nearest import GoalNearestSequencer
from cpmp.baselines.nearest_progress import NearestProgress

__all__ = [
    "BCSequencer",
    "GoalNearestBatch",
    "GoalNearestSequencer",
    "NearestProgress",
    "SingleEpisodePolicy",
]
