"""When a control variable switches: switching rules, coupling between graphs, stall recovery.

Pure Python on top of the per-tick transition probabilities; used by
:class:`cpmp.sequencer.ConcurrentSequencer`.

**Switching rules** decide, per variable, whether the best successor ``s`` of the current node
fires, given its transition probability ``p_s = φ_current(x) · (1 - φ_s(x))``:

* ``paper`` — the paper's sentence read literally: "above a certain threshold and has not
  improved over the last 50 ms": ``p(m) > threshold`` and ``p(m) <= p(m - patience) +
  min_improvement``, where ``m`` is the time the features were measured and ``p(m - patience)``
  the same successor's ``p`` interpolated linearly between the two measurements around
  ``m - patience``. A ``p`` that peaks above the threshold and then falls back fires; a ``p``
  still rising waits.
* ``peak`` (the default) — the ``paper`` rule, and also a ``p`` that has fallen back from a
  peak above the threshold within the last ``patience``: ``p(m) > threshold`` and ``p(m) <
  max p(m') - min_improvement`` over the measurements ``m - patience <= m' < m``, with that
  maximum above the threshold. An event (contact lost, a force read) makes ``p`` jump within
  one measurement, and the MPs still running then carry the state away from where the
  demonstrator switched: its ``p`` peaks for less than ``patience``, and the ``paper`` rule,
  which compares with ``p(m - patience)`` from before the jump, sees it still improving until
  it has fallen below the threshold. A ``p`` that rises and settles fires as with ``paper``.
**Time and fresh input (the rules' contract).** Both rules compare ``p`` at *measurement
times* (:class:`cpmp.sequencer.timing.MeasurementClock`), not at ticks, so they decide the same
at any control rate: tested at 30 Hz to 1 kHz, with ±30 % jitter of the period and dropped
ticks (a switch comes within one tick of the time an ideal loop would switch). A
tick whose features are not a new measurement (the stamp passed to ``step`` has not advanced;
without a stamp, the same feature vector as before) adds no evidence: ``p`` must fail to improve
over at least ``patience`` of measurement time, spanned by at least two distinct measurements
(the first one the measurement at which the node became active). A sensor slower than the loop
is therefore supported at any rate with stamps, and without them up to ``stale_time`` between
refreshes (default 0.25 s: 4 Hz); a switch then waits for the next refresh (up to one sensor
period late), and with a sensor period longer than ``patience`` the improvement over
``patience`` is read off the line between the last two measurements. A new measurement
two :data:`~cpmp.sequencer.timing.MEASUREMENT_STEP` (10 ms) or more after the last one (a
slow loop, dropped ticks, a stamped slow sensor) is decided on along the line from the last
one, states ``MEASUREMENT_STEP`` apart first, so a ``p`` that peaks between two samples is not
skipped (:meth:`cpmp.sequencer.episode.SequencerEpisode.advance`). A step of the caller's
clock (a tick interval of more than 5 median intervals) is not time that passed. Features
older than the last measurement (a stamp that goes back) are ignored.

**Coupling** (the paper's discussion asks for more than the shared features): for every
demonstrated switch ``source -> target`` of a variable, the MPs every *other* variable was
running when it happened (the labels one sample before and at the switch, so that switches made
in the same tick in either order are both allowed), and how far each of those MPs had
progressed (the least expected progress, eq. 1, over the demonstrations, on the sample before
the switch: the state the demonstrator decided on). A transition whose
context — the other variables' current MPs — contains an MP never seen for that switch, or an
MP whose predicted progress φ is more than a margin below the least demonstrated one, is held
back. It is learned from the labels alone (nothing task-specific), per other variable (a
product of marginal sets, more lenient than requiring a demonstrated joint context). A switch
that every demonstration made in the same sample as another variable's switch (a bowl served as
the last pour ends) is *joint* with it (``joint=true``): it waits until the other variable has
switched, or fires in the tick its rule decides to (a waiting switch stays armed while its ``p``
is above the threshold), and a recovery takes both. Where the other variable's ``p`` was below
this switch's at every demonstrated instance, and below the threshold at one, its progress does
not time the pair (the gripper's ``close -> open`` after a slip: its ``close`` ended early, and
the arm's ``lift -> lower`` is what the lost contact times): the switch takes it along
(:attr:`JointPartner.carried`, learned after the fit from the fitted φ at the demonstrated
instances).

**Recovery** resolves a stall: no transition of any variable for ``stall_time`` seconds of
measurement time while the features are at rest (every feature moves slower than
``rest_speed`` times its training range per second). Only a switch the demonstrator made here
may resolve it: every other variable runs an MP seen at that switch, and of the demonstrated
switches out of the same MP in this context, the one in the state nearest the current one
(:meth:`Coupling.nearest_target`) goes there. Among those (whose ``p`` reaches
``recovery_threshold``, 0 by default: a stall is a state nothing will change, so a low ``p``
will not rise — a re-align that starts where an align ends reads "done"), the one with the
fewest other variables less far than at any demonstrated switch (a stall is often an MP that
cannot go further: fingers closed on an object), then the most probable, fires. A joint switch
takes its partners along, so it may resolve a stall only if each partner's own switch is the
demonstrator's here too (a holder's ``hold -> retreat``, always made as the other arm's try
succeeded, does not carry a jammed try into ``next``: that try's nearest demonstrated state went
to ``undo``). When none may, the
sequencer gives up (a ``give_up`` note; it switches no more) — unless every variable's node is
*final* in the current context (no successor demonstrated with the other variables' current
MPs): that is the task's demonstrated end, and nothing happens.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import NamedTuple, Protocol

import numpy as np

from cpmp.config import COUPLINGS, SWITCH_RULES
from cpmp.data import Demonstration
from cpmp.progress import LabelKind, demo_labels
from cpmp.records import JsonValue
from cpmp.sequencer.motion import (
    SPEED_FACTOR,
    MotionData,
    SpeedLimit,
    ambient_features,
    learn_speed_limits,
    motion_data,
)
from cpmp.sequencer.timing import EPS_T


class SwitchRule(Protocol):
    """Per-variable switching state, fed with the successors' ``p`` at measurement times."""

    def reset(self) -> None:
        """Forget the history (called when the variable's node changes)."""

    def observe(self, t: float, p: Sequence[float]) -> None:
        """Record the successors' ``p`` measured at ``t`` [s] without deciding.

        Called with the measurement at which the node became active.
        """

    def update(self, t: float, p: Sequence[float], allowed: Sequence[bool]) -> int | None:
        """Record the successors' ``p`` measured at ``t`` [s] and decide.

        Args:
            t: when the features were measured [s] (:class:`~cpmp.sequencer.timing.Reading`);
                a ``t`` not later than the last one's is a repeat and adds no evidence.
            p: each successor's transition probability.
            allowed: per successor, whether it may fire (the coupling's and the exit gate).

        Returns:
            The index of the successor to switch to now (one with ``allowed[i]``), or ``None``.
        """


