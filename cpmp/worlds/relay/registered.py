"""The relay and the paced relay as registered worlds (:class:`~cpmp.worlds.protocol.World`).

:class:`RelayWorld` is the hand-over of :mod:`cpmp.worlds.relay.world` with its options;
:class:`PacedRelayWorld` the same task with MPs at varied speeds (:mod:`cpmp.worlds.relay.
varied`): paced demonstrations (varied speeds and holds mid-MP) and a paced robot (varied
speeds). Both score an episode by its start and its goal state
(:func:`~cpmp.worlds.protocol.default_score`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from typing_extensions import override

from cpmp.config.task import Pacing
from cpmp.data import Demonstration
from cpmp.errors import ConfigError
from cpmp.records import Policy
from cpmp.worlds.common import seeded_episodes
from cpmp.worlds.outcomes import Outcome
from cpmp.worlds.protocol import default_score, substeps
from cpmp.worlds.relay import varied
from cpmp.worlds.relay.demonstrator import demonstrate, make_demonstrations
from cpmp.worlds.relay.world import (
    FEATURE_NAMES,
    STRATEGIES,
    VARIABLES,
    RelayEpisode,
    RelayTask,
)


class _RelayRun:
    """One relay episode in progress (a :class:`~cpmp.worlds.protocol.WorldRun`)."""

    def __init__(self, task: RelayTask, episode: RelayEpisode) -> None:
        self.task, self.episode = task, episode
        self.state = task.initial_state(episode)

    @override
    def features(self) -> np.ndarray:
        return self.task.features(self.state, self.episode)

    @override
    def advance(self, active: Mapping[str, str], h: float) -> None:
        n, hs = substeps(h, self.task.dt)
        for _ in range(n):
            self.task.advance(self.state, self.episode, active, dt=hs)

    @override
    def done(self, active: Mapping[str, str]) -> bool:
        return self.complete(active)

    @override
    def complete(self, active: Mapping[str, str]) -> bool:
        return self.task.at_goal(self.state, self.episode)


class RelayWorld:
    r"""The relay world; ``RelayWorld(**options)`` takes :class:`RelayTask`'s fields.

    Contexts are :class:`RelayEpisode`\ s alternating the strategies (``meet`` first).
    """

    name = "relay"
    variables = tuple(VARIABLES)
    feature_names = tuple(FEATURE_NAMES)
    strategies: tuple[str, ...] = STRATEGIES

    def __init__(self, **options: Any) -> None:
        self.task = RelayTask(**options)
        self.dt = self.task.dt
        self.max_time = self.task.max_time

    @override
    def demonstrations(self, n: int, seed: int) -> list[Demonstration]:
        return make_demonstrations(n, seed=seed, task=self.task)

    @override
    def contexts(self, n: int, seed: int) -> list[RelayEpisode]:
        return seeded_episodes(self.task.sample_episode, STRATEGIES, n, seed)

    @override
    def demonstrate(self, context: RelayEpisode, name: str | None = None) -> Demonstration:
        return demonstrate(self.task, context, name)

    @override
    def start(self, context: RelayEpisode) -> _RelayRun:
        return _RelayRun(self.task, context)

    @override
    def strategy(self, context: RelayEpisode) -> str:
        return context.strategy

    @override
    def initial_mps(self, context: RelayEpisode) -> dict[str, str]:
        return self.task.initial_mps(context)

    @override
    def scripted_policy(self) -> Policy:
        from cpmp.worlds.relay.policy import RelayFeaturePolicy  # lazy: tables stay cheap

        return RelayFeaturePolicy(self.task)

    @override
    def score(
        self,
        context: Any,
        initial: Mapping[str, str],
        sequences: Mapping[str, Sequence[str]],
        completed: bool,
    ) -> Outcome:
        return default_score(self, context, initial, sequences, completed)


class _PacedRun:
    """One paced relay episode in progress."""

    def __init__(self, task: varied.PacedRelayTask, episode: varied.PacedEpisode) -> None:
        self.task, self.episode = task, episode
        self.state = task.initial_state(episode)

    @override
    def features(self) -> np.ndarray:
        return self.task.features(self.state, self.episode)

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


def pacing(value: Pacing | Mapping[str, Any] | None, default: Pacing, what: str) -> Pacing:
    """A :class:`Pacing` from itself or a mapping of its fields (``None``: ``default``).

    Raises:
        ConfigError: not a mapping, or a bad field.
    """
    if value is None:
        return default
    if isinstance(value, Pacing):
        return value
    if not isinstance(value, Mapping):
        raise ConfigError(f"the paced_relay world's {what} must be a mapping of Pacing's fields")
    fields = {k: tuple(v) if isinstance(v, (list, tuple)) else v for k, v in value.items()}
    try:
        return Pacing(**fields)
    except TypeError as err:
        raise ConfigError(
            f"bad option of the paced_relay world's {what} ({err}); its options are the fields "
            "of cpmp.config.task.Pacing"
        ) from err


class PacedRelayWorld(RelayWorld):
    """The paced relay (:func:`cpmp.worlds.relay.varied.paced_relay`).

    Args:
        demo: the demonstrator's pacing (:data:`~cpmp.worlds.relay.varied.DEMO_PACING`).
        robot: the closed-loop robot's pacing (:data:`~cpmp.worlds.relay.varied.ROBOT_PACING`).
        relay: the relay task's options (default: its defaults with
            :data:`~cpmp.worlds.relay.varied.MAX_TIME`).
    """

    name = "paced_relay"

    def __init__(
        self,
        demo: Pacing | Mapping[str, Any] | None = None,
        robot: Pacing | Mapping[str, Any] | None = None,
        relay: Mapping[str, Any] | None = None,
    ) -> None:
        super().__init__(**{"max_time": varied.MAX_TIME, **dict(relay or {})})
        self.demo_task = varied.PacedRelayTask(self.task, pacing(demo, varied.DEMO_PACING, "demo"))
        self.robot_task = varied.PacedRelayTask(
            self.task, pacing(robot, varied.ROBOT_PACING, "robot")
        )

    @override
    def demonstrations(self, n: int, seed: int) -> list[Demonstration]:
        return varied.make_demonstrations(n, seed, self.demo_task)

    @override
    def contexts(self, n: int, seed: int) -> list[varied.PacedEpisode]:  # type: ignore[override]
        return self.robot_task.episodes(n, seed, varied.ROBOT_STREAM)

    @override
    def demonstrate(  # type: ignore[override]
        self, context: varied.PacedEpisode, name: str | None = None
    ) -> Demonstration:
        return varied.demonstrate(self.robot_task, context, name)

    @override
    def start(self, context: varied.PacedEpisode) -> _PacedRun:  # type: ignore[override]
        return _PacedRun(self.robot_task, context)

    @override
    def strategy(self, context: varied.PacedEpisode) -> str:  # type: ignore[override]
        return context.strategy

    @override
    def initial_mps(self, context: varied.PacedEpisode) -> dict[str, str]:  # type: ignore[override]
        return self.robot_task.initial_mps(context)
