"""The dynamics of a procedural task (:class:`~cpmp.worlds.procedural.generator.TaskSpec`).

Every variable's point follows the active MP's attractor ``ṗ = K (g - p)`` (Euler steps of at
most ``dt``) to the MP's goal, jittered per context. The loop's variable is the exception while
it tries and the context's hidden failures are not used up: the try is blocked
``JAM_DISTANCE`` short of its goal (the point is held on that sphere) and its ``force`` feature
rises towards ``FORCE_MAX``; otherwise the force decays to 0 (exactly, ``f -> target + (f -
target) exp(-FORCE_RATE h)``). A try that jammed counts as failed once the variable leaves it.

A context (:class:`ProceduralContext`) holds the strategy (the ``context`` feature's side), the
hidden failure count, jittered starts and goals, and the distractors. Features are the
positions, the loop's force, the context value and the distractors, all in about [0, 2].
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from cpmp.errors import UnknownMPError
from cpmp.worlds.procedural.generator import (
    FORCE_MAX,
    FORCE_RATE,
    JAM_DISTANCE,
    TOLERANCE,
    TaskSpec,
    check_strategy,
    distance,
)
from cpmp.worlds.protocol import substeps

CONTEXT_RANGES = {"a": (0.2, 0.8), "b": (1.2, 1.8)}
"""The context feature's range per strategy."""
DISTRACTOR_RANGE = (0.1, 1.9)
"""The distractors' range (uniform, constant over an episode)."""


@dataclass(frozen=True, eq=False)
class ProceduralContext:
    """The random parameters of one episode.

    Attributes:
        strategy: ``a`` or ``b``.
        failures: failed tries of the loop before the one that succeeds (0–2; 0 without a
            loop). Hidden: only the force feature tells, while it runs.
        context: the context feature, in ``CONTEXT_RANGES[strategy]``.
        starts: per variable, its start ``(dim,)``.
        goals: per variable, per MP (the spec's order), its goal ``(dim,)``.
        distractors: the distractor features ``(n_distractors,)``.
    """

    strategy: str
    failures: int
    context: float
    starts: tuple[tuple[float, ...], ...]
    goals: tuple[tuple[tuple[float, ...], ...], ...]
    distractors: tuple[float, ...]


def sample_context(
    spec: TaskSpec,
    rng: np.random.Generator,
    strategy: str,
    failures: int,
    goal_jitter: float,
    start_jitter: float,
) -> ProceduralContext:
    """One context of ``spec`` drawn from ``rng``.

    Args:
        spec: the task.
        rng: the random numbers (context value, starts, goals, distractors, in this order).
        strategy: ``a`` or ``b``.
        failures: the hidden failure count (0–2; set to 0 when the task has no loop).
        goal_jitter: half-width of the uniform goal jitter per axis.
        start_jitter: half-width of the uniform start jitter per axis.

    Returns:
        The context.
    """
    check_strategy(strategy)
    value = float(rng.uniform(*CONTEXT_RANGES[strategy]))
    starts = tuple(
        tuple(
            float(c) for c in np.asarray(v.start) + rng.uniform(-start_jitter, start_jitter, v.dim)
        )
        for v in spec.variables
    )
    goals = tuple(
        tuple(
            tuple(
                float(c) for c in np.asarray(m.goal) + rng.uniform(-goal_jitter, goal_jitter, v.dim)
            )
            for m in v.mps
        )
        for v in spec.variables
    )
    distractors = tuple(float(d) for d in rng.uniform(*DISTRACTOR_RANGE, spec.n_distractors))
    return ProceduralContext(
        strategy=strategy,
        failures=int(failures) if spec.loop is not None else 0,
        context=value,
        starts=starts,
        goals=goals,
        distractors=distractors,
    )


