"""One episode of a fitted :class:`~cpmp.sequencer.ConcurrentSequencer`: the state machine of
the transition rule.

:class:`SequencerEpisode` holds one episode's state (active MPs, events, notes, the switching
rules' histories, the stall detector) and applies the transition rule to the φ it is handed:
the start rule at :meth:`~SequencerEpisode.start`, the transitions, holds and recoveries at
every :meth:`~SequencerEpisode.advance`. :class:`~cpmp.sequencer.ConcurrentSequencer` drives
one, :class:`~cpmp.sequencer.batch.BatchedSequencer` many (:mod:`cpmp.sequencer.batch`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from cpmp.errors import ConfigError, DataError, NotFittedError
from cpmp.graph import SequenceGraph
from cpmp.predictors import START_PREFIX
from cpmp.records import SequencerNote, TickInfo, TransitionEvent
from cpmp.sequencer.fit_data import start_keys
from cpmp.sequencer.inputs import checked_time
from cpmp.sequencer.switching import StallDetector, make_rule, recovery_choice

if TYPE_CHECKING:
    from cpmp.sequencer.sequencer import ConcurrentSequencer

PlanRow = tuple[str, str, list[str], list[int], int, list[int], list[tuple[int, int, float]]]
"""One variable's row of :meth:`SequencerEpisode._transition_plan`."""


@dataclass(frozen=True)
class NodeIndex:
    """Where each node's φ sits in the predictor's output, and the successor tables the
    transition rule reads every tick; built once per sequencer (:meth:`build`).

    Attributes:
        keys: (variable, MP) of every graph node, in the order of the φ columns.
        index: (variable, MP) -> its φ column.
        start_index: (variable, MP) -> the column whose ``1 - φ`` is the MP's entry
            probability at the start (its start head, or its node's column without heads).
        successors: (variable, MP) -> (successor MPs, their φ columns).
    """

    keys: list[tuple[str, str]]
    index: dict[tuple[str, str], int]
    start_index: dict[tuple[str, str], int]
    successors: dict[tuple[str, str], tuple[list[str], list[int]]]

    @classmethod
    def build(
        cls, graphs: Mapping[str, SequenceGraph], predictor_keys: Sequence[tuple[str, str]]
    ) -> NodeIndex:
        """The index of ``graphs``' nodes in a predictor with heads ``predictor_keys``: the
        graph nodes in order, then optionally one start head per initial node.

        Raises:
            ConfigError: the predictor's heads are not the graphs' nodes.
        """
        keys = [(v, mp) for v in sorted(graphs) for mp in graphs[v].ordered_nodes()]
        extra = list(predictor_keys[len(keys) :])
        if list(predictor_keys[: len(keys)]) != keys or extra not in ([], start_keys(graphs)):
            raise ConfigError("the predictor's nodes do not match the sequence graphs' nodes")
        index = {key: i for i, key in enumerate(keys)}
        start_index = {
            (v, mp[len(START_PREFIX) :]): len(keys) + i for i, (v, mp) in enumerate(extra)
        } or index
        successors = {
            (v, mp): (
                graphs[v].successors(mp),
                [index[(v, s)] for s in graphs[v].successors(mp)],
            )
            for v, mp in keys
        }
        return cls(keys, index, start_index, successors)

    def phi_dict(self, phi: np.ndarray | list[float]) -> dict[str, dict[str, float]]:
        """Per-node φ ``(K,)`` (start heads after them ignored) as variable -> MP -> φ."""
        out: dict[str, dict[str, float]] = {v: {} for v, _ in self.keys}
        values = phi.tolist() if isinstance(phi, np.ndarray) else phi
        for (v, mp), value in zip(self.keys, values[: len(self.keys)], strict=True):
            out[v][mp] = value
        return out