def _best(p: Sequence[float], allowed: Sequence[bool]) -> int | None:
    """Index of the highest allowed ``p`` (the first of equals), ``None`` if none is allowed."""
    if len(p) == 1:
        return 0 if allowed[0] else None
    best = None
    for i, (value, ok) in enumerate(zip(p, allowed, strict=True)):
        if ok and (best is None or value > p[best]):
            best = i
    return best


class PaperRule:
    """``p(m) > threshold`` and ``p(m) <= p(m - patience) + min_improvement`` (see module doc).

    ``p(m - patience)`` is interpolated linearly between the two measurements around it; the
    rule waits until the measurements span ``patience``.
    """

    def __init__(self, threshold: float, patience: float, min_improvement: float) -> None:
        self.threshold = threshold
        self.patience = patience
        self.min_improvement = min_improvement
        self._history: deque[tuple[float, list[float]]] = deque()

    def reset(self) -> None:
        """Forget the history (called when the variable's node changes)."""
        self._history.clear()

    def observe(self, t: float, p: Sequence[float]) -> None:
        """Record ``p`` measured at ``t`` [s] (a repeat of the last time is not recorded)."""
        history = self._history
        if not history or t > history[-1][0] + EPS_T:
            history.append((t, list(p)))
        # Keep exactly one entry at or before t - patience: the reference's left neighbour.
        reference = t - self.patience + EPS_T
        while len(history) >= 2 and history[1][0] <= reference:
            history.popleft()

    def update(self, t: float, p: Sequence[float], allowed: Sequence[bool]) -> int | None:
        """Record ``p`` measured at ``t`` [s]; the one to fire (see :class:`SwitchRule`)."""
        self.observe(t, p)
        best = _best(p, allowed)
        if best is None or p[best] <= self.threshold:
            return None
        return best if self._stopped(t, p[best], best) else None

    def _stopped(self, t: float, q: float, k: int) -> bool:
        """Whether successor ``k``'s ``p`` (``q`` at ``t`` [s], recorded) has not improved."""
        history = self._history
        reference = t - self.patience
        t0, p0 = history[0]
        if t0 > reference + EPS_T:
            return False  # the measurements do not span `patience` yet
        p_ref = p0[k]
        if len(history) >= 2 and reference - t0 > EPS_T:
            t1, p1 = history[1]
            p_ref += (reference - t0) / (t1 - t0) * (p1[k] - p_ref)
        return q <= p_ref + self.min_improvement


