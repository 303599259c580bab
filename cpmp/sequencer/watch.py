"""What an episode remembers of each switch that has not fired yet, to explain a missing one.

:class:`ActivationWatch` follows one activation of one variable's MP: per successor, the best
transition probability ``p`` since the MP became active and when, ``p`` at the last tick, and
how the edge stood at the last tick its ``p`` was above the threshold (still rising, held back,
outranked, after a give-up, or flat). A :class:`~cpmp.sequencer.episode.SequencerEpisode` keeps
one per activation (the finished ones too, so that a wrong switch can be explained later) and
feeds it every tick, O(successors); :meth:`ActivationWatch.pending` turns it into the
:class:`~cpmp.records.PendingSwitch` of one edge.

"Rising" mirrors the switching rules (:mod:`cpmp.sequencer.switching`) with O(1) state: while
``p`` stays above the threshold, an anchor moves to each value that beats it by more than
``min_improvement``; ``p`` counts as rising while the anchor is less than ``patience`` old.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Literal

from cpmp.records import CauseReason, PendingSwitch
from cpmp.sequencer.branches import STAY
from cpmp.sequencer.timing import EPS_T

EdgeStatus = Literal["", "rising", "flat", "held", "outranked", "stopped"]
"""How an edge stood at the last tick its ``p`` was above the threshold (``""``: never)."""


class ActivationWatch:
    """One activation of ``variable``'s MP ``current``, its successors' ``p`` followed.

    Args:
        variable: the control variable.
        current: the active MP.
        successors: its successors, in the order of each tick's ``p``.
        since: when it became active [s].
        threshold: the switching threshold.
        patience: the rule's patience [s].
        min_improvement: the rule's least improvement.
    """

    __slots__ = (
        "_above",
        "_anchor_m",
        "_anchor_p",
        "best",
        "best_t",
        "current",
        "detail",
        "last",
        "min_improvement",
        "patience",
        "since",
        "status",
        "successors",
        "threshold",
        "variable",
    )

    def __init__(
        self,
        variable: str,
        current: str,
        successors: Sequence[str],
        since: float,
        threshold: float,
        patience: float,
        min_improvement: float,
    ) -> None:
        n = len(successors)
        self.variable = variable
        self.current = current
        self.successors = list(successors)
        self.since = since
        self.threshold = threshold
        self.patience = patience
        self.min_improvement = min_improvement
        self.best = [-math.inf] * n
        """Per successor, the best ``p`` since :attr:`since`."""
        self.best_t = [math.nan] * n
        """Per successor, when it was reached [s]."""
        self.last: Sequence[float] = [math.nan] * n
        """Per successor, ``p`` at the last tick."""
        self.status: list[EdgeStatus] = [""] * n
        """Per successor, how it stood when last above the threshold."""
        self.detail = [""] * n
        """Per successor, what held it back when last above (empty if nothing)."""
        self._above = [False] * n
        self._anchor_p = [0.0] * n
        self._anchor_m = [0.0] * n

    def see(self, t: float, m: float, p: Sequence[float], stopped: bool) -> bool:
        """One tick's ``p`` (kept by reference, not copied).

        Args:
            t: the tick's time [s].
            m: its features' measurement time [s] (what the rules count patience on).
            p: each successor's ``p``.
            stopped: the episode has given up (nothing fires any more).

        Returns:
            Whether any ``p`` is above the threshold (then call :meth:`gate`).
        """
        self.last = p
        best, threshold, above = self.best, self.threshold, self._above
        any_above = False
        for i, q in enumerate(p):
            if q > best[i]:
                best[i] = q
                self.best_t[i] = t
            if q > threshold:
                any_above = True
                if not above[i] or q > self._anchor_p[i] + self.min_improvement:
                    self._anchor_p[i], self._anchor_m[i] = q, m
                above[i] = True
                if stopped:
                    self.status[i] = "stopped"
                elif m - self._anchor_m[i] < self.patience - EPS_T:
                    self.status[i] = "rising"
                else:
                    self.status[i] = "flat"
                self.detail[i] = ""
            else:
                above[i] = False
        return any_above

    def gate(self, allowed: Sequence[bool], chosen: str | None) -> None:
        """Mark the successors above the threshold at this tick that could not fire.

        Args:
            allowed: per successor, whether the coupling, the exit gate and the branch choice
                let it fire.
            chosen: the successor (or :data:`~cpmp.sequencer.branches.STAY`) the branch choice
                picked, ``None`` if the node does not branch.
        """
        p, threshold = self.last, self.threshold
        top = max((i for i, ok in enumerate(allowed) if ok), key=p.__getitem__, default=None)
        for i, q in enumerate(p):
            if q <= threshold or self.status[i] == "stopped":
                continue
            if not allowed[i]:
                self.status[i] = "held"
                if chosen == STAY:
                    self.detail[i] = f"the demonstrator kept {self.current} in states like this"
                elif chosen is not None and chosen != self.successors[i]:
                    self.detail[i] = f"the branch choice picked {chosen}"
                else:
                    self.detail[i] = ""  # the coupling: its hold note says why
            elif top is not None and top != i and p[top] > q:
                self.status[i] = "outranked"
                self.detail[i] = f"{self.successors[top]} had the higher p ({p[top]:.3f})"

    def wait(self, target: str, others: str) -> None:
        """``target`` is ready but waits for the switches ``others`` it is demonstrated with."""
        i = self.successors.index(target)
        self.status[i] = "held"
        self.detail[i] = f"waited for {others}"

    def pending(
        self,
        expected: str,
        gave_up: float | None,
        fired: str = "",
        at: float = math.nan,
    ) -> PendingSwitch:
        """The cause this activation gives for the missing switch to ``expected``.

        Args:
            expected: the demonstrator's next MP (empty: it switched no more).
            gave_up: when the episode gave up [s], or ``None``.
            fired: the MP this activation switched to instead (empty: none).
            at: when that switch fired [s].

        Returns:
            The :class:`~cpmp.records.PendingSwitch`.
        """
        v, current, threshold = self.variable, self.current, self.threshold
        if expected not in self.successors:
            reason: CauseReason = "wrong_transition" if fired else "not_a_successor"
            detail = "" if fired or not expected else self._successors_text()
            return PendingSwitch(
                v,
                current,
                expected,
                reason,
                threshold=threshold,
                fired=fired,
                at=at,
                detail=detail,
            )
        i = self.successors.index(expected)
        best = self.best[i]
        status = self.status[i]
        detail = ""
        up = math.nan if gave_up is None else gave_up
        if fired:
            reason, up = "wrong_transition", at
        elif status in ("held", "outranked"):
            reason, detail = "held", self.detail[i]
        elif status == "stopped":
            reason = "given_up"
        elif status in ("rising", "flat"):
            reason = "still_improving"
            if status == "flat":  # the rule would have fired on a plateau: p dipped and rose
                detail = (
                    f"p had stopped gaining more than {self.min_improvement:g} for "
                    f"{self.patience:g} s, but rose again above its value {self.patience:g} s "
                    "before, so the rule still saw it improving: a p that wobbles near its "
                    "plateau"
                )
        else:
            reason = "below_threshold"
        return PendingSwitch(
            v,
            current,
            expected,
            reason,
            best_p=best if math.isfinite(best) else math.nan,
            best_t=self.best_t[i],
            final_p=float(self.last[i]),
            threshold=threshold,
            fired=fired,
            at=up if reason in ("given_up", "below_threshold", "wrong_transition") else math.nan,
            detail=detail,
        )

    def _successors_text(self) -> str:
        """``successors: a, b`` (or that there are none)."""
        if not self.successors:
            return f"{self.current} is a final node"
        return "its successors: " + ", ".join(self.successors)


__all__ = ["ActivationWatch", "EdgeStatus"]