class SequencerEpisode:
    """The state of one episode of a :class:`~cpmp.sequencer.ConcurrentSequencer`: the active
    MPs, the events, the notes, the switching rules' histories and the stall detector.

    :class:`~cpmp.sequencer.ConcurrentSequencer` drives one,
    :class:`~cpmp.sequencer.batch.BatchedSequencer` many; both evaluate the predictor themselves and
    hand each episode its φ, so one episode decides the same way in either.
    """

    def __init__(self, seq: ConcurrentSequencer) -> None:
        self.seq = seq
        self.active: dict[str, str] = {}
        """Variable -> active MP (empty before :meth:`start`)."""
        self.events: list[TransitionEvent] = []
        self.notes: list[SequencerNote] = []
        c = seq.config
        self._rules = {
            v: make_rule(c.switch_rule, c.threshold, c.patience, c.min_improvement)
            for v in seq.graphs
        }
        self._coupled = c.coupling == "context"
        self._stall = StallDetector(seq.feature_range, c.stall_time, c.rest_speed)
        self._holding: dict[str, str | None] = {}
        self._last_t: float | None = None
        self._plan: tuple[dict[str, str], list[PlanRow]] | None = None
        self._tick: TickInfo | None = None
        self._pending: tuple | None = None

    @property
    def last_tick(self) -> TickInfo | None:
        """What the last tick computed (built on first access after the tick)."""
        if self._pending is not None:
            t, phi, rows, active, held = self._pending
            seq = self.seq
            probs: dict[str, dict[str, float]] = {v: {} for v in sorted(seq.graphs)}
            for v, _, names, p, _ in rows:
                probs[v] = dict(zip(names, p, strict=True))
            self._tick = TickInfo(t, seq.nodes.phi_dict(phi), probs, active, held)
            self._pending = None
        return self._tick

    def start(self, t: float, x: np.ndarray, phi: np.ndarray) -> dict[str, str]:
        """Begin the episode at time ``t`` [s] with features ``x (d,)`` and every head's φ
        ``(H,)``; returns the initial MPs.
        """
        if not np.isfinite(phi).all():
            raise DataError(
                "the progress predictor gave a non-finite φ at reset; the model is broken "
                "(check its parameters) or the features are far outside the training data"
            )
        seq = self.seq
        self.active = self._initial_mps(phi)
        self.events = []
        self.notes = []
        for rule in self._rules.values():
            rule.reset()
        self._holding = {v: None for v in seq.graphs}
        self._stall.reset(t, np.asarray(x, dtype=np.float64).reshape(-1))
        self._last_t = t
        self._plan = None
        self._pending = None
        self._tick = TickInfo(
            t, seq.nodes.phi_dict(phi), {v: {} for v in seq.graphs}, dict(self.active)
        )
        return dict(self.active)

    def check_time(self, t: float) -> float:
        """``t`` [s] as a float; raises unless the episode was started and ``t`` is finite and
        does not go back in time.
        """
        if not self.active:
            raise NotFittedError("call reset(t, x) before step(t, x)")
        t = checked_time(t)
        if self._last_t is not None and t < self._last_t:
            raise DataError(f"time went backwards: step at t={t} after t={self._last_t}")
        return t

    def advance(
        self, t: float, state: np.ndarray, phi: list[float], finite: bool
    ) -> dict[str, str]:
        """One tick at time ``t`` [s]: features ``state (d,)``, the nodes' φ ``(K,)`` as a list
        and whether all of them are finite. Returns the active MPs after the tick.
        """
        seq = self.seq
        c = seq.config
        self._last_t = t
        if not finite:
            bad = [
                f"{v}/{mp}"
                for (v, mp), f in zip(seq.nodes.keys, phi, strict=True)
                if not math.isfinite(f)
            ]
            text = f"non-finite φ for {', '.join(bad[:5])}; every MP kept"
            if c.nonfinite == "raise":
                raise DataError(f"at t={t}: {text} (sequencer option nonfinite='raise')")
            if not self.notes or self.notes[-1].kind != "nonfinite":
                self.notes.append(SequencerNote(t, "nonfinite", "", text))
            self._tick = TickInfo(t, seq.nodes.phi_dict(phi), {}, dict(self.active))
            self._pending = None
            return dict(self.active)
        self._stall.observe(t, state)
        if self._plan is None:
            context = dict(self.active)
            self._plan = (context, self._transition_plan(context))
        context, plan = self._plan
        coupled = self._coupled
        held: dict[str, str] = {}
        rows = []
        fired = False
        for v, current, names, idx, exit_i, unseen, checks in plan:
            exit_p = phi[exit_i]
            p = [exit_p * (1.0 - phi[i]) for i in idx]
            bad = unseen
            if checks:
                bad = list(unseen)
                for successor, j, bound in checks:
                    if phi[j] < bound:
                        bad[successor] += 1
            rows.append((v, current, names, p, bad))
            gate = exit_p > c.min_exit
            allowed = [gate and b == 0 for b in bad] if coupled else [gate] * len(p)
            k = self._rules[v].update(t, p, allowed)
            if coupled and gate and not all(allowed):
                top = 0 if len(p) == 1 else max(range(len(p)), key=p.__getitem__)
                if p[top] > c.threshold and not allowed[top] and k != top:
                    held[v] = names[top]
                    if self._holding.get(v) != names[top]:
                        self._note_hold(t, v, current, names[top], p[top], context, phi)
            self._holding[v] = held.get(v)
            if k is not None:
                self._switch(t, v, names[k], p[k], state, "switch")
                fired = True
        if not fired and c.recovery and self._stall.stalled(t):
            candidates = [
                (v, current, s, q, b)
                for v, current, names, p, bad in rows
                for s, q, b in zip(names, p, bad, strict=True)
            ]
            choice = recovery_choice(candidates, c.recovery_threshold)
            if choice is not None:
                v, source, target, p_rec = choice
                self._switch(t, v, target, p_rec, state, "recovery")
                self.notes.append(
                    SequencerNote(
                        t,
                        "recovery",
                        v,
                        f"stall of {c.stall_time:g} s resolved: {v}: {source} -> {target} "
                        f"(p={p_rec:.2f})",
                    )
                )
        active = dict(self.active)
        self._pending = (t, phi, rows, active, held)
        return dict(active)

    def _initial_mps(self, phi: np.ndarray) -> dict[str, str]:
        """The start rule (see :meth:`~cpmp.sequencer.ConcurrentSequencer.reset`) on every
        head's φ ``(H,)``: variable -> MP.
        """
        seq = self.seq
        if seq.config.start_rule == "joint" and seq.initial_combinations:
            entry = np.clip(1.0 - phi, 1e-12, 1.0)
            scores = [
                sum(np.log(entry[seq.nodes.start_index[(v, mp)]]) for v, mp in combo.items())
                for combo in seq.initial_combinations
            ]
            return dict(seq.initial_combinations[int(np.argmax(scores))])
        active = {}
        for v in sorted(seq.graphs):
            initial = sorted(seq.graphs[v].initial_nodes)
            entry_v = [1.0 - phi[seq.nodes.start_index[(v, mp)]] for mp in initial]
            active[v] = initial[int(np.argmax(entry_v))]
        return active

    def _transition_plan(self, context: Mapping[str, str]) -> list[PlanRow]:
        """What every tick needs while the active MPs are ``context``: per variable with
        successors (sorted), ``(variable, current MP, successors, their φ columns, the current
        MP's φ column, unseen, checks)`` (:meth:`~cpmp.sequencer.switching.Coupling.gates`): per
        successor the number of other variables running an MP never seen at that switch, and
        ``(successor, φ column, bound)`` for every φ that adds one inconsistency while below
        its bound.
        """
        seq = self.seq
        margin = seq.config.progress_margin
        plan = []
        for v in sorted(seq.graphs):
            current = context[v]
            names, idx = seq.nodes.successors[(v, current)]
            if not names:
                continue
            unseen_counts, checks = [], []
            for k, s in enumerate(names):
                unseen, bounds = seq.coupling.gates((v, current, s), context, margin)
                unseen_counts.append(len(unseen))
                checks += [
                    (k, seq.nodes.index[(u, context[u])], bound)
                    for u, _, bound in bounds
                    if u in context
                ]
            plan.append(
                (v, current, names, idx, seq.nodes.index[(v, current)], unseen_counts, checks)
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
    ) -> None:
        """Note a transition the coupling holds back, with the reasons."""
        seq = self.seq
        done = {u: phi[seq.nodes.index[(u, mp)]] for u, mp in context.items()}
        why = seq.coupling.inconsistent(
            (v, current, target), context, done, seq.config.progress_margin
        )
        self.notes.append(
            SequencerNote(
                t,
                "hold",
                v,
                f"{v}: {current} -> {target} held (p={p:.2f}): "
                + "; ".join(why)
                + ", never seen at this switch",
            )
        )

    def _switch(
        self, t: float, v: str, target: str, p: float, state: np.ndarray, kind: str
    ) -> None:
        self.events.append(TransitionEvent(t, v, self.active[v], target, p, state.copy(), kind))
        self.active[v] = target
        self._rules[v].reset()
        self._holding[v] = None
        self._stall.switched(t)
        self._plan = None