class PeakRule(PaperRule):
    """:class:`PaperRule`, or ``p`` fallen back from a peak above ``threshold`` (see module doc).

    The peak is the highest ``p`` of the same successor over the earlier measurements of the
    last ``patience`` (the history :class:`PaperRule` keeps, from the node's first
    measurement on).
    """

    def _stopped(self, t: float, q: float, k: int) -> bool:
        """Not improved (:class:`PaperRule`), or fallen back from a peak above the threshold."""
        if super()._stopped(t, q, k):
            return True
        window = t - self.patience - EPS_T
        peak = max((h[k] for th, h in self._history if window <= th < t - EPS_T), default=-1.0)
        return peak > self.threshold and q < peak - self.min_improvement


def transition_p(exit_phi: float, target_phi: float, entry_scale: float = 1.0) -> float:
    """A switch's transition probability ``p = φ_current · min(1, (1 - φ_target) · scale)``.

    The one formula every part of the sequencer reads ``p`` by: the tick's rule, the first
    measurement of a new node, the joint partners' test at fit time.

    Args:
        exit_phi: φ of the current node (its exit probability) in [0, 1].
        target_phi: φ of the successor; ``1 - target_phi`` is its entry probability.
        entry_scale: the factor on the entry probability of a switch whose demonstrated
            entries the progress predictor reads as "done" (a node re-entered in a loop;
            :func:`cpmp.sequencer.branches.entry_scales`); 1 for every other switch. The
            scaled entry is capped at 1.

    Returns:
        ``p`` in [0, 1].
    """
    return exit_phi * min(1.0, (1.0 - target_phi) * entry_scale)


def make_rule(name: str, threshold: float, patience: float, min_improvement: float) -> SwitchRule:
    """A fresh switching rule ``name`` (one of :data:`SWITCH_RULES`)."""
    cls = {"paper": PaperRule, "peak": PeakRule}[name]
    return cls(threshold, patience, min_improvement)


Edge = tuple[str, str, str]
"""(variable, source MP, target MP)."""


class ProgressBound(NamedTuple):
    """How far another variable's MP must have progressed for a switch to be consistent.

    Attributes:
        variable: the other variable.
        least: the least progress (eq. 1) its MP had at a demonstrated switch.
        bound: ``least - margin``: a φ below it is inconsistent.
    """

    variable: str
    least: float
    bound: float


class Gates(NamedTuple):
    """What holds back one switch in a given context (:meth:`Coupling.gates`).

    Attributes:
        unseen: the other variables that run an MP never seen at this switch.
        bounds: one :class:`ProgressBound` per other variable whose MP had a least
            demonstrated progress at this switch.
    """

    unseen: list[str]
    bounds: list[ProgressBound]


@dataclass(frozen=True, eq=False)
class SwitchInstance:
    """One demonstrated switch of a variable out of an MP (:attr:`Coupling.instances`).

    Attributes:
        target: the MP it switched to.
        state: the features ``(d,)`` at the switch (the first sample under ``target``).
        context: each other variable's MPs just before and at the switch.
    """

    target: str
    state: np.ndarray
    context: dict[str, frozenset[str]]

    def __eq__(self, other: object) -> bool:
        return (
            isinstance(other, SwitchInstance)
            and (self.target, self.context) == (other.target, other.context)
            and np.array_equal(self.state, other.state)
        )


class JointPartner(NamedTuple):
    """Another variable's switch that a switch was always demonstrated together with.

    Attributes:
        sources: the MPs it switched out of (sorted; several when it came from different ones).
        target: the MP it always switched into.
        carried: the switch takes it along instead of waiting for it: at every demonstrated
            instance the partner's own ``p`` was below the switch's, and at one below the
            threshold (:meth:`Coupling.with_carried`). Its progress does not time the pair:
            the gripper's ``close -> open`` after a slip, whose ``close`` ended early, comes
            with the arm's ``lift -> lower``, which the lost contact times.
    """

    sources: tuple[str, ...]
    target: str
    carried: bool = False

    @property
    def source_text(self) -> str:
        """The sources as text (``a or b``)."""
        return " or ".join(self.sources)


