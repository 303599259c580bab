"""The repetition task as a registered world (:class:`~cpmp.worlds.protocol.World`).

An episode is complete when it reaches the goal state running exactly the demonstrator's MP
sequences (spilt soup scooped again is another route, and ``incomplete``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from typing_extensions import override

from cpmp.data import Demonstration
from cpmp.records import Policy
from cpmp.worlds.common import seeded_episodes
from cpmp.worlds.outcomes import Outcome, episode_outcome
from cpmp.worlds.protocol import substeps
from cpmp.worlds.repetition.demonstrator import demonstrate, make_demonstrations
from cpmp.worlds.repetition.world import (
    FEATURE_NAMES,
    STRATEGIES,
    VARIABLES,
    RepetitionEpisode,
    RepetitionTask,
)


class _RepetitionRun:
    """One repetition episode in progress (a :class:`~cpmp.worlds.protocol.WorldRun`)."""

    def __init__(self, task: RepetitionTask, episode: RepetitionEpisode) -> None:
        self.task, self.episode = task, episode
        self.state = task.initial_state(episode)

    @override
    def features(self) -> np.ndarray:
        return self.task.features(self.state)

    @override
    def advance(self, active: Mapping[str, str], h: float) -> None:
        n, hs = substeps(h, self.task.dt)
        for _ in range(n):
            self.task.advance(self.state, self.episode, dict(active), dt=hs)

    @override
    def done(self, active: Mapping[str, str]) -> bool:
        return self.complete(active)

    @override
    def complete(self, active: Mapping[str, str]) -> bool:
        return self.task.at_goal(self.state, self.episode)


class RepetitionWorld:
    r"""The repetition world; ``RepetitionWorld(**options)`` takes :class:`RepetitionTask`'s fields.

    Contexts are :class:`RepetitionEpisode`\ s cycling ``once``, ``twice``, ``thrice``.
    """

    name = "repetition"
    variables = tuple(VARIABLES)
    feature_names = tuple(FEATURE_NAMES)
    strategies: tuple[str, ...] = STRATEGIES

    def __init__(self, **options: Any) -> None:
        self.task = RepetitionTask(**options)
        self.dt = self.task.dt
        self.max_time = self.task.max_time

    @override
    def demonstrations(self, n: int, seed: int) -> list[Demonstration]:
        return make_demonstrations(n, seed=seed, task=self.task)

    @override
    def contexts(self, n: int, seed: int) -> list[RepetitionEpisode]:
        return seeded_episodes(self.task.sample_episode, STRATEGIES, n, seed)

    @override
    def demonstrate(self, context: RepetitionEpisode, name: str | None = None) -> Demonstration:
        return demonstrate(self.task, context, name)

    @override
    def start(self, context: RepetitionEpisode) -> _RepetitionRun:
        return _RepetitionRun(self.task, context)

    @override
    def strategy(self, context: RepetitionEpisode) -> str:
        return context.strategy

    @override
    def initial_mps(self, context: RepetitionEpisode) -> dict[str, str]:
        return self.task.initial_mps(context)

    @override
    def scripted_policy(self) -> Policy:
        from cpmp.worlds.repetition.policy import RepetitionFeaturePolicy  # lazy

        return RepetitionFeaturePolicy(self.task)

    @override
    def score(
        self,
        context: RepetitionEpisode,
        initial: Mapping[str, str],
        sequences: Mapping[str, Sequence[str]],
        completed: bool,
    ) -> Outcome:
        """Start, goal state and the demonstrator's sequences.

        The sequences are :meth:`RepetitionTask.expected_sequences` of the context.
        """
        expected = self.task.expected_sequences(context)
        started = dict(initial) == {v: s[0] for v, s in expected.items()}
        same = all(list(sequences[v]) == expected[v] for v in self.variables)
        return episode_outcome(started, completed and same)
