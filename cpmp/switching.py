"""When a control variable switches: the switching rules, the learned coupling between graphs and
stall recovery. Pure Python on top of the per-tick transition probabilities; used by
:class:`cpmp.sequencer.ConcurrentSequencer`.

**Switching rules** decide, per variable and tick, whether the best successor ``s`` of the
current node fires, given its transition probability ``p_s(t) = φ_current(x) · (1 - φ_s(x))``:

* ``paper`` — the paper's sentence read literally: "above a certain threshold and has not
  improved over the last 50 ms": ``p(t) > threshold`` and ``p(t) <= p(t - patience) +
  min_improvement``, where ``p(t - patience)`` is the same successor's ``p`` at the last tick at
  or before ``t - patience``. A ``p`` that peaks above the threshold and then falls back fires;
  a ``p`` still rising waits.
* ``plateau`` — ``p`` must stay above the threshold for ``patience`` seconds without a new
  maximum (cpmp's earlier rule). It misses switches whose ``p`` crosses the threshold near its
  peak and then declines as the next MPs start to move.

**Coupling** (the paper's discussion asks for more than the shared features): for every
demonstrated switch ``source -> target`` of a variable, the MPs every *other* variable was
running when it happened (the labels one sample before and at the switch, so that switches made
in the same tick in either order are both allowed). A transition whose context — the other
variables' current MPs — contains an MP never seen for that switch is held back. It is learned
from the labels alone (nothing task-specific), per other variable (a product of marginal sets,
more lenient than requiring a demonstrated joint context).

**Recovery** resolves a stall: no transition of any variable for ``stall_time`` seconds while
the features are at rest (every feature moves slower than ``rest_speed`` times its training
range per second). Then the single candidate transition most consistent with the coupling, and
among those the most probable, fires if its ``p`` reaches ``recovery_threshold``.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

if TYPE_CHECKING:
    from cpmp.data import Demonstration

SWITCH_RULES = ("paper", "plateau")
COUPLINGS = ("none", "context")

_EPS_T = 1e-9
"""Slack [s] when comparing tick times (ticks are sums of floating-point periods)."""


class SwitchRule(Protocol):
    """Per-variable switching state: fed every tick with the successors' ``p``."""

    def reset(self) -> None:
        """Forget the history (called when the variable's node changes)."""

    def update(self, t: float, p: Sequence[float], allowed: Sequence[bool]) -> int | None:
        """Record the successors' ``p`` at time ``t`` [s]; return the index of the successor
        to switch to now (only one with ``allowed[i]``), or ``None``."""


def _best(p: Sequence[float], allowed: Sequence[bool]) -> int | None:
    best = None
    for i, (value, ok) in enumerate(zip(p, allowed, strict=True)):
        if ok and (best is None or value > p[best]):
            best = i
    return best


class PaperRule:
    """``p(t) > threshold`` and ``p(t) <= p(t - patience) + min_improvement`` (see module doc)."""

    def __init__(self, threshold: float, patience: float, min_improvement: float) -> None:
        self.threshold = threshold
        self.patience = patience
        self.min_improvement = min_improvement
        self._history: deque[tuple[float, list[float]]] = deque()

    def reset(self) -> None:
        self._history.clear()

    def update(self, t: float, p: Sequence[float], allowed: Sequence[bool]) -> int | None:
        history = self._history
        history.append((t, list(p)))
        # Keep exactly one entry at or before t - patience: the reference tick.
        while len(history) >= 2 and history[1][0] <= t - self.patience + _EPS_T:
            history.popleft()
        best = _best(p, allowed)
        if best is None or p[best] <= self.threshold:
            return None
        t_ref, p_ref = history[0]
        if t_ref > t - self.patience + _EPS_T:
            return None  # the node has not been active for `patience` yet
        return best if p[best] <= p_ref[best] + self.min_improvement else None


class PlateauRule:
    """``p`` above ``threshold`` for ``patience`` seconds without a new maximum."""

    def __init__(self, threshold: float, patience: float, min_improvement: float) -> None:
        self.threshold = threshold
        self.patience = patience
        self.min_improvement = min_improvement
        self._target: int | None = None
        self._best = 0.0
        self._since = 0.0

    def reset(self) -> None:
        self._target = None

    def update(self, t: float, p: Sequence[float], allowed: Sequence[bool]) -> int | None:
        best = _best(p, allowed)
        if best is None or p[best] <= self.threshold:
            self._target = None
            return None
        if self._target != best:
            self._target, self._best, self._since = best, p[best], t
        elif p[best] > self._best + self.min_improvement:
            self._best, self._since = p[best], t
        if t - self._since >= self.patience - _EPS_T:
            self._target = None
            return best
        return None


def make_rule(name: str, threshold: float, patience: float, min_improvement: float) -> SwitchRule:
    """A fresh switching rule ``name`` (one of :data:`SWITCH_RULES`)."""
    cls = {"paper": PaperRule, "plateau": PlateauRule}[name]
    return cls(threshold, patience, min_improvement)


Edge = tuple[str, str, str]
"""(variable, source MP, target MP)."""