@dataclass(eq=False)
class Coupling:
    """Contexts of the demonstrated switches (see module doc).

    Attributes:
        contexts: ``(variable, source, target)`` -> other variable -> MPs it ran at that switch.
        progress: ``(variable, source, target)`` -> other variable -> MP -> the lowest expected
            progress (eq. 1) that MP had reached at a demonstrated switch, for other variables
            that kept running the same MP through the switch. It is read on the state the
            demonstrator decided on: the last sample under ``source``, not the first under
            ``target``, which already holds one step of ``target`` (a gripper's first opening
            step drops the object, and the arm's progress jumps with the contact and the
            load).
        instances: ``(variable, source)`` -> every demonstrated switch of ``variable`` out of
            ``source``: its target, the features at it and the other variables' MPs around
            it (what a recovery reads: :meth:`nearest_target`).
        joint: ``(variable, source, target)`` -> other variable -> :class:`JointPartner` when
            every demonstration of that switch came in the same sample as a switch of the
            other variable into the same MP ``to`` (from whichever MP): the switch is made
            together with it (a bowl is served as the last pour ends), so it may fire only once
            the other variable is in ``to`` or ready to switch there (its ``p`` above the
            threshold and its branch choice there).
        speed: ``(variable, source, target)`` -> the switch's speed envelope
            (:mod:`cpmp.sequencer.motion`): a transition is inconsistent while a feature its
            source moves is faster than demonstrated at the switch.
        ambient: ``(d,)`` the features that move at a similar rate under every MP (the stall
            detector ignores them); ``None``: none known.
    """

    contexts: dict[Edge, dict[str, frozenset[str]]] = field(default_factory=dict)
    progress: dict[Edge, dict[str, dict[str, float]]] = field(default_factory=dict)
    instances: dict[tuple[str, str], list[SwitchInstance]] = field(default_factory=dict)
    joint: dict[Edge, dict[str, JointPartner]] = field(default_factory=dict)
    speed: dict[Edge, SpeedLimit] = field(default_factory=dict)
    ambient: np.ndarray | None = None

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Coupling):
            return NotImplemented
        same = (self.contexts, self.progress, self.instances, self.joint) == (
            other.contexts,
            other.progress,
            other.instances,
            other.joint,
        )
        speeds = self.speed.keys() == other.speed.keys() and all(
            np.array_equal(a, b)
            for edge, limit in self.speed.items()
            for a, b in zip(limit, other.speed[edge], strict=True)
        )
        mine, theirs = self.ambient, other.ambient
        ambient = (mine is None) == (theirs is None) and (
            mine is None or np.array_equal(mine, theirs)
        )
        return same and speeds and ambient

    @classmethod
    def learn(
        cls,
        demos: Sequence[Demonstration],
        variables: Sequence[str],
        transform: Callable[[np.ndarray], np.ndarray] | None = None,
        labels: LabelKind = "path",
        progress: Sequence[Mapping[str, np.ndarray]] | None = None,
        feature_range: np.ndarray | None = None,
        motion: Sequence[MotionData] | None = None,
        ambient: np.ndarray | None = None,
    ) -> Coupling:
        """Collect the contexts of every switch of ``variables`` in ``demos``.

        The learned progress thresholds are in the units of the φ they are compared with (e.g.
        eq. 1 on the denoised trajectory of noisy demonstrations).

        Args:
            demos: labelled demonstrations.
            variables: the control variables.
            transform: maps features ``(n, d)`` to the space progress is measured in (the
                predictor's scaling); ``None``: the features as they are.
            labels: the predictor's kind of progress label
                (:func:`cpmp.progress.progress_labels`).
            progress: each demonstration's labels per variable ``(n,)`` when the caller has
                them already (a fit: :func:`cpmp.sequencer.fit_data.demo_progress`);
                ``transform`` and ``labels`` are then not used.
            feature_range: ``(d,)`` each feature's training range (0: never moves); with it
                the speed envelopes and the ambient features are learned too
                (:mod:`cpmp.sequencer.motion`), without it neither.
            motion: ``demos`` as :func:`~cpmp.sequencer.motion.motion_data` gives them, when
                the caller has them already (a fit); ``None``: made here.
            ambient: ``(d,)`` bool, the ambient features
                (:func:`~cpmp.sequencer.motion.ambient_features` of ``motion``), when the
                caller has them already (a fit: its eq. 1 left them out); ``None``: found
                here. Only with ``feature_range``.

        Returns:
            The coupling.
        """
        contexts: dict[Edge, dict[str, set[str]]] = {}
        progress_seen: dict[Edge, dict[str, dict[str, float]]] = {}
        instances: dict[tuple[str, str], list[SwitchInstance]] = {}
        together: dict[Edge, list[dict[str, tuple[str, str]]]] = {}
        variables = list(variables)
        if progress is None:
            progress = [demo_labels(demo, variables, transform, labels) for demo in demos]
        for demo, done in zip(demos, progress, strict=True):
            mps = {v: np.asarray(demo.labels[v]) for v in variables}
            for v in variables:
                lab = mps[v]
                for i in np.flatnonzero(lab[1:] != lab[:-1]) + 1:
                    edge = (v, str(lab[i - 1]), str(lab[i]))
                    ctx = contexts.setdefault(edge, {})
                    prog = progress_seen.setdefault(edge, {})
                    around = {}
                    switched = {}
                    for u in variables:
                        if u == v:
                            continue
                        before, after = str(mps[u][i - 1]), str(mps[u][i])
                        ctx.setdefault(u, set()).update((before, after))
                        around[u] = frozenset((before, after))
                        if before != after:
                            switched[u] = (before, after)
                        else:
                            # the demonstrator decided on sample i - 1 (the last under the
                            # source); sample i already holds one step of the new MP, whose
                            # own effect (an object let go: contact, a load) moves u's progress
                            seen = prog.setdefault(u, {})
                            seen[after] = min(seen.get(after, 1.0), float(done[u][i - 1]))
                    together.setdefault(edge, []).append(switched)
                    instances.setdefault(edge[:2], []).append(
                        SwitchInstance(edge[2], demo.features[i].copy(), around)
                    )
        joint = {}
        for edge, seen in together.items():
            always = {
                u: JointPartner(tuple(sorted({s[u][0] for s in seen})), to)
                for u, (_, to) in seen[0].items()
                if all(u in s and s[u][1] == to for s in seen)
            }
            if always:
                joint[edge] = always
        speed: dict[Edge, SpeedLimit] = {}
        if feature_range is None:
            ambient = None
        else:
            data = motion_data(demos) if motion is None else motion
            speed = learn_speed_limits(data, variables, feature_range)
            if ambient is None:
                ambient = ambient_features(data, variables, len(feature_range))
        return cls(
            {e: {u: frozenset(s) for u, s in c.items()} for e, c in contexts.items()},
            {e: c for e, c in progress_seen.items() if c},
            instances,
            joint,
            speed,
            ambient,
        )

    def with_carried(
        self,
        progress: Callable[[np.ndarray], np.ndarray],
        index: Mapping[tuple[str, str], int],
        threshold: float,
        entry_scale: Mapping[Edge, float] | None = None,
    ) -> Coupling:
        """This coupling with the joint partners its switches take along marked ``carried``.

        For a joint switch ``v: s -> t`` and its partner ``u: a -> b``, the transition
        probabilities at every demonstrated instance (the state at the switch, from
        :attr:`instances`): the switch's own ``φ_s · (1 - φ_t)`` and the partner's
        ``φ_a · (1 - φ_b)``, each entry scaled as an episode scales it. The partner is carried
        when its ``p`` was below the switch's at every instance and below ``threshold`` at one
        or more: then the switch's ``p``, not the partner's, times the pair. Where the
        partners' ``p`` are alike (a bowl served as the last pour ends), the switch waits.

        Args:
            progress: φ of every node for states ``(N, d)``: ``(N, K)``.
            index: (variable, MP) -> its column of φ.
            threshold: the switching threshold.
            entry_scale: (variable, source, target) -> the factor on the entry probability
                (:attr:`~cpmp.sequencer.branches.BranchChoices.entry_scale`; 1 if absent).

        Returns:
            A new coupling; the same but for ``carried``.
        """
        scale = entry_scale or {}

        def p(phi: np.ndarray, v: str, source: str, target: str) -> np.ndarray:
            g = scale.get((v, source, target), 1.0)
            s_, t_ = index[(v, source)], index[(v, target)]
            return np.array([transition_p(float(r[s_]), float(r[t_]), g) for r in phi])

        joint: dict[Edge, dict[str, JointPartner]] = {}
        for (v, s, t), partners in sorted(self.joint.items()):
            seen = [inst for inst in self.instances.get((v, s), []) if inst.target == t]
            phi = progress(np.stack([inst.state for inst in seen])) if seen else None
            out = {}
            for u, partner in sorted(partners.items()):
                b = partner.target
                sources = [next(iter(inst.context.get(u, {b}) - {b}), None) for inst in seen]
                keys = [(v, s), (v, t), (u, b), *((u, a) for a in sources)]
                carried = False
                if phi is not None and all(k in index for k in keys):  # (u, None) is not a key
                    own = p(phi, v, s, t)
                    theirs = np.array([p(phi[[i]], u, a, b)[0] for i, a in enumerate(sources)])
                    carried = bool(theirs.max() < own.min() and theirs.min() < threshold)
                out[u] = partner._replace(carried=carried)
            joint[(v, s, t)] = out
        return replace(self, joint=joint)

    def inconsistent(
        self,
        edge: Edge,
        active: Mapping[str, str],
        phi: Mapping[str, float] | None = None,
        margin: float | None = None,
    ) -> list[str]:
        """Why a transition along ``edge`` is inconsistent with every demonstrated context.

        Args:
            edge: the switch.
            active: variable -> active MP.
            phi: each variable's predicted progress of its active MP (``None``: compare MPs
                only).
            margin: how much less advanced than at any demonstrated switch an MP may be.

        Returns:
            One entry per other variable that runs an MP never seen at this switch, or (with
            ``phi`` and ``margin``) whose MP is more than ``margin`` less advanced than at any
            demonstrated switch. Empty: consistent (also for an edge never demonstrated).
        """
        unseen, bounds = self.gates(edge, active, None if phi is None else margin)
        out = [f"{u} runs {active[u]}" for u in unseen]
        for u, least, bound in bounds:
            if u in phi and phi[u] < bound:
                out.append(
                    f"{u} has {active[u]} at progress {phi[u]:.2f} (demonstrated >= {least:.2f})"
                )
        return out

    def gates(self, edge: Edge, active: Mapping[str, str], margin: float | None = None) -> Gates:
        """The part of :meth:`inconsistent` that depends on the other variables' MPs only.

        It is fixed between switches, so a sequencer computes it once per context. The
        transition is inconsistent once per ``unseen`` variable and once per bound whose
        variable's φ is below its ``bound``.

        Args:
            edge: the switch.
            active: variable -> active MP.
            margin: subtracted from the least demonstrated progress; ``None``: no bounds.

        Returns:
            The other variables that run an MP never seen at this switch, and one
            :class:`ProgressBound` per other variable whose MP had a least demonstrated
            progress at this switch (none when ``margin`` is ``None``).
        """
        unseen = [
            u
            for u, mps in (self.contexts.get(edge) or {}).items()
            if u in active and active[u] not in mps
        ]
        bounds = []
        if margin is not None:
            for u, seen in (self.progress.get(edge) or {}).items():
                mp = active.get(u)
                if mp in seen:
                    bounds.append(ProgressBound(u, seen[mp], seen[mp] - margin))
        return Gates(unseen, bounds)

    def nearest_target(
        self, variable: str, source: str, x: np.ndarray, active: Mapping[str, str]
    ) -> str | None:
        """What the demonstrator did leaving ``source`` in the demonstrated state nearest ``x``.

        Among the demonstrated switches of ``variable`` out of ``source`` made while every
        other variable ran its MP in ``active`` (just before or at the switch), the one whose
        features are nearest ``x`` (Euclidean: the geometry of cpmp's global feature
        scaling).

        Args:
            variable: the control variable.
            source: its active MP.
            x: the features now ``(d,)``.
            active: variable -> active MP.

        Returns:
            That switch's target; ``None`` if no switch out of ``source`` was demonstrated in
            this context (or the coupling keeps no switch states: a checkpoint of version 2).
        """
        best, target = np.inf, None
        for inst in self.instances.get((variable, source), []):
            if any(u in active and active[u] not in mps for u, mps in inst.context.items()):
                continue
            distance = float(np.sum((inst.state - x) ** 2))
            if distance < best:
                best, target = distance, inst.target
        return target

    def describe(self, variable: str, feature_names: Sequence[str] | None = None) -> list[str]:
        """One line per switch of ``variable``: the other variables' demonstrated MPs.

        Each MP is followed by the least progress at which it was seen, where known; then the
        switches it is made together with and the features its speed envelope watches (by
        name, from ``feature_names``, else by index).
        """
        lines = []
        for (v, source, target), ctx in sorted(self.contexts.items()):
            if v != variable:
                continue
            prog = self.progress.get((v, source, target), {})
            parts = []
            for u, mps in sorted(ctx.items()):
                part = f"{u} in {{{', '.join(sorted(mps))}}}"
                if u in prog:
                    part += (
                        " ("
                        + ", ".join(f"{mp} >= {q:.2f}" for mp, q in sorted(prog[u].items()))
                        + ")"
                    )
                parts.append(part)
            for u, partner in sorted(self.joint.get((v, source, target), {}).items()):
                carried = " (taken along)" if partner.carried else ""
                parts.append(
                    f"together with {u}: {partner.source_text} -> {partner.target}{carried}"
                )
            limit = self.speed.get((v, source, target))
            if limit is not None and limit.features.size:
                names = [
                    feature_names[j] if feature_names is not None else f"feature {j}"
                    for j in limit.features.tolist()
                ]
                shown = ", ".join(names[:4]) + (
                    f" and {len(names) - 4} more" if len(names) > 4 else ""
                )
                pace = ""
                if limit.share is not None:
                    pace = f", in ranges/s and as a share of their top speed under {source}"
                parts.append(f"{shown} at most {SPEED_FACTOR:g}x as fast as demonstrated{pace}")
            lines.append(f"  {source} -> {target} when " + ("; ".join(parts) or "always"))
        return lines

    def to_dict(self) -> dict[str, JsonValue]:
        """JSON/checkpoint-friendly form."""
        return {
            "switches": [
                {
                    "variable": v,
                    "source": s,
                    "target": t,
                    "context": {u: sorted(m) for u, m in sorted(c.items())},
                    "progress": {
                        u: dict(sorted(q.items()))
                        for u, q in sorted(self.progress.get((v, s, t), {}).items())
                    },
                    "joint": {
                        u: {"from": list(p.sources), "to": p.target}
                        | ({"carried": True} if p.carried else {})
                        for u, p in sorted(self.joint.get((v, s, t), {}).items())
                    },
                    **(
                        {"speed": self.speed[(v, s, t)].to_dict()}
                        if (v, s, t) in self.speed
                        else {}
                    ),
                }
                for (v, s, t), c in sorted(self.contexts.items())
            ],
            "ambient": None if self.ambient is None else self.ambient.tolist(),
            "instances": [
                {
                    "variable": v,
                    "source": s,
                    "target": inst.target,
                    "state": inst.state.tolist(),
                    "context": {u: sorted(m) for u, m in sorted(inst.context.items())},
                }
                for (v, s), insts in sorted(self.instances.items())
                for inst in insts
            ],
        }

    @classmethod
    def from_dict(
        cls, data: Mapping[str, JsonValue] | Sequence[Mapping[str, JsonValue]]
    ) -> Coupling:
        """Inverse of :meth:`to_dict` (also reads the list form of checkpoint version 2)."""
        rows = data.get("switches", []) if isinstance(data, Mapping) else data
        contexts, progress, joint, speed = {}, {}, {}, {}
        for r in rows:
            edge = (str(r["variable"]), str(r["source"]), str(r["target"]))
            contexts[edge] = {str(u): frozenset(map(str, m)) for u, m in r["context"].items()}
            prog = {
                str(u): {str(mp): float(q) for mp, q in seen.items()}
                for u, seen in (r.get("progress") or {}).items()
            }
            if prog:
                progress[edge] = prog
            pairs = {str(u): _partner(p) for u, p in (r.get("joint") or {}).items()}
            if pairs:
                joint[edge] = pairs
            if r.get("speed") is not None:
                speed[edge] = SpeedLimit.from_dict(r["speed"])
        instances: dict[tuple[str, str], list[SwitchInstance]] = {}
        for r in data.get("instances", []) if isinstance(data, Mapping) else []:
            instances.setdefault((str(r["variable"]), str(r["source"])), []).append(
                SwitchInstance(
                    str(r["target"]),
                    np.asarray(r["state"], dtype=np.float64),
                    {str(u): frozenset(map(str, m)) for u, m in r["context"].items()},
                )
            )
        ambient = data.get("ambient") if isinstance(data, Mapping) else None
        mask = None if ambient is None else np.asarray(ambient, dtype=bool).reshape(-1)
        return cls(contexts, progress, instances, joint, speed, mask)


