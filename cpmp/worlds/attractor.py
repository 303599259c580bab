"""The goal of a first-order attractor, inferred from the positions it passes.

A goal is not a feature, but a first-order attractor ``ṗ = K s (g - p)`` gives it away: every
control tick moves the point by a fixed fraction ``c`` of what is left, so two consecutive steps
``d_1``, ``d_2`` of one activation satisfy ``d_2 = (1 - c) d_1`` and the goal is ``p + d_2 (1 -
c) / c``, whatever the gain, the speed factor ``s`` or the control period. A tick on which the
point does not move at all (a paced hold) tells nothing and is skipped: the step after it is
still ``(1 - c)`` times the step before it. The worlds' feature-only scripted policies use it
(:class:`AttractorGoal`) to tell arrival from a pause without reading the goals.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

MIN_STEP = 1e-10
"""Steps shorter than this (in the positions' unit) tell nothing about the goal: a hold, or a
point already at its goal to within floating-point noise."""


class _StepPair(NamedTuple):
    """Two consecutive steps of one activation (positions' unit).

    Attributes:
        end: ``(k,)`` where the later step ended.
        before: ``(k,)`` the earlier step.
        before_norm2: its squared length.
        step: ``(k,)`` the later step.
    """

    end: list[float]
    before: list[float]
    before_norm2: float
    step: list[float]


class AttractorGoal:
    """The goal of one first-order attractor, inferred from the positions it passes, tick by tick.

    Feed it the position every tick (:meth:`observe`) and call :meth:`restart` when the
    attractor's goal or speed may change (a new activation). The estimate (:meth:`goal`) is
    exact up to floating-point noise (about ``1e-11`` in the positions' unit) from the second
    step of an activation on, as long as the control ticks are equally spaced. Plain floats:
    it runs every tick of every closed-loop episode.

    Args:
        low: ``(k,)`` lower corner of the box the goal must lie in (e.g. the nominal goal less
            its jitter), or ``None`` for no bound.
        high: ``(k,)`` upper corner of that box, or ``None``.
        slack: how far outside the box an estimate may lie and still count (positions' unit).
    """

    def __init__(
        self,
        low: Sequence[float] | None = None,
        high: Sequence[float] | None = None,
        slack: float = 1e-6,
    ) -> None:
        self.low = None if low is None else [float(v) - slack for v in low]
        self.high = None if high is None else [float(v) + slack for v in high]
        self.position: list[float] | None = None
        """``(k,)`` the last position seen."""
        self.last: _StepPair | None = None
        """The running activation's last two steps longer than :data:`MIN_STEP`."""
        self._step: list[float] | None = None
        self._step_norm2 = 0.0

    def clear(self) -> None:
        """Forget everything (a new episode)."""
        self.position = None
        self.restart()

    def restart(self) -> None:
        """A new activation starts: forget its steps, keep the position."""
        self.last = None
        self._step = None
        self._step_norm2 = 0.0

    def observe(self, position: Sequence[float]) -> None:
        """The position ``(k,)`` after one more control tick of the running activation."""
        p = [float(v) for v in position]
        if self.position is not None:
            d = [a - b for a, b in zip(p, self.position, strict=True)]
            norm2 = math.fsum(v * v for v in d)
            if norm2 > MIN_STEP * MIN_STEP:
                if self._step is not None:
                    self.last = _StepPair(p, self._step, self._step_norm2, d)
                self._step, self._step_norm2 = d, norm2
        self.position = p

    def goal(self) -> list[float] | None:
        """``(k,)`` the running activation's goal, or ``None`` while unknown or out of bounds."""
        pair = self.last
        if pair is None:
            return None
        ratio = math.fsum(a * b for a, b in zip(pair.step, pair.before, strict=True))
        ratio /= pair.before_norm2  # 1 - c
        if not 0.0 < ratio < 1.0:
            return None  # not a fixed goal (it moves)
        k = ratio / (1.0 - ratio)
        goal = [p + k * d for p, d in zip(pair.end, pair.step, strict=True)]
        if self.low is not None and any(g < lo for g, lo in zip(goal, self.low, strict=True)):
            return None
        if self.high is not None and any(g > hi for g, hi in zip(goal, self.high, strict=True)):
            return None
        return goal

    def distance(self) -> float:
        """Distance from the last position to the estimated goal; ``inf`` while unknown."""
        goal = self.goal()
        if goal is None or self.position is None:
            return math.inf
        return math.dist(goal, self.position)
