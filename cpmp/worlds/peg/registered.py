"""The peg task as a registered world (:class:`~cpmp.worlds.protocol.World`).

:class:`PegWorld` is the task's options (:class:`~cpmp.worlds.peg.world.PegTask`, validated on
construction) plus the world's face: demonstrations, contexts, runs, the scripted policy and
the score (the demonstrator's exact MP sequences, hidden jams included, are required for
``complete``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from cpmp.data import Demonstration
from cpmp.worlds.common import positive_count
from cpmp.worlds.peg.demonstrator import demonstrate
from cpmp.worlds.peg.policy import FeaturePolicy
from cpmp.worlds.peg.world import (
    FEATURE_NAMES,
    STRATEGIES,
    VARIABLES,
    PegContext,
    PegState,
    PegTask,
)
from cpmp.worlds.protocol import WorldBase, failure_text, substeps


@dataclass
class PegRun:
    """One episode of the peg world in progress (:class:`~cpmp.worlds.protocol.WorldRun`).

    Attributes:
        task: the task's options.
        context: the episode's context.
        state: the simulated world, hidden state included.
        failed_at: when the base slid, the peg broke or dropped [s] (``None``: it did not).
    """

    task: PegTask
    context: PegContext
    state: PegState
    failed_at: float | None = None

    def features(self) -> np.ndarray:
        """The features ``(13,)`` now."""
        return self.task.features(self.state, self.context)

    def advance(self, active: Mapping[str, str], h: float) -> None:
        """Run the ``active`` MPs for ``h`` [s], in equal sub-steps of at most ``dt``.

        Raises:
            ConfigError: ``h`` is not a positive finite time.
            UnknownMPError: an MP the task does not know.
        """
        n, step = substeps(h, self.task.dt)
        mps = dict(active)
        for _ in range(n):
            self.task.advance(self.state, self.context, mps, step)
            if self.failed_at is None and self.state.failed:
                self.failed_at = self.state.t

    def failure(self) -> str:
        """Why the run is not complete, in words (:meth:`PegTask.shortfall`, with the time)."""
        return failure_text(self.task.shortfall(self.state, self.context), self.failed_at)

    def done(self, active: Mapping[str, str]) -> bool:
        """The goal reached, or the base slid, the peg broke or dropped."""
        return self.state.failed or self.complete(active)

    def complete(self, active: Mapping[str, str]) -> bool:
        """Whether the goal state is reached and the MPs ``active`` keep it there.

        The inserter must run ``home`` and the holder ``retreat`` or ``rest``.
        """
        keeps = active.get("inserter") == "home" and active.get("holder") in ("retreat", "rest")
        return keeps and self.task.at_goal(self.state, self.context)


@dataclass
class PegWorld(PegTask, WorldBase[PegContext]):
    """The peg world (see :mod:`cpmp.worlds.peg.world`); its fields are the task's options."""

    strict: ClassVar[bool] = True

    name: ClassVar[str] = "peg"
    variables: ClassVar[tuple[str, ...]] = VARIABLES
    feature_names: ClassVar[tuple[str, ...]] = FEATURE_NAMES
    strategies: ClassVar[tuple[str, ...]] = STRATEGIES

    def demonstrations(self, n: int, seed: int) -> list[Demonstration]:
        """``n`` demonstrations of :meth:`contexts` ``(n, seed)``, named ``demo_<i>``.

        Raises:
            ConfigError: ``n`` is not a positive integer.
        """
        return [self.demonstrate(c, f"demo_{i}") for i, c in enumerate(self.contexts(n, seed))]

    def contexts(self, n: int, seed: int) -> list[PegContext]:
        """``n`` contexts from ``seed`` (strategy ``i % 4``, ``(i // 4 + i) % 3`` jams).

        Raises:
            ConfigError: ``n`` is not a positive integer.
        """
        return super().contexts(positive_count(n, "n"), seed)

    def demonstrate(self, context: PegContext, name: str | None = None) -> Demonstration:
        """The scripted demonstrator's labelled demonstration of ``context``."""
        return demonstrate(self, context, name)

    def start(self, context: PegContext) -> PegRun:
        """A run of ``context`` at ``t = 0``."""
        return PegRun(self, context, self.initial_state(context))

    def strategy(self, context: PegContext) -> str:
        """The context's strategy."""
        return context.strategy

    def scripted_policy(self) -> FeaturePolicy:
        """A fresh feature-only policy."""
        return FeaturePolicy(self)
