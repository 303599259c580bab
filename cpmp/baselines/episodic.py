"""What the sequencing baselines share: batches, replay and their offline progress.

:class:`EpisodicBaseline` is the part of :class:`~cpmp.baselines.GoalNearestSequencer` and
:class:`~cpmp.baselines.bc.BCSequencer` that does not depend on how they switch: ``N``
independent episodes (:meth:`EpisodicBaseline.batched`), an open-loop replay, and the
nearest-neighbour progress (:class:`~cpmp.baselines.NearestProgress`) that offline
evaluation reads and the switching never uses.
"""

from __future__ import annotations

import copy
from typing import Any

import numpy as np
import torch

from cpmp.baselines.batch import GoalNearestBatch
from cpmp.baselines.nearest_progress import NearestProgress
from cpmp.records import ReplayResult, TransitionEvent
from cpmp.sequencer import EpisodeBatch, checked_features


class EpisodicBaseline:
    """The shared surface of a baseline that decides one episode on its own.

    A subclass has ``predictor`` (its :class:`NearestProgress`), ``feature_names``, ``events``
    and ``_new_episode()``, ``reset(t, x)`` and ``step(t, x)``.
    """

    predictor: NearestProgress
    feature_names: list[str]
    events: list[TransitionEvent]

    def _new_episode(self) -> None:
        """Forget the current episode (a fresh state; the fitted data stays shared)."""
        raise NotImplementedError

    def reset(self, t: float, x: np.ndarray) -> dict[str, str]:
        """Start an episode at time ``t`` [s] with features ``x (d,)``; the initial MPs."""
        raise NotImplementedError

    def step(self, t: float, x: np.ndarray) -> dict[str, str]:
        """One tick at time ``t`` [s] with features ``x (d,)``; the active MPs after it."""
        raise NotImplementedError

    def batched(self, n: int) -> GoalNearestBatch:
        """``n`` independent episodes of this baseline, stepped together.

        A :class:`~cpmp.baselines.GoalNearestBatch` (it steps any single-episode policy), the
        batched policy :func:`cpmp.sim.run_episodes` drives; each episode is a copy of this
        baseline sharing its fitted data.
        """
        episodes: list[Any] = []
        for _ in range(EpisodeBatch.checked_count(n)):
            episode = copy.copy(self)
            episode._new_episode()
            episodes.append(episode)
        return GoalNearestBatch(episodes)

    @property
    def node_keys(self) -> list[tuple[str, str]]:
        """(variable, MP) of every node, in the order of :meth:`progress`'s columns."""
        return list(self.predictor.node_keys)

    def progress(self, x: np.ndarray | torch.Tensor) -> np.ndarray:
        """Nearest-neighbour progress ``(..., K)`` of every node for features ``x (..., d)``.

        For offline evaluation; the switching does not use it.
        """
        xn = checked_features(x, self.feature_names)
        with torch.no_grad():
            return self.predictor(torch.from_numpy(np.ascontiguousarray(xn))).numpy()

    def replay(self, time: np.ndarray, features: np.ndarray) -> ReplayResult:
        """Run open-loop over a recorded feature stream.

        Args:
            time: ``(n,)`` sample times [s].
            features: ``(n, d)`` features.

        Returns:
            The MP sequence per variable and the transition events.
        """
        seqs = {v: [mp] for v, mp in self.reset(time[0], features[0]).items()}
        for t, x in zip(time[1:], features[1:], strict=True):
            for v, mp in self.step(t, x).items():
                if mp != seqs[v][-1]:
                    seqs[v].append(mp)
        return ReplayResult(seqs, list(self.events))
