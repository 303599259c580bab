"""One episode of a fitted sequencer: the state machine of the transition rule.

:class:`SequencerEpisode` holds one episode's state (active MPs, events, notes, the switching
rules' histories, the stall detector) and applies the transition rule to the φ it is handed:
the start rule at :meth:`~SequencerEpisode.start`, the transitions, holds and recoveries at
every :meth:`~SequencerEpisode.advance`, on the measurement time of each tick's features
(:mod:`cpmp.sequencer.timing`). It reads the fitted sequencer only through its
:class:`~cpmp.sequencer.model.TransitionModel`; :class:`~cpmp.sequencer.ConcurrentSequencer`
drives one episode, :class:`~cpmp.sequencer.batch.BatchedSequencer` many.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from typing import NamedTuple

import numpy as np

from cpmp.errors import DataError, NotFittedError
from cpmp.records import (
    PendingSwitch,
    SequencerNote,
    StartDecision,
    StartOption,
    SwitchKind,
    TickInfo,
    TransitionEvent,
    divergence,
)
from cpmp.sequencer.branches import STAY
from cpmp.sequencer.inputs import checked_stamp, checked_time
from cpmp.sequencer.model import TransitionModel
from cpmp.sequencer.motion import SpeedLimit, SpeedMeter, without_ambient
from cpmp.sequencer.switching import (
    Candidate,
    Coupling,
    Edge,
    JointPartner,
    StallDetector,
    make_rule,
    recovery_choice,
    transition_p,
)
from cpmp.sequencer.timing import EPS_T, MEASUREMENT_STEP, MeasurementClock
from cpmp.sequencer.watch import ActivationWatch


class PhiCheck(NamedTuple):
    """A φ that adds one inconsistency to a successor while it is below its bound (coupling).

    Attributes:
        successor: the successor's position in its :class:`PlanRow`.
        column: the φ column of another variable's active MP.
        bound: the least progress demonstrated at this switch minus the margin.
    """

    successor: int
    column: int
    bound: float


MAX_BETWEEN = 50
"""The most states :meth:`SequencerEpisode.advance` decides on between two measurements (a
gap of up to 0.51 s at 10 ms; a longer one, a sensor that came back, more coarsely)."""


class PlanRow(NamedTuple):
    """One variable's part of the transition plan, fixed while the active MPs do not change.

    Attributes:
        variable: the control variable.
        current: its active MP.
        successors: the active MP's successors (sorted).
        columns: their φ columns.
        exit_column: the active MP's φ column.
        unseen: per successor, the number of other variables running an MP never seen at
            that switch (:meth:`~cpmp.sequencer.switching.Coupling.gates`).
        checks: the φ that add one inconsistency each while below their bound.
        joints: per successor, the other variables' switches it is demonstrated together
            with, as ``(variable, partner)`` (:attr:`~cpmp.sequencer.switching.Coupling.joint`).
        entry_scale: per successor, the factor on its entry probability
            (:attr:`~cpmp.sequencer.branches.BranchChoices.entry_scale`; 1 for most).
        speed: per successor, the switch's speed envelope (one inconsistency while exceeded;
            ``None``: none, :attr:`~cpmp.sequencer.switching.Coupling.speed`).
    """

    variable: str
    current: str
    successors: list[str]
    columns: list[int]
    exit_column: int
    unseen: list[int]
    checks: list[PhiCheck]
    joints: list[list[tuple[str, JointPartner]]]
    entry_scale: list[float]
    speed: list[SpeedLimit | None]


class TransitionPlan(NamedTuple):
    """What every tick needs while the active MPs are ``context``.

    Attributes:
        context: variable -> active MP when the plan was made.
        rows: one :class:`PlanRow` per variable with successors, sorted by variable.
    """

    context: dict[str, str]
    rows: list[PlanRow]


class TickRow(NamedTuple):
    """One variable's transition probabilities at one tick.

    Attributes:
        variable: the control variable.
        current: its active MP at the tick.
        successors: the active MP's successors.
        p: each successor's transition probability ``φ_current · (1 - φ_successor)`` (the
            entry scaled for a re-entered successor, capped at 1).
        inconsistent: per successor, the number of other variables inconsistent with the
            demonstrated contexts of that switch.
    """

    variable: str
    current: str
    successors: list[str]
    p: list[float]
    inconsistent: list[int]


class _TickProbabilities(NamedTuple):
    """The first step of a tick (:meth:`SequencerEpisode._probabilities`).

    Attributes:
        rows: one :class:`TickRow` per variable with successors, in the plan's order.
        chosen_by: variable -> the successor its branching node lets fire (``None``: no
            branch choice there).
        above: the variables whose watch saw a ``p`` above the threshold this tick.
    """

    rows: list[TickRow]
    chosen_by: dict[str, str | None]
    above: set[str]


class _PendingTick(NamedTuple):
    """What a tick computed, kept until :attr:`SequencerEpisode.last_tick` is read."""

    t: float
    phi: list[float]
    rows: list[TickRow]
    active: dict[str, str]
    held: dict[str, str]


def _partner_p(
    u: str, partner: JointPartner, context: Mapping[str, str], rows: Sequence[TickRow]
) -> float | None:
    """The ``p`` of joint partner ``u``'s switch into ``partner.target`` at this tick.

    ``None`` unless ``u`` runs one of the partner's source MPs (``context``) and that switch is
    one of its successors (``rows``: the tick's rows, one per variable with successors).
    """
    row = next((r for r in rows if r.variable == u), None)
    if context.get(u) not in partner.sources or row is None:
        return None
    if partner.target not in row.successors:
        return None
    return row.p[row.successors.index(partner.target)]


def _with_partners_demonstrated(
    candidates: Sequence[Candidate], coupling: Coupling, active: Mapping[str, str]
) -> tuple[list[Candidate], dict[Edge, str]]:
    """``candidates``, each marked not demonstrated where a joint partner it takes is not.

    A joint switch was always made together with its partners, so a recovery takes them along;
    when a partner's own switch is not the demonstrator's here (another variable's jammed
    ``try``, whose nearest demonstrated state went to ``undo``, carried into ``next`` by the
    holder's ``hold -> retreat``), the pair was not demonstrated here either.

    Returns:
        The candidates, and for each one newly marked (by its switch) the partner switch that
        was not the demonstrator's (``"u: a -> b"``).
    """
    made = {(c.variable, c.target): c.demonstrated for c in candidates}
    out, passed = [], {}
    for cand in candidates:
        partners = coupling.joint.get((cand.variable, cand.source, cand.target), {})
        bad = [
            f"{u}: {active[u]} -> {partner.target}"
            for u, partner in sorted(partners.items())
            if active.get(u) in partner.sources and not made.get((u, partner.target), True)
        ]
        if bad and cand.demonstrated:
            passed[_edge(cand)] = bad[0]
            cand = cand._replace(demonstrated=False)
        out.append(cand)
    return out, passed


def _passed_over(
    first: Candidate | None, choice: Candidate | None, passed: Mapping[Edge, str]
) -> str:
    """A note's clause on the joint switch a recovery would have taken but for a partner.

    Empty unless ``first``, the recovery's pick before the partners were checked, is one of
    the switches in ``passed`` and differs from ``choice``, its pick after.
    """
    if first is None or _edge(first) not in passed or (choice and _edge(choice) == _edge(first)):
        return ""
    return (
        f"; not {first.variable}: {first.source} -> {first.target} (p={first.p:.2f}), which "
        f"would take {passed[_edge(first)]} along, not the demonstrator's switch here"
    )


def _edge(candidate: Candidate) -> Edge:
    """The switch of ``candidate``: ``(variable, source, target)``."""
    return candidate.variable, candidate.source, candidate.target


class SequencerEpisode:
    """The state of one episode of a fitted sequencer.

    It holds the active MPs, the events, the notes, the switching rules' histories and the
    stall detector. :class:`~cpmp.sequencer.ConcurrentSequencer` drives one,
    :class:`~cpmp.sequencer.batch.BatchedSequencer` many; both evaluate the predictor
    themselves and hand each episode its φ, so one episode decides the same way in either.

    Args:
        model: the fitted sequencer's graphs, node index, options, coupling, feature ranges
            and demonstrated starts.
    """

    def __init__(self, model: TransitionModel) -> None:
        self.model = model
        self.active: dict[str, str] = {}
        """Variable -> active MP (empty before :meth:`start`)."""
        self.events: list[TransitionEvent] = []
        self.notes: list[SequencerNote] = []
        self.start_decision: StartDecision | None = None
        """How :meth:`start` chose the initial MPs (``None`` before it)."""
        c = model.config
        self._rules = {
            v: make_rule(c.switch_rule, c.threshold, c.patience, c.min_improvement)
            for v in model.graphs
        }
        self._coupled = c.coupling == "context"
        self._stall = StallDetector(
            without_ambient(model.feature_range, model.coupling.ambient),
            c.stall_time,
            c.rest_speed,
        )
        self._speed = SpeedMeter(model.feature_range)
        self._since: dict[str, float] = {}
        """Per variable, the measurement time [s] at which its active MP became active."""
        self._top: dict[str, np.ndarray] = {}
        """Per variable, each feature's top speed ``(d,)`` [ranges/s] since then (what the
        speed envelopes' second bound reads)."""
        self._moving: dict[str, np.ndarray | None] = {}
        """Per variable, each feature's speed ``(d,)`` [ranges/s] since then, as of the last
        measurement (``None`` before one a window old, or taken after it): what the speed
        envelopes read, measured once per measurement."""
        self._clock = MeasurementClock(c.stale_time)
        self._holding: dict[str, str | None] = {}
        self._armed: dict[str, str] = {}
        self._last_t: float | None = None
        self._measured: tuple[float, np.ndarray] | None = None
        """The last finite new measurement: its time [s] and features ``(d,)``."""
        self._repeats = False
        """Whether a tick repeated the last measurement since it was made."""
        self._nonfinite = False
        self.gave_up: float | None = None
        """The time [s] the episode gave up (a stall no demonstrated transition resolves;
        it switches no more), or ``None``."""
        self._plan: TransitionPlan | None = None
        self._tick: TickInfo | None = None
        self._pending: _PendingTick | None = None
        self._watch: dict[str, list[ActivationWatch]] = {}
        """Per variable, one watch per activation, the active one last (:meth:`explain`)."""

    @property
    def last_tick(self) -> TickInfo | None:
        """What the last tick computed (built on first access after the tick)."""
        pending = self._pending
        if pending is not None:
            model = self.model
            probs: dict[str, dict[str, float]] = {v: {} for v in sorted(model.graphs)}
            for row in pending.rows:
                probs[row.variable] = dict(zip(row.successors, row.p, strict=True))
            self._tick = TickInfo(
                pending.t, model.nodes.phi_dict(pending.phi), probs, pending.active, pending.held
            )
            self._pending = None
        return self._tick

    def explain(self, expected: Mapping[str, Sequence[str]]) -> PendingSwitch | None:
        """Why the episode has not run the demonstrator's MP sequences: the missing switch.

        The first place the episode's sequences leave ``expected``
        (:func:`~cpmp.records.divergence`): a wrong switch is named with the ``p`` its
        demonstrated alternative reached; a switch still pending with the best ``p`` of its
        edge since the MP became active, when, ``p`` now, and why the rule did not fire
        (:class:`~cpmp.records.PendingSwitch`).

        Args:
            expected: variable -> the MPs the demonstrator ran on the same context.

        Returns:
            The cause, or ``None`` before :meth:`start`, after a wrong start, or when the
            sequences equal ``expected``.
        """
        if not self._watch:
            return None
        sequences = {v: [w.current for w in watches] for v, watches in self._watch.items()}
        found = divergence(sequences, expected)
        if found is None:
            return None
        watch = self._watch[found.variable][found.index - 1]
        if found.fired:
            mine = [e for e in self.events if e.variable == found.variable]
            at = mine[found.index - 1].t
            return watch.pending(found.expected, self.gave_up, found.fired, at)
        cause = watch.pending(found.expected, self.gave_up)
        if cause.reason == "held" and not cause.detail:
            notes = [
                n.text
                for n in self.notes
                if n.kind == "hold" and n.variable == found.variable and n.t >= watch.since
            ]
            text = notes[-1] if notes else "held back by the coupling"
            cause = replace(cause, detail=text)
        return cause

    def start(self, t: float, x: np.ndarray, phi: np.ndarray) -> dict[str, str]:
        """Begin the episode: the start rule on the features and every node's φ.

        Args:
            t: the time [s].
            x: the features ``(d,)``.
            phi: every node's φ ``(K,)``.

        Returns:
            Variable -> initial MP.

        Raises:
            DataError: a φ is not finite.
        """
        if not np.isfinite(phi).all():
            raise DataError(
                "the progress predictor gave a non-finite φ at reset; the model is broken "
                "(check its parameters) or the features are far outside the training data"
            )
        model = self.model
        self.start_decision = self._initial_mps(t, x, phi)
        self.active = dict(self.start_decision.chosen)
        self.events = []
        self.notes = []
        self._watch = {v: [self._new_watch(v, t)] for v in sorted(model.graphs)}
        for v, rule in self._rules.items():
            rule.reset()
            self._observe_entry(v, t, phi)
        self._holding = {v: None for v in model.graphs}
        self._armed = {}
        state = np.asarray(x, dtype=np.float64).reshape(-1)
        m = self._clock.reset(t, state)
        self._measured, self._repeats = (m, state), False
        self._stall.reset(m, state)
        self._speed.reset(m, state)
        self._since = dict.fromkeys(model.graphs, m)
        self._top = {v: np.zeros(state.size) for v in model.graphs}
        self._moving = dict.fromkeys(model.graphs)
        self._last_t = t
        self._nonfinite = False
        self.gave_up = None
        self._plan = None
        self._pending = None
        self._tick = TickInfo(
            t, model.nodes.phi_dict(phi), {v: {} for v in model.graphs}, dict(self.active)
        )
        return dict(self.active)

    def check_time(self, t: float, stamp: float | None = None) -> float:
        """The time of the next tick, checked (and its features' stamp, if given).

        Args:
            t: the time [s].
            stamp: when the tick's features were measured [s] (``None``: unknown).

        Returns:
            ``t`` as a float.

        Raises:
            NotFittedError: the episode was not started.
            DataError: ``t`` is not finite or goes back in time; ``stamp`` is not finite or
                later than ``t``.
        """
        if not self.active:
            raise NotFittedError("call reset(t, x) before step(t, x)")
        t = checked_time(t)
        if self._last_t is not None and t < self._last_t:
            raise DataError(f"time went backwards: step at t={t} after t={self._last_t}")
        checked_stamp(stamp, t)
        return t

    def advance(
        self,
        t: float,
        state: np.ndarray,
        phi: list[float] | None,
        finite: bool,
        stamp: float | None = None,
        progress: Callable[[np.ndarray], np.ndarray] | None = None,
    ) -> dict[str, str]:
        """One tick of the transition rule: switches, holds and stall recovery.

        A new measurement two :data:`~cpmp.sequencer.timing.MEASUREMENT_STEP` or more after
        the last one (a slow loop, dropped ticks; a slow sensor whose ticks carry stamps) is
        decided on along the way from the last one: the states linearly between the two, at most
        ``MEASUREMENT_STEP`` apart, each at its own measurement time, come first
        (:meth:`_decide` on each, as a measurement would). A ``p`` that peaks between two
        samples of a slow sensor — an event seen only as a jump, the state carried past the
        demonstrated switch by the next sample — is then not skipped: the rule sees it rise
        and fall back as a fast loop would, and the switch fires at this tick (the new MP's
        activation starting at this measurement; the states after it are not read). Without a
        stamp, a new measurement after ticks that repeated the last one has none in between
        (when the state changed is not known).

        Args:
            t: the time [s] (checked by :meth:`check_time`).
            state: the features ``(d,)``.
            phi: the nodes' φ ``(K,)`` as a list; ``None``: the features are not finite (the
                predictor was not evaluated).
            finite: whether all of ``phi`` is finite.
            stamp: when ``state`` was measured [s] (checked by :meth:`check_time`; ``None``:
                unknown, see :mod:`cpmp.sequencer.timing`).
            progress: the nodes' φ of states ``(n, d)``: ``(n, K)``, for the states between
                two measurements; ``None``: none (a stateful predictor, whose φ depends on
                the stream of states it was given).

        Returns:
            Variable -> active MP after the tick.

        Raises:
            DataError: the features or a φ are not finite and the option ``nonfinite`` is
                ``raise``.
        """
        self._last_t = t
        reading = self._clock.tick(t, state if phi is not None else None, stamp)
        if reading.clock_step > 0.0:
            self._note_clock_step(t, reading.clock_step)
        if phi is None or not finite:
            self._measured = None
            return self._hold_nonfinite(t, state, phi)
        self._nonfinite = False
        m = reading.m
        if not reading.fresh:
            self._repeats = True
        else:
            # without a stamp, after repeats of the last measurement, when the state changed
            # between the two is not known: no states in between then
            last = self._measured if stamp is not None or not self._repeats else None
            self._measured, self._repeats = (m, np.array(state, dtype=np.float64)), False
            if last is not None and progress is not None:
                for m_k, x_k, phi_k in self._between(last, m, state, progress):
                    before = dict(self.active)
                    self._decide(t, m_k, x_k, phi_k, True)
                    switched = [v for v, mp in before.items() if self.active[v] != mp]
                    if switched:
                        # the robot runs the new MPs from this tick on: their activations
                        # start at this measurement, not at the state in between
                        for v in switched:
                            self._reanchor(v, m, phi)
                        break
        return self._decide(t, m, state, phi, reading.fresh)

    def _reanchor(self, v: str, m: float, phi: list[float]) -> None:
        """Start ``v``'s activation at the measurement ``m`` [s] with φ ``phi`` (K,).

        What the active MP's rule, speed envelope and stall time read starts there: at a
        switch (:meth:`_switch`), and again at the tick's own measurement for a switch decided
        on a state between two measurements, which takes effect at that tick.
        """
        self._rules[v].reset()
        self._observe_entry(v, m, phi)
        self._stall.switched(m)
        self._since[v] = m
        self._top[v] = np.zeros_like(self._top[v])
        self._moving[v] = None  # nothing measured after m yet

    def _between(
        self,
        last: tuple[float, np.ndarray],
        m: float,
        state: np.ndarray,
        progress: Callable[[np.ndarray], np.ndarray],
    ) -> list[tuple[float, np.ndarray, list[float]]]:
        """The states between the measurement ``last`` and ``state`` measured at ``m`` [s].

        Returns:
            ``(measurement time, features (d,), φ (K,))`` of each, in time order (at most
            :data:`MAX_BETWEEN`, evenly spaced: a long gap is read more coarsely); none when
            the two are less than two :data:`~cpmp.sequencer.timing.MEASUREMENT_STEP` apart
            or a φ between them is not finite.
        """
        m0, x0 = last
        n = min(math.floor((m - m0) / MEASUREMENT_STEP + EPS_T), MAX_BETWEEN + 1)
        if n < 2:
            return []
        w = np.arange(1, n)[:, None] / n
        xs = x0 + w * (state - x0)
        phis = np.asarray(progress(xs), dtype=np.float64)
        if not np.isfinite(phis).all():
            return []
        times = m0 + w[:, 0] * (m - m0)
        return [(float(mk), xk, row) for mk, xk, row in zip(times, xs, phis.tolist(), strict=True)]

    def _decide(
        self, t: float, m: float, state: np.ndarray, phi: list[float], fresh: bool
    ) -> dict[str, str]:
        """The rule on the features ``state (d,)`` measured at ``m`` [s], at the tick ``t``."""
        if fresh:
            self._stall.observe(m, state)
            self._speed.observe(m, state)
            if self._coupled:
                self._observe_speeds()
        if self._plan is None:
            context = dict(self.active)
            self._plan = TransitionPlan(context, self._transition_plan(context))
        context, plan = self._plan
        stopped = self.gave_up is not None
        # 1. every successor's p, the branch choices, which watches saw p above the threshold
        probs = self._probabilities(t, m, state, phi, plan, stopped)
        # 2. each variable's rule decides; the coupling and the branch choice hold some back
        held: dict[str, str] = {}
        going = {} if stopped else self._rule_decisions(t, m, phi, probs, context, held)
        # 3. the switches fire, those demonstrated together with another's waiting for it (or
        #    taking it along)
        ready = {**self._armed, **going}
        fired = self._fire(t, m, state, phi, plan, probs.rows, ready, context, held)
        # 4. no switch and the features at rest: recover, or give up
        c = self.model.config
        if not (fired or stopped) and c.recovery and fresh and self._stall.stalled(m):
            self._resolve_stall(t, m, state, phi, probs.rows, plan)
        active = dict(self.active)
        self._pending = _PendingTick(t, phi, probs.rows, active, held)
        return dict(active)

    def _observe_speeds(self) -> None:
        """At a new measurement, each variable's speeds since its MP became active.

        They are kept for the tick's rule (:attr:`_moving`), and its top speeds raised to them.
        """
        for v, top in self._top.items():
            speed = self._speed.speed(self._since[v])
            self._moving[v] = speed
            if speed is not None:
                np.maximum(top, speed, out=top)

    def _note_clock_step(self, t: float, step: float) -> None:
        """Note a jump of ``step`` [s] beyond the tick period at ``t`` [s] (one tick)."""
        period = self._clock.period or 0.0
        self.notes.append(
            SequencerNote(
                t,
                "clock_step",
                "",
                f"the time jumped by {step + period:.3f} s (ticks every "
                f"{period:.3f} s): a clock step, counted as one tick",
            )
        )

    def _probabilities(
        self,
        t: float,
        m: float,
        state: np.ndarray,
        phi: list[float],
        plan: list[PlanRow],
        stopped: bool,
    ) -> _TickProbabilities:
        """Every variable's successor ``p`` at ``t`` [s] (measured at ``m`` [s]).

        Also the successor each branching node lets fire at ``state (d,)`` and, through each
        active MP's watch, which variables have a ``p`` above the threshold.
        """
        rows = []
        chosen_by: dict[str, str | None] = {}
        above: set[str] = set()
        for v, current, names, columns, exit_column, unseen, checks, _, scale, limits in plan:
            exit_p = phi[exit_column]
            p = [transition_p(exit_p, phi[i], g) for i, g in zip(columns, scale, strict=True)]
            bad = unseen
            if checks:
                bad = list(unseen)
                for successor, column, bound in checks:
                    if phi[column] < bound:
                        bad[successor] += 1
            # the speeds since the source MP became active (over SPEED_WINDOW at most), for the
            # variables with a speed envelope on a successor
            speed = None
            if self._coupled and any(limit is not None for limit in limits):
                speed = self._moving[v]
            if speed is not None:
                for k, limit in enumerate(limits):
                    if limit is not None and limit.exceeded(speed, self._top[v]).size:
                        bad = list(bad) if bad is unseen else bad
                        bad[k] += 1
            rows.append(TickRow(v, current, names, p, bad))
            chosen_by[v] = self._branch_choice(v, current, names, unseen, state)
            if self._watch[v][-1].see(t, m, p, stopped):
                above.add(v)
        return _TickProbabilities(rows, chosen_by, above)

    def _rule_decisions(
        self,
        t: float,
        m: float,
        phi: list[float],
        probs: _TickProbabilities,
        context: dict[str, str],
        held: dict[str, str],
    ) -> dict[str, str]:
        """Each variable's switching rule on its allowed successors: the switches it fires.

        A successor is allowed when (with the coupling) its context was demonstrated and (at
        a branching node) it is the chosen one. A best successor above the threshold that is
        not allowed is held: added to ``held`` (variable -> target) and noted once.

        Returns:
            Variable -> the successor its rule fires.
        """
        c = self.model.config
        coupled = self._coupled
        going: dict[str, str] = {}
        for v, current, names, p, bad in probs.rows:
            allowed = [b == 0 for b in bad] if coupled else [True] * len(p)
            chosen = probs.chosen_by[v]
            if chosen is not None:
                allowed = [ok and s == chosen for ok, s in zip(allowed, names, strict=True)]
            k = self._rules[v].update(m, p, allowed)
            if v in probs.above:
                self._watch[v][-1].gate(allowed, chosen)
            armed = self._armed.get(v)
            if armed is not None and (armed not in names or p[names.index(armed)] <= c.threshold):
                self._armed.pop(v)
            if k is not None:
                going[v] = names[k]
            if (coupled or chosen is not None) and not all(allowed):
                top = 0 if len(p) == 1 else max(range(len(p)), key=p.__getitem__)
                if chosen in names:
                    top = names.index(chosen)
                if p[top] > c.threshold and not allowed[top] and k != top:
                    held[v] = names[top]
                    if self._holding.get(v) != names[top]:
                        stay = chosen == STAY
                        self._note_hold(t, v, current, names[top], p[top], context, phi, stay)
            self._holding[v] = held.get(v)
        return going

    def _fire(
        self,
        t: float,
        m: float,
        state: np.ndarray,
        phi: list[float],
        plan: list[PlanRow],
        rows: list[TickRow],
        ready: dict[str, str],
        context: dict[str, str],
        held: dict[str, str],
    ) -> bool:
        """Fire the ``ready`` switches (variable -> target); whether any fired.

        With joint switches, one always demonstrated together with another variable's switch
        waits (armed, held and noted) until that one is ready too; a partner it carries
        (:attr:`~cpmp.sequencer.switching.JointPartner.carried`) and that is ready for nothing
        else switches with it.
        """
        joint = self._coupled and self.model.config.joint
        carried: set[str] = set()
        fired = False
        for plan_row, row in zip(plan, rows, strict=True):
            v = row.variable
            target = ready.get(v)
            if target is None or v in carried:
                continue
            k = row.successors.index(target)
            waits, along = [], []
            for u, partner in plan_row.joints[k] if joint else []:
                b = partner.target
                if context[u] == b or ready.get(u) == b:
                    continue
                q = _partner_p(u, partner, context, rows)
                if partner.carried and ready.get(u) is None and q is not None:
                    along.append((u, b, q))
                else:
                    waits.append((u, partner.source_text, b))
            if waits:
                if self._armed.get(v) != target:
                    self._armed[v] = target
                    self._note_joint(t, v, row.current, target, row.p[k], waits)
                self._watch[v][-1].wait(target, "; ".join(f"{u}: {a} -> {b}" for u, a, b in waits))
                held[v] = target
                self._holding[v] = target
                continue
            self._armed.pop(v, None)
            self._switch(t, m, v, target, row.p[k], state, phi, "switch")
            for u, b, q in along:
                if u not in carried:
                    carried.add(u)
                    held.pop(u, None)
                    self._switch(t, m, u, b, q, state, phi, "switch")
            fired = True
        return fired

    def _branch_choice(
        self, v: str, current: str, names: list[str], unseen: list[int], state: np.ndarray
    ) -> str | None:
        """The successor ``v``'s branching node ``current`` lets fire at ``state (d,)``.

        Chosen among the successors demonstrated in the current context (all of them if none
        is); ``None`` if the node does not branch (:mod:`cpmp.sequencer.branches`).
        """
        choice = self.model.branches.get(v, current)
        if choice is None:
            return None
        among = [s for s, n in zip(names, unseen, strict=True) if n == 0] or names
        return choice.choose(state, among)

    def _hold_nonfinite(
        self, t: float, state: np.ndarray, phi: list[float] | None
    ) -> dict[str, str]:
        """A tick with non-finite features (``phi`` ``None``) or φ: every MP kept, noted once.

        Raises:
            DataError: the option ``nonfinite`` is ``raise``.
        """
        model = self.model
        if phi is None:
            bad = [str(j) for j in np.flatnonzero(~np.isfinite(state))]
            text = f"non-finite features (columns {', '.join(bad[:5])}); every MP kept"
            phi = [math.nan] * len(model.nodes.keys)
        else:
            bad = [
                f"{v}/{mp}"
                for (v, mp), f in zip(model.nodes.keys, phi, strict=True)
                if not math.isfinite(f)
            ]
            text = f"non-finite φ for {', '.join(bad[:5])}; every MP kept"
        if model.config.nonfinite == "raise":
            raise DataError(f"at t={t}: {text} (sequencer option nonfinite='raise')")
        if not self._nonfinite:
            self.notes.append(SequencerNote(t, "nonfinite", "", text))
            self._nonfinite = True
        self._tick = TickInfo(t, model.nodes.phi_dict(phi), {}, dict(self.active))
        self._pending = None
        return dict(self.active)

    def _resolve_stall(
        self,
        t: float,
        m: float,
        state: np.ndarray,
        phi: list[float],
        rows: list[TickRow],
        plan: list[PlanRow],
    ) -> None:
        """A stall: recover with a consistent transition, or give up, or (at the end) nothing.

        See :mod:`cpmp.sequencer.switching` (Recovery).
        """
        model = self.model
        c = model.config
        candidates = []
        for row, plan_row in zip(rows, plan, strict=True):
            # the demonstrator, in the demonstrated state nearest this one, went to `nearest`
            nearest = model.coupling.nearest_target(row.variable, row.current, state, self.active)
            candidates += [
                Candidate(row.variable, row.current, s, q, b, n == 0 and nearest in (None, s))
                for s, q, b, n in zip(
                    row.successors, row.p, row.inconsistent, plan_row.unseen, strict=True
                )
            ]
        checked: list[Candidate] = candidates
        passed: dict[Edge, str] = {}
        if self._coupled and c.joint:
            checked, passed = _with_partners_demonstrated(candidates, model.coupling, self.active)
        choice = recovery_choice(checked, c.recovery_threshold)
        over = ""
        if passed:
            over = _passed_over(recovery_choice(candidates, c.recovery_threshold), choice, passed)
        if choice is not None:
            v = choice.variable
            context = dict(self.active)
            self._switch(t, m, v, choice.target, choice.p, state, phi, "recovery")
            text = f"{v}: {choice.source} -> {choice.target} (p={choice.p:.2f})"
            if self._coupled and c.joint:
                # the switches it was always demonstrated together with come along
                joint = model.coupling.joint.get((v, choice.source, choice.target), {})
                for u, partner in sorted(joint.items()):
                    q = _partner_p(u, partner, context, rows)
                    if q is not None:
                        b = partner.target
                        self._switch(t, m, u, b, q, state, phi, "recovery")
                        text += f" with {u}: {context[u]} -> {b} (p={q:.2f}, demonstrated together)"
            self.notes.append(
                SequencerNote(
                    t, "recovery", v, f"stall of {c.stall_time:g} s resolved: {text}{over}"
                )
            )
            return
        open_rows = [row for row in plan if 0 in row.unseen]
        if not open_rows:
            return  # every node is final here: the task's demonstrated end
        self.gave_up = t
        waiting = "; ".join(
            f"{row.variable}: {row.current} -> "
            + ", ".join(s for s, n in zip(row.successors, row.unseen, strict=True) if n == 0)
            for row in open_rows
        )
        floor = f", p >= {c.recovery_threshold:g}" if c.recovery_threshold > 0 else ""
        self.notes.append(
            SequencerNote(
                t,
                "give_up",
                "",
                f"stall of {c.stall_time:g} s that no demonstrated switch resolves (made by the "
                f"demonstrator here{floor}); demonstrated in this context: {waiting}; every MP "
                f"kept from now on{over}",
            )
        )

    def _initial_mps(self, t: float, x: np.ndarray, phi: np.ndarray) -> StartDecision:
        """The start rule at ``t`` [s] on the features ``x (d,)`` or every node's φ ``(K,)``.

        Returns:
            The MPs and the scores. See :meth:`~cpmp.sequencer.ConcurrentSequencer.reset`.
        """
        model = self.model
        rule = model.config.start_rule
        start = model.branches.start
        if rule == "learned" and start is not None:
            prob = start.probabilities(np.asarray(x, dtype=np.float64).reshape(-1))
            options = [
                StartOption(dict(combo), float(np.log(max(q, 1e-300))))
                for combo, q in zip(start.combinations, prob, strict=True)
            ]
            chosen = dict(start.combinations[int(np.argmax(prob))])
            return StartDecision(t, "learned", options, chosen)
        index = model.nodes.index
        entry = np.clip(1.0 - phi, 1e-12, 1.0)
        if rule in ("joint", "learned") and model.initial_combinations:
            scores = [
                sum(np.log(entry[index[(v, mp)]]) for v, mp in combo.items())
                for combo in model.initial_combinations
            ]
            options = [
                StartOption(dict(combo), float(score))
                for combo, score in zip(model.initial_combinations, scores, strict=True)
            ]
            chosen = dict(model.initial_combinations[int(np.argmax(scores))])
            return StartDecision(t, "joint", options, chosen)
        active, options = {}, []
        for v in sorted(model.graphs):
            initial = sorted(model.graphs[v].initial_nodes)
            entry_v = [1.0 - phi[index[(v, mp)]] for mp in initial]
            active[v] = initial[int(np.argmax(entry_v))]
            options += [
                StartOption({v: mp}, float(np.log(entry[index[(v, mp)]]))) for mp in initial
            ]
        return StartDecision(t, "independent", options, active)

    def _transition_plan(self, context: Mapping[str, str]) -> list[PlanRow]:
        """What every tick needs while the active MPs are ``context``.

        Args:
            context: variable -> active MP.

        Returns:
            One :class:`PlanRow` per variable with successors, sorted by variable.
        """
        model = self.model
        nodes = model.nodes
        margin = model.config.progress_margin
        plan = []
        for v in sorted(model.graphs):
            current = context[v]
            names, columns = nodes.successors[(v, current)]
            if not names:
                continue
            unseen_counts, checks, joints = [], [], []
            limits: list[SpeedLimit | None] = []
            for k, s in enumerate(names):
                unseen, bounds = model.coupling.gates((v, current, s), context, margin)
                unseen_counts.append(len(unseen))
                joint = model.coupling.joint.get((v, current, s), {})
                joints.append([(u, j) for u, j in sorted(joint.items()) if u in context])
                limits.append(model.coupling.speed.get((v, current, s)))
                checks += [
                    PhiCheck(k, nodes.index[(b.variable, context[b.variable])], b.bound)
                    for b in bounds
                    if b.variable in context
                ]
            plan.append(
                PlanRow(
                    v,
                    current,
                    names,
                    columns,
                    nodes.index[(v, current)],
                    unseen_counts,
                    checks,
                    joints,
                    [model.branches.entry_scale.get((v, current, s), 1.0) for s in names],
                    limits,
                )
            )
        return plan

    def _note_hold(
        self,
        t: float,
        v: str,
        current: str,
        target: str,
        p: float,
        context: dict[str, str],
        phi: list[float],
        stay: bool = False,
    ) -> None:
        """Note a transition the coupling (or, with ``stay``, the branch choice) holds back."""
        model = self.model
        if stay:
            text = (
                f"the demonstrator kept {current} in states like this one "
                f"({v}: {current} -> {target} held, p={p:.2f})"
            )
        else:
            done = {u: phi[model.nodes.index[(u, mp)]] for u, mp in context.items()}
            why = model.coupling.inconsistent(
                (v, current, target), context, done, model.config.progress_margin
            )
            why += self._too_fast((v, current, target))
            text = "; ".join(why) + f", never seen at {v}: {current} -> {target} (held, p={p:.2f})"
        self.notes.append(SequencerNote(t, "hold", v, text))

    def _too_fast(self, edge: tuple[str, str, str]) -> list[str]:
        """One reason per feature faster than ``edge``'s speed envelope allows, now."""
        limit = self.model.coupling.speed.get(edge)
        speed = self._speed.speed(self._since[edge[0]])
        if limit is None or speed is None:
            return []
        name = self.model.feature_name
        top = self._top[edge[0]]
        fast, for_pace = limit.too_fast(speed), limit.too_fast_for_pace(speed, top)
        why = []
        for i in np.flatnonzero(fast | for_pace).tolist():
            j = int(limit.features[i])
            if fast[i]:
                why.append(
                    f"{name(j)} moves at {speed[j]:.3g} ranges/s "
                    f"(demonstrated switches allow {limit.limit[i]:.3g})"
                )
            else:
                assert limit.share is not None  # for_pace is all false without it
                share = speed[j] / max(top[j], speed[j])
                why.append(
                    f"{name(j)} moves at {share:.0%} of its top speed under {edge[1]} "
                    f"(demonstrated switches allow {limit.share[i]:.0%})"
                )
        return why

    def _note_joint(
        self,
        t: float,
        v: str,
        current: str,
        target: str,
        p: float,
        waits: list[tuple[str, str, str]],
    ) -> None:
        """Note a switch that waits for the switches it was always demonstrated together with."""
        others = "; ".join(f"{u}: {a} -> {b}" for u, a, b in waits)
        text = (
            f"waits for {others} (always demonstrated together with {v}: {current} -> "
            f"{target}; held, p={p:.2f})"
        )
        self.notes.append(SequencerNote(t, "hold", v, text))

    def _new_watch(self, v: str, t: float) -> ActivationWatch:
        """A watch of ``v``'s active MP, active from ``t`` [s] (:meth:`explain`)."""
        c = self.model.config
        current = self.active[v]
        names = self.model.nodes.successors[(v, current)].names
        return ActivationWatch(v, current, names, t, c.threshold, c.patience, c.min_improvement)

    def _observe_entry(self, v: str, m: float, phi: list[float] | np.ndarray) -> None:
        """Give ``v``'s rule the ``p`` of its new node's successors measured at ``m`` [s].

        The measurement on which the node became active is the first of its history, so the
        rule can fire ``patience`` after it, whatever the control rate.
        """
        nodes = self.model.nodes
        current = self.active[v]
        names, columns = nodes.successors[(v, current)]
        if columns:
            exit_p = float(phi[nodes.index[(v, current)]])
            scale = self.model.branches.entry_scale
            self._rules[v].observe(
                m,
                [
                    transition_p(exit_p, float(phi[i]), scale.get((v, current, s), 1.0))
                    for s, i in zip(names, columns, strict=True)
                ],
            )

    def _switch(
        self,
        t: float,
        m: float,
        v: str,
        target: str,
        p: float,
        state: np.ndarray,
        phi: list[float],
        kind: SwitchKind,
    ) -> None:
        """Switch ``v`` to ``target`` at time ``t`` [s] with probability ``p``, and record it.

        ``m`` is the measurement time of the features ``state`` it was decided on; their φ
        (``phi``) gives the new node's successors' first ``p``.
        """
        self.events.append(TransitionEvent(t, v, self.active[v], target, p, state.copy(), kind))
        self.active[v] = target
        self._watch[v].append(self._new_watch(v, t))
        self._armed.pop(v, None)
        self._holding[v] = None
        self._reanchor(v, m, phi)
        self._plan = None