@dataclass
class Coupling:
    """Contexts of the demonstrated switches (see module doc).

    Attributes:
        contexts: ``(variable, source, target)`` -> other variable -> MPs it ran at that switch.
    """

    contexts: dict[Edge, dict[str, frozenset[str]]] = field(default_factory=dict)

    @classmethod
    def learn(cls, demos: Sequence[Demonstration], variables: Sequence[str]) -> Coupling:
        """Collect the contexts of every switch of ``variables`` in ``demos``."""
        contexts: dict[Edge, dict[str, set[str]]] = {}
        variables = list(variables)
        for demo in demos:
            labels = {v: np.asarray(demo.labels[v]) for v in variables}
            for v in variables:
                lab = labels[v]
                for i in np.flatnonzero(lab[1:] != lab[:-1]) + 1:
                    ctx = contexts.setdefault((v, str(lab[i - 1]), str(lab[i])), {})
                    for u in variables:
                        if u != v:
                            ctx.setdefault(u, set()).update(
                                (str(labels[u][i - 1]), str(labels[u][i]))
                            )
        return cls({e: {u: frozenset(s) for u, s in c.items()} for e, c in contexts.items()})

    def inconsistent(self, edge: Edge, active: Mapping[str, str]) -> list[str]:
        """Other variables whose current MP was never seen at a demonstrated ``edge`` switch
        (empty: consistent; an edge without a recorded context is consistent)."""
        ctx = self.contexts.get(edge)
        if not ctx:
            return []
        return [u for u, mps in ctx.items() if u in active and active[u] not in mps]

    def describe(self, variable: str) -> list[str]:
        """One line per switch of ``variable``: the other variables' demonstrated MPs."""
        lines = []
        for (v, source, target), ctx in sorted(self.contexts.items()):
            if v != variable:
                continue
            parts = [f"{u} in {{{', '.join(sorted(mps))}}}" for u, mps in sorted(ctx.items())]
            lines.append(f"  {source} -> {target} when " + ("; ".join(parts) or "always"))
        return lines

    def to_dict(self) -> list[dict[str, Any]]:
        """JSON/checkpoint-friendly form."""
        return [
            {
                "variable": v,
                "source": s,
                "target": t,
                "context": {u: sorted(m) for u, m in sorted(c.items())},
            }
            for (v, s, t), c in sorted(self.contexts.items())
        ]

    @classmethod
    def from_dict(cls, rows: Sequence[Mapping[str, Any]]) -> Coupling:
        return cls(
            {
                (str(r["variable"]), str(r["source"]), str(r["target"])): {
                    str(u): frozenset(map(str, m)) for u, m in r["context"].items()
                }
                for r in rows
            }
        )


class StallDetector:
    """Tracks when any variable last switched and when the features last moved.

    ``feature_range (d,)``: each feature's range in the training data; motion is measured
    relative to it, so the detector does not depend on the features' units.
    """

    def __init__(self, feature_range: np.ndarray, stall_time: float, rest_speed: float) -> None:
        r = np.asarray(feature_range, dtype=np.float64)
        self.inv_range = np.where(r > 1e-12 * max(float(np.max(r, initial=0.0)), 1e-300), 1 / r, 0)
        self.stall_time = stall_time
        self.rest_speed = rest_speed
        self._x: np.ndarray | None = None
        self._t = 0.0
        self.last_switch = 0.0
        self.last_motion = 0.0

    def reset(self, t: float, x: np.ndarray) -> None:
        self._x, self._t = np.array(x, dtype=np.float64), t
        self.last_switch = self.last_motion = t

    def observe(self, t: float, x: np.ndarray) -> None:
        """Feed the features ``x (d,)`` of the tick at ``t`` [s]."""
        dt = t - self._t
        if self._x is not None and dt > 0:
            speed = float(np.max(np.abs(x - self._x) * self.inv_range, initial=0.0)) / dt
            if speed > self.rest_speed:
                self.last_motion = t
        self._x, self._t = np.array(x, dtype=np.float64), t

    def switched(self, t: float) -> None:
        self.last_switch = t

    def stalled(self, t: float) -> bool:
        """No switch for ``stall_time`` and no motion for ``stall_time``."""
        since = t - self.stall_time + _EPS_T
        return self.last_switch <= since and self.last_motion <= since


def recovery_choice(
    candidates: Sequence[tuple[str, str, str, float, int]], threshold: float
) -> tuple[str, str, str, float] | None:
    """Pick the stall-recovery transition.

    ``candidates``: ``(variable, source, target, p, n_inconsistent)`` for every successor of
    every variable's current node. Returns the one with the fewest inconsistent other variables
    and, among those, the highest ``p``, if that ``p`` reaches ``threshold``; else ``None``.
    """
    ok = [c for c in candidates if c[3] >= threshold]
    if not ok:
        return None
    v, s, t, p, _ = min(ok, key=lambda c: (c[4], -c[3], c[0], c[2]))
    return v, s, t, p


__all__ = [
    "COUPLINGS",
    "SWITCH_RULES",
    "Coupling",
    "PaperRule",
    "PlateauRule",
    "StallDetector",
    "SwitchRule",
    "make_rule",
    "recovery_choice",
]