def _partner(row: JsonValue) -> JointPartner:
    """A :class:`JointPartner` from its checkpoint form (or the ``[from, to]`` pair of before)."""
    if isinstance(row, Mapping):
        return JointPartner(
            tuple(str(a) for a in row["from"]), str(row["to"]), bool(row.get("carried", False))
        )
    a, b = row
    return JointPartner((str(a),), str(b))


def indicator_features(x: np.ndarray) -> np.ndarray:
    """``(d,)`` bool: the features of ``x (N, d)`` that take at most two distinct values.

    Binary signals such as touch; they flicker while a contact is made or broken.
    """
    x = np.asarray(x, dtype=np.float64)
    lo, hi = x.min(axis=0), x.max(axis=0)
    return np.all((x == lo) | (x == hi), axis=0)


class StallDetector:
    """Tracks when any variable last switched and when the features last moved.

    Times are measurement times (:mod:`cpmp.sequencer.timing`): feed it new measurements only,
    so that time without them (a clock step, a sensor that stopped) is never a stall.
    ``feature_range (d,)``: each feature's range in the training data; motion is measured
    relative to it, so the detector does not depend on the features' units. Features with a
    range of 0 are ignored (:meth:`ConcurrentSequencer.fit` gives indicator features range 0:
    a touch signal that flickers is not motion; an episode gives the ambient features range 0
    too, :func:`~cpmp.sequencer.motion.without_ambient`: a distractor's wobble is not
    progress).
    """

    def __init__(self, feature_range: np.ndarray, stall_time: float, rest_speed: float) -> None:
        r = np.asarray(feature_range, dtype=np.float64)
        varies = r > 1e-12 * max(float(np.max(r, initial=0.0)), 1e-300)
        self.inv_range = np.divide(1.0, r, out=np.zeros_like(r), where=varies)
        self.stall_time = stall_time
        self.rest_speed = rest_speed
        self._x: np.ndarray | None = None
        self.last_switch = 0.0
        self.last_motion = 0.0

    def reset(self, t: float, x: np.ndarray) -> None:
        """Start an episode at ``t`` [s] with features ``x (d,)`` (counts as switch and motion)."""
        self._x = np.array(x, dtype=np.float64)
        self.last_switch = self.last_motion = t

    def observe(self, t: float, x: np.ndarray) -> None:
        """Feed the features ``x (d,)`` of the tick at ``t`` [s].

        Motion is a displacement of any feature by more than ``rest_speed * stall_time`` of
        its range from where the features were when motion was last seen (a dead band: contact
        jitter that goes back and forth never adds up to motion, a slow drift does).
        """
        if self._x is None:
            self._x = np.array(x, dtype=np.float64)
            return
        moved = float((np.abs(x - self._x) * self.inv_range).max(initial=0.0))
        if moved > self.rest_speed * self.stall_time:
            self.last_motion = t
            self._x = np.array(x, dtype=np.float64)

    def switched(self, t: float) -> None:
        """Note a switch at ``t`` [s]."""
        self.last_switch = t

    def stalled(self, t: float) -> bool:
        """No switch for ``stall_time`` and no motion for ``stall_time``."""
        since = t - self.stall_time + EPS_T
        return self.last_switch <= since and self.last_motion <= since