class ProceduralRun:
    """One episode of a procedural task in progress (a :class:`~cpmp.worlds.protocol.WorldRun`).

    Args:
        spec: the task.
        context: the episode.
        dt: the largest Euler step [s].
    """

    def __init__(self, spec: TaskSpec, context: ProceduralContext, dt: float) -> None:
        self.spec, self.context, self.dt = spec, context, dt
        self._names = spec.variable_names
        self._gains = [v.gain for v in spec.variables]
        self._goals = [
            {m.name: list(g) for m, g in zip(v.mps, gs, strict=True)}
            for v, gs in zip(spec.variables, context.goals, strict=True)
        ]
        final = spec.final_mps(context.strategy)
        self._final = [(v.name, final[v.name], v.mp(final[v.name]).goal) for v in spec.variables]
        self.positions = [list(s) for s in context.starts]
        loop = spec.loop
        self._loop = None if loop is None else self._names.index(loop.variable)
        self._try = None if loop is None else loop.try_mp
        self.force = 0.0
        self.failed = 0
        self.jammed = False
        self.succeeded = loop is None
        self._last = None if loop is None else spec.initial_mps(context.strategy)[loop.variable]
        self._tail = [context.context, *context.distractors]
        self._active: dict[str, str] = {}

    def features(self) -> np.ndarray:
        """The features ``(d,)`` in the spec's ``feature_names`` order."""
        out = [c for p in self.positions for c in p]
        if self._loop is not None:
            out.append(self.force)
        return np.array(out + self._tail)

    def _goal(self, i: int, active: Mapping[str, str]) -> list[float]:
        """The goal of variable ``i``'s active MP.

        Raises:
            UnknownMPError: the variable is missing from ``active`` or its MP is unknown.
        """
        v = self._names[i]
        mp = active.get(v)
        goal = self._goals[i].get(mp)  # type: ignore[arg-type]
        if goal is None:
            raise UnknownMPError(
                f"procedural task {self.spec.seed}: {v} has no MP {mp!r}; it knows "
                f"{', '.join(self._goals[i])}"
            )
        return goal

    def advance(self, active: Mapping[str, str], h: float) -> None:
        """Run the ``active`` MPs for ``h`` [s] in equal Euler steps of at most ``dt``.

        Raises:
            ConfigError: ``h`` is not a positive finite time.
            UnknownMPError: a variable without an MP, or an MP the task does not know.
        """
        n, hs = substeps(h, self.dt)
        goals = [self._goal(i, active) for i in range(len(self._names))]
        self._active = dict(active)
        decay = math.exp(-FORCE_RATE * hs)
        for _ in range(n):
            for i, (p, g) in enumerate(zip(self.positions, goals, strict=True)):
                k = hs * self._gains[i]
                for a in range(len(p)):
                    p[a] += k * (g[a] - p[a])
            if self._loop is not None:
                self._step_loop(active[self._names[self._loop]], goals[self._loop], decay)

    def _step_loop(self, mp: str, goal: list[float], decay: float) -> None:
        """The loop's jam, force and failure count after one Euler step under ``mp``."""
        if mp != self._try and self._last == self._try and self.jammed:
            self.failed += 1
            self.jammed = False
        self._last = mp
        blocked = False
        p = self.positions[self._loop]  # type: ignore[index]
        if mp == self._try:
            r = distance(p, goal)
            if self.failed < self.context.failures and r < JAM_DISTANCE:
                s = JAM_DISTANCE / max(r, 1e-12)
                for a in range(len(p)):
                    p[a] = goal[a] + (p[a] - goal[a]) * s
                blocked = self.jammed = True
            elif not self.jammed and distance(p, self._nominal(self._try)) < TOLERANCE:
                self.succeeded = True
        target = FORCE_MAX if blocked else 0.0
        self.force = target + (self.force - target) * decay

    def _nominal(self, mp: str) -> tuple[float, ...]:
        """The nominal goal of the loop variable's ``mp``."""
        return self.spec.variables[self._loop].mp(mp).goal  # type: ignore[index]

    def failure(self) -> str:
        """Why the run is not complete, in words (``""`` when it is), under the MPs it last ran.

        The loop's try not yet succeeded (with the jams so far), then each variable not in its
        last MP for the strategy or not at that MP's goal (distance in the task's units).
        """
        unmet = []
        if not self.succeeded:
            loop = self._names[self._loop]  # type: ignore[index]
            unmet.append(
                f"{loop}'s {self._try} has not succeeded ({self.failed} of "
                f"{self.context.failures} jams so far)"
            )
        for (v, mp, goal), p in zip(self._final, self.positions, strict=True):
            now = self._active.get(v)
            if now != mp:
                unmet.append(f"{v} ends in {now}, not {mp}")
            elif (r := distance(p, goal)) >= TOLERANCE:
                unmet.append(f"{v} is {r:.2f} from {mp}'s goal (tolerance {TOLERANCE:g})")
        return "; ".join(unmet)

    def done(self, active: Mapping[str, str]) -> bool:
        """Whether the episode is over: the goal state (nothing else ends it early)."""
        return self.complete(active)

    def complete(self, active: Mapping[str, str]) -> bool:
        """Every variable in its last MP for the strategy, at its goal; the loop's try succeeded."""
        if not self.succeeded:
            return False
        for (v, mp, goal), p in zip(self._final, self.positions, strict=True):
            if active.get(v) != mp or distance(p, goal) >= TOLERANCE:
                return False
        return True
