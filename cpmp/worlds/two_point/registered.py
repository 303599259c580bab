"""The two-point task as a registered world (:class:`~cpmp.worlds.protocol.World`)."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from typing_extensions import override

from cpmp.config.validation import OptionValue
from cpmp.data import Demonstration
from cpmp.records import Policy
from cpmp.worlds.protocol import WorldBase, substeps
from cpmp.worlds.two_point.policy import TwoPointFeaturePolicy
from cpmp.worlds.two_point.task import (
    FEATURE_NAMES,
    VARIABLES,
    SyntheticTask,
    TwoPointEpisode,
    make_demonstrations,
)


class _TwoPointRun:
    """One two-point episode in progress (a :class:`~cpmp.worlds.protocol.WorldRun`)."""

    def __init__(self, task: SyntheticTask, episode: TwoPointEpisode) -> None:
        self.task, self.episode = task, episode
        self.p = np.array(episode.start, dtype=float)
        self.gain = np.asarray(task.gain)
        self._active: dict[str, str] = {}

    @override
    def features(self) -> np.ndarray:
        return np.array([self.p[0], self.p[1], self.episode.context])

    @override
    def advance(self, active: Mapping[str, str], h: float) -> None:
        n, hs = substeps(h, self.task.dt)
        self._active = dict(active)
        for _ in range(n):
            goals = self.task.goals(self.episode, dict(active))
            self.p = self.p + hs * self.gain * (goals - self.p)

    @override
    def done(self, active: Mapping[str, str]) -> bool:
        return self.complete(active)

    @override
    def complete(self, active: Mapping[str, str]) -> bool:
        back = active["a"] == "a_back" and active["b"] == "b_back"
        return bool(back and np.all(np.abs(self.p) < 0.01))

    def failure(self) -> str:
        """Why the run is not complete, in words (``""`` when it is).

        Under the MPs it last ran: each point not under its ``*_back`` MP, or not home.
        """
        unmet = []
        for name, x in zip(("a", "b"), self.p, strict=True):
            if (mp := self._active.get(name)) != f"{name}_back":
                unmet.append(f"point {name} runs {mp}, not {name}_back")
            elif abs(x) >= 0.01:
                unmet.append(f"point {name} is {abs(x):.3f} from home")
        return "; ".join(unmet)


class TwoPointWorld(WorldBase[TwoPointEpisode]):
    """The two-point world; ``TwoPointWorld(**options)`` takes :class:`SyntheticTask`'s fields.

    Demonstrations alternate the strategies (:func:`make_demonstrations`); closed-loop contexts
    draw the context uniformly (as :func:`evaluate` does). Complete: both points home under
    their ``*_back`` MPs.
    """

    name = "two_point"
    variables = tuple(VARIABLES)
    feature_names = tuple(FEATURE_NAMES)
    strategies = ("sequential", "parallel")

    def __init__(self, **options: OptionValue) -> None:
        self.task = SyntheticTask(**options)
        self.dt = self.task.dt
        self.max_time = self.task.max_time

    @override
    def demonstrations(self, n: int, seed: int) -> list[Demonstration]:
        return make_demonstrations(n, seed=seed, task=self.task)

    @override
    def contexts(self, n: int, seed: int) -> list[TwoPointEpisode]:
        rng = np.random.default_rng(seed)
        return [self.task.sample_episode(rng) for _ in range(n)]

    @override
    def demonstrate(self, context: TwoPointEpisode, name: str | None = None) -> Demonstration:
        return self.task.demonstrate(context, name)

    @override
    def start(self, context: TwoPointEpisode) -> _TwoPointRun:
        return _TwoPointRun(self.task, context)

    @override
    def strategy(self, context: TwoPointEpisode) -> str:
        return "parallel" if context.parallel else "sequential"

    @override
    def initial_mps(self, context: TwoPointEpisode) -> dict[str, str]:
        return self.task.initial_mps(context)

    @override
    def scripted_policy(self) -> Policy:
        return TwoPointFeaturePolicy(self.task)