class Candidate(NamedTuple):
    """A transition that stall recovery may take.

    Attributes:
        variable: the control variable.
        source: its active MP.
        target: a successor of ``source``.
        p: the transition probability at this tick.
        n_inconsistent: the number of other variables inconsistent with the demonstrated
            contexts of this switch (an MP never seen there, or one less far than there).
        demonstrated: whether the demonstrator made this switch here: every other variable
            runs an MP seen at it, and of the demonstrated switches out of ``source`` in this
            context, the one in the state nearest the current one goes to ``target`` (a
            recovery also asks it of each joint partner the switch would take along).
    """

    variable: str
    source: str
    target: str
    p: float
    n_inconsistent: int
    demonstrated: bool = True


def _recovery_rank(c: Candidate) -> tuple[int, float, str, str]:
    """Sort key: fewest inconsistencies, then highest ``p``, then by variable and target."""
    return (c.n_inconsistent, -c.p, c.variable, c.target)


def recovery_choice(candidates: Sequence[Candidate], threshold: float) -> Candidate | None:
    """Pick the stall-recovery transition.

    Args:
        candidates: every successor of every variable's current node.
        threshold: the least ``p`` a recovery needs.

    Returns:
        Among the ``demonstrated`` candidates whose ``p`` reaches ``threshold``, the one with
        the fewest inconsistent other variables and, among those, the most probable (ties: by
        variable, then target); ``None`` if there is none: a switch the demonstrator did not
        make here is never a recovery.
    """
    ok = [c for c in candidates if c.demonstrated and c.p >= threshold]
    if not ok:
        return None
    return min(ok, key=_recovery_rank)


__all__ = [
    "COUPLINGS",
    "SWITCH_RULES",
    "Candidate",
    "Coupling",
    "Gates",
    "PaperRule",
    "PeakRule",
    "ProgressBound",
    "StallDetector",
    "SwitchInstance",
    "SwitchRule",
    "indicator_features",
    "make_rule",
    "recovery_choice",
    "transition_p",
]
