"""The scripted demonstrator of a procedural task: its guards, demonstrations and contexts.

The demonstrator switches a variable at the first tick one of its current MP's guards holds
(:class:`~cpmp.worlds.procedural.generator.Guard`, tested in order). A guard reads only the
variable's own MP and this tick's features, so switches whose guards hold together fire
together, and the feature-only policy (:mod:`cpmp.worlds.procedural.policy`) is the same
machine. The demonstrator alone knows the context: its initial MPs come from the strategy.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from cpmp.data import Demonstration, DemonstrationLog
from cpmp.worlds.procedural.generator import CONTEXT_SPLIT, TOLERANCE, Guard, TaskSpec, check_seed
from cpmp.worlds.procedural.world import ProceduralContext, ProceduralRun, sample_context

_EPS_T = 1e-9
"""Slack [s] when comparing times."""
_CONTEXT_SALT = 0x5C7
"""Mixed into a context seed (contexts of one seed differ between tasks)."""


@dataclass(frozen=True)
class _Check:
    """A compiled :class:`Guard` (feature indices instead of names).

    Attributes:
        target: the MP switched to.
        own: ``(first index, dim, nominal goal)`` of the variable's point, or ``None``.
        force: index of the variable's force feature (``-1``: none).
        above: force level to exceed, or ``None``.
        below: force level to stay under, or ``None``.
        strategy: ``a``/``b`` or ``None``.
        wait: ``(first index, dim, nominal goals)`` of the waited-on variable, or ``None``.
    """

    target: str
    own: tuple[int, int, tuple[float, ...]] | None
    force: int
    above: float | None
    below: float | None
    strategy: str | None
    wait: tuple[int, int, tuple[tuple[float, ...], ...]] | None


class Switches:
    """The demonstrator's guards of ``spec`` compiled for fast ticks.

    Args:
        spec: the task.
    """

    def __init__(self, spec: TaskSpec) -> None:
        self.spec = spec
        names = spec.feature_names
        self._context = names.index("context")
        first = {v.name: names.index(f"{v.name}_x") for v in spec.variables}
        self._checks: dict[str, dict[str, list[_Check]]] = {}
        for v in spec.variables:
            force = names.index(f"{v.name}_force") if f"{v.name}_force" in names else -1
            table: dict[str, list[_Check]] = {m.name: [] for m in v.mps}
            for g in v.guards:
                table[g.source].append(self._compile(g, v.name, first, force))
            self._checks[v.name] = table

    def _compile(self, g: Guard, variable: str, first: dict[str, int], force: int) -> _Check:
        """``g`` of ``variable`` with feature indices."""
        spec = self.spec
        v = spec.variable(variable)
        own = (first[variable], v.dim, v.mp(g.source).goal) if g.arrive else None
        wait = None
        if g.wait_variable is not None:
            w = spec.variable(g.wait_variable)
            wait = (first[w.name], w.dim, tuple(w.mp(m).goal for m in g.wait_mps))
        return _Check(g.target, own, force, g.force_above, g.force_below, g.strategy, wait)

    def __call__(self, x: np.ndarray, active: Mapping[str, str]) -> dict[str, str]:
        """The MPs after this tick's switches.

        Args:
            x: this tick's features ``(d,)``.
            active: variable -> MP before the tick.

        Returns:
            Variable -> MP after the tick.
        """
        xs = x.tolist()
        side = "a" if xs[self._context] < CONTEXT_SPLIT else "b"
        new = dict(active)
        for v, table in self._checks.items():
            for c in table[active[v]]:
                if _holds(c, xs, side):
                    new[v] = c.target
                    break
        return new


def _near(xs: list[float], i: int, dim: int, goal: tuple[float, ...]) -> bool:
    """Whether the point at ``xs[i : i + dim]`` is within ``TOLERANCE`` of ``goal``."""
    if dim == 1:
        return abs(xs[i] - goal[0]) < TOLERANCE
    dx, dy = xs[i] - goal[0], xs[i + 1] - goal[1]
    return dx * dx + dy * dy < TOLERANCE * TOLERANCE


def _holds(c: _Check, xs: list[float], side: str) -> bool:
    """Whether the compiled guard ``c`` holds at features ``xs`` with the context on ``side``."""
    if c.strategy is not None and c.strategy != side:
        return False
    if c.above is not None and not xs[c.force] > c.above:
        return False
    if c.below is not None and not xs[c.force] < c.below:
        return False
    if c.own is not None and not _near(xs, *c.own):
        return False
    if c.wait is not None:
        i, dim, goals = c.wait
        if not any(_near(xs, i, dim, g) for g in goals):
            return False
    return True


def demonstrate(
    spec: TaskSpec,
    context: ProceduralContext,
    dt: float,
    max_time: float,
    name: str | None = None,
    switches: Switches | None = None,
) -> Demonstration:
    """The scripted demonstrator's labelled demonstration of ``context``.

    Args:
        spec: the task.
        context: the episode.
        dt: the sample period and Euler step [s].
        max_time: the time limit [s].
        name: the demonstration's name.
        switches: the compiled guards (built from ``spec`` when ``None``).

    Returns:
        Samples every ``dt`` from ``t = 0`` until the goal state (or ``max_time``); the label
        of a sample is the MP active before that tick's switches. Metadata: ``task``,
        ``strategy``, ``failures``, ``context`` and ``reached_goal``.
    """
    switch = switches or Switches(spec)
    run = ProceduralRun(spec, context, dt)
    active = spec.initial_mps(context.strategy)
    log = DemonstrationLog(spec.variable_names)
    t = 0.0
    while True:
        x = run.features()
        log.append(t, x, active)
        if run.complete(active) or t >= max_time - _EPS_T:
            break
        active = switch(x, active)
        run.advance(active, dt)
        t = round(t + dt, 10)
    metadata = {
        "task": f"procedural_{spec.seed}",
        "strategy": context.strategy,
        "failures": context.failures,
        "context": context.context,
        "reached_goal": run.complete(active),
    }
    return log.to_demonstration(spec.feature_names, name, metadata)


def make_contexts(
    spec: TaskSpec, n: int, seed: int, goal_jitter: float, start_jitter: float
) -> list[ProceduralContext]:
    """``n`` contexts of ``spec`` from ``seed``, cycling strategies and failures.

    Item ``i`` has strategy ``"ab"[i % 2]`` and ``(i + 1) % 3`` hidden failures (so any three
    in a row include one and two failures).

    Args:
        spec: the task.
        n: how many (a positive integer; checked by the caller).
        seed: a non-negative integer.
        goal_jitter: half-width of the goal jitter per axis.
        start_jitter: half-width of the start jitter per axis.

    Raises:
        ConfigError: ``seed`` is not a non-negative integer.
    """
    s = check_seed(seed, "seed")
    rng = np.random.default_rng(np.random.SeedSequence([s, spec.seed, _CONTEXT_SALT]))
    return [
        sample_context(spec, rng, "ab"[i % 2], (i + 1) % 3, goal_jitter, start_jitter)
        for i in range(n)
    ]
