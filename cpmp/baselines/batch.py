"""``N`` episodes of the goal-nearest baseline, for many rollouts (:func:`cpmp.sim.run_episodes`).

:class:`GoalNearestBatch` gives the baseline the batched interface of the learned sequencer's
:class:`~cpmp.sequencer.BatchedSequencer` (both are an :class:`~cpmp.sequencer.EpisodeBatch`);
it steps its episodes one after another, each a :class:`~cpmp.baselines.GoalNearestSequencer`
of its own. Build one with ``GoalNearestSequencer.batched(n)``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

import numpy as np

from cpmp.errors import CpmpError
from cpmp.sequencer import EpisodeBatch, EpisodeRecord, Features, LiveMask, Stamps, Times


class SingleEpisodePolicy(EpisodeRecord, Protocol):
    """One episode of a policy that decides on its own: ``reset`` then ``step``, one tick each.

    A :class:`~cpmp.baselines.GoalNearestSequencer` is one.
    """

    feature_names: list[str]
    """The ``d`` feature names."""

    def reset(self, t: float, x: np.ndarray) -> dict[str, str]:
        """Start the episode at time ``t`` [s] with features ``x (d,)``; the initial MPs."""
        ...

    def step(self, t: float, x: np.ndarray) -> dict[str, str]:
        """One tick at time ``t`` [s] with features ``x (d,)``; the active MPs after it."""
        ...


class GoalNearestBatch(EpisodeBatch):
    """``N`` independent episodes of one fitted goal-nearest baseline.

    The interface of :class:`~cpmp.sequencer.BatchedSequencer`: ``reset``/``step`` take ``t``
    (scalar or ``(N,)``) [s], features ``x (N, d)`` and an optional ``live (N,)`` bool mask
    (other episodes are left untouched; ``step`` also an optional ``stamp``) and return every
    episode's active MPs;
    ``episodes[i]`` holds episode ``i``'s ``events`` and ``last_tick``.

    Args:
        episodes: one policy per episode (copies of one fitted
            :class:`~cpmp.baselines.GoalNearestSequencer`, sharing its fitted data).
    """

    def __init__(self, episodes: Sequence[SingleEpisodePolicy]) -> None:
        self.episodes: list[SingleEpisodePolicy] = list(episodes)

    def reset(self, t: Times, x: Features, live: LiveMask = None) -> list[dict[str, str]]:
        """Start the ``live`` episodes (default: all).

        Args:
            t: one time [s] or ``(N,)`` times.
            x: features ``(N, d)``.
            live: ``(N,)`` bool, the episodes to start (``None``: all).

        Returns:
            Every episode's active MPs (variable -> MP).
        """
        ts, xn, rows = self._inputs(t, x, live, len(self.episodes[0].feature_names))
        for i in rows:
            self.episodes[i].reset(ts[i], xn[i])
        return self.active

    def step(
        self, t: Times, x: Features, live: LiveMask = None, stamp: Stamps = None
    ) -> list[dict[str, str]]:
        """Advance the ``live`` episodes (default: all) one tick.

        Args:
            t: one time [s] or ``(N,)`` times.
            x: features ``(N, d)``.
            live: ``(N,)`` bool, the episodes to advance (``None``: all).
            stamp: when the features were measured (one time or ``(N,)``), as the learned
                sequencer's batch takes it; checked, not used: the baseline decides on the
                features alone.

        Returns:
            Every episode's active MPs (variable -> MP).

        Raises:
            CpmpError: what an episode raised, with the episode's index in the message.
        """
        ts, xn, rows = self._inputs(t, x, live, len(self.episodes[0].feature_names))
        self._stamps(stamp)
        for i in rows:
            try:
                self.episodes[i].step(ts[i], xn[i])
            except CpmpError as err:
                raise type(err)(f"episode {i}: {err}") from err
        return self.active
