"""The records every layer shares: transitions, notes, ticks, replays and policy protocols.

A transition, a sequencer note, a start decision, a control tick, an open-loop replay, the
policy protocols a closed loop drives, an episode's recoveries judged against the demonstrator
(:func:`count_recoveries`) and the cause of an incomplete episode (:class:`PendingSwitch`,
:func:`pending_switch`, :func:`episode_cause`); the closed sets of transition, note and cause
kinds (:data:`SwitchKind`, :data:`NoteKind`, :data:`CauseReason`) are checked where a record is
made.

The sequencer (:mod:`cpmp.sequencer.sequencer`), the simulator runner (:mod:`cpmp.sim.runner`), the
recordings (:mod:`cpmp.recordings`) and the evaluation (:mod:`cpmp.evaluation.offline`) all
speak in these types. A producer fills the fields it knows; the others keep their documented
defaults. (A demonstration's activations, :class:`cpmp.data.Activation`, live beside the
demonstration record.)
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Literal, NamedTuple, Protocol, get_args

import numpy as np

from cpmp.errors import DataError

SwitchKind = Literal["switch", "recovery"]
"""Why a transition fired: ``switch`` (the switching rule) or ``recovery`` (a stall resolved)."""
SWITCH_KINDS: tuple[SwitchKind, ...] = get_args(SwitchKind)

NoteKind = Literal["hold", "recovery", "give_up", "nonfinite", "clock_step"]
"""What a :class:`SequencerNote` is about (see there)."""
NOTE_KINDS: tuple[NoteKind, ...] = get_args(NoteKind)

CauseReason = Literal[
    "below_threshold",
    "still_improving",
    "held",
    "given_up",
    "not_a_successor",
    "wrong_transition",
    "task_unfinished",
    "unknown",
]
"""Why the switch an incomplete episode waited for did not fire (:class:`PendingSwitch`)."""
CAUSE_REASONS: tuple[CauseReason, ...] = get_args(CauseReason)


@dataclass(frozen=True)
class TransitionEvent:
    """A switch of one control variable.

    Attributes:
        t: time [s] of the tick at which the switch fired (for a demonstration: the time of
            the first sample under the new MP).
        variable: control variable.
        source: MP active before.
        target: MP active after.
        probability: transition probability ``p`` at that tick; ``nan`` where the producer
            does not know it (the simulator runner, which sees only the active MPs; a
            demonstration's label switch).
        state: (d,) feature vector on which the switch was decided (for a demonstration: the
            first sample under the new MP); ``None`` where the producer does not keep it (a
            recording read back). Not compared by ``==``.
        kind: ``switch`` (the switching rule fired) or ``recovery`` (a stall was resolved);
            ``switch`` where the producer cannot tell.
    """

    t: float
    variable: str
    source: str
    target: str
    probability: float = math.nan
    state: np.ndarray | None = field(default=None, repr=False, compare=False)
    kind: SwitchKind = "switch"

    def __post_init__(self) -> None:
        if self.kind not in SWITCH_KINDS:
            raise DataError(
                f"a transition's kind is one of {', '.join(SWITCH_KINDS)}, got {self.kind!r}"
            )


@dataclass(frozen=True)
class SequencerNote:
    """Something the sequencer decided not to do, or did exceptionally, at time ``t`` [s].

    ``kind``: ``hold`` (a transition the rule would fire is held back by the coupling),
    ``recovery`` (a stall resolved), ``give_up`` (a stall no demonstrated transition resolves:
    the sequencer switches no more), ``nonfinite`` (the features or φ were NaN/inf; every MP
    kept; one note per run of such ticks) or ``clock_step`` (the caller's time jumped: not
    counted as time that passed); ``variable``: the control variable concerned (empty if
    none); ``text``: readable.
    """

    t: float
    kind: NoteKind
    variable: str
    text: str

    def __post_init__(self) -> None:
        if self.kind not in NOTE_KINDS:
            raise DataError(
                f"a sequencer note's kind is one of {', '.join(NOTE_KINDS)}, got {self.kind!r}"
            )


class StartOption(NamedTuple):
    """One start the start rule weighed.

    Attributes:
        combination: variable -> initial MP (every variable for the ``learned`` and ``joint``
            rules, one for ``independent``).
        score: ``learned``: the log-probability of this demonstrated start at the first
            state; otherwise ``Σ log(1 - φ)`` of its MPs' start heads: the log-likelihood that
            each MP is at its beginning (higher is more likely; 0 is certain).
    """

    combination: dict[str, str]
    score: float


@dataclass(frozen=True)
class StartDecision:
    """How a sequencer chose the initial MPs at ``t`` [s].

    Attributes:
        t: the time [s] of the reset.
        rule: ``learned`` (the demonstrated combination of initial MPs the learned start
            choice finds most probable), ``joint`` (the demonstrated combination of highest
            entry probability) or ``independent`` (each variable's best initial MP on its own).
        options: the starts weighed, in the order weighed (``joint``: each demonstrated
            combination (``learned``, ``joint``); ``independent``: each variable's initial MPs,
            one variable each).
        chosen: variable -> the initial MP taken.
    """

    t: float
    rule: str
    options: list[StartOption]
    chosen: dict[str, str]


@dataclass
class TickInfo:
    """One control tick.

    The sequencer fills what it computed (``last_tick``); the simulator runner passes what it
    observed to ``on_tick`` callbacks (before the tick's physics).

    Attributes:
        t: time [s].
        progress: variable -> MP -> φ (every node; sequencer, empty from the runner).
        transition_probs: variable -> successor -> ``p`` (successors of the active MP;
            sequencer, empty from the runner).
        active: variable -> active MP (sequencer: after the tick; runner: during it).
        held: variable -> successor held back by the coupling at this tick (sequencer).
        features: (d,) feature vector (runner; ``None`` from the sequencer).
        body_poses: body -> (position (3,) [m], quaternion (4,) wxyz) in the world frame
            (runner; empty from the sequencer).
    """

    t: float
    progress: dict[str, dict[str, float]] = field(default_factory=dict)
    transition_probs: dict[str, dict[str, float]] = field(default_factory=dict)
    active: dict[str, str] = field(default_factory=dict)
    held: dict[str, str] = field(default_factory=dict)
    features: np.ndarray | None = None
    body_poses: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)


class ReplayResult(NamedTuple):
    """A policy run open-loop over a recorded feature stream (``replay``).

    Attributes:
        sequences: variable -> the MPs it ran, in order.
        events: the transitions, in order.
    """

    sequences: dict[str, list[str]]
    events: list[TransitionEvent]


class RecoveryCounts(NamedTuple):
    """An episode's stall recoveries, judged against the demonstrator's run on its context.

    Attributes:
        right: recoveries to the MP the demonstrator ran next on that variable.
        wrong: the others.
    """

    right: int
    wrong: int


def count_recoveries(
    events: Sequence[TransitionEvent], expected: Mapping[str, Sequence[str]]
) -> RecoveryCounts:
    """Right and wrong recoveries among an episode's transitions.

    The ``k``-th transition of a variable is right when the demonstrator's run on the same
    context (``expected``: variable -> its MP sequence) made its ``k``-th switch to the same
    MP.

    Args:
        events: the episode's transitions, in order.
        expected: the demonstrator's MP sequence per variable.

    Returns:
        The counts of ``recovery`` transitions, right and wrong.
    """
    right = wrong = 0
    seen: dict[str, int] = {}
    for event in events:
        k = seen[event.variable] = seen.get(event.variable, 0) + 1
        if event.kind != "recovery":
            continue
        want = expected.get(event.variable, [])
        if k < len(want) and want[k] == event.target:
            right += 1
        else:
            wrong += 1
    return RecoveryCounts(right, wrong)


@dataclass(frozen=True)
class PendingSwitch:
    """The cause of an incomplete episode: the demonstrated switch that never came.

    ``expected`` is the demonstrator's next MP of ``variable`` after ``current`` on the same
    context (its switch number ``len(sequence)``); the ``p`` fields are of the edge
    ``current -> expected`` while ``current`` was active (``nan`` where the policy does not
    say, or the edge is not in the sequence graph).

    ``reason``:

    * ``below_threshold``: its ``p`` never exceeded ``threshold``;
    * ``still_improving``: it did, but when last above it was still rising by more than
      ``min_improvement`` per ``patience`` (the rule waits for a plateau); ``detail`` says
      when ``p`` had levelled off and only wobbled up again (the rule compares ``p`` with
      its value ``patience`` before);
    * ``held``: it was above the threshold but held back when last above (the coupling, a
      switch it waits for, a branch or stay choice, or a successor of higher ``p``;
      ``detail`` says which);
    * ``given_up``: it was above the threshold only after the sequencer gave up (a stall no
      demonstrated switch resolved; ``at``: when);
    * ``not_a_successor``: ``expected`` is not a successor of ``current`` in the graph;
    * ``wrong_transition``: another switch, ``current -> fired``, fired instead at ``at`` [s]
      (``expected`` empty: the demonstrator switched no more);
    * ``task_unfinished``: every variable ran the demonstrated MPs and the task still did not
      finish (no switch pending: ``variable``, ``current`` and ``expected`` empty);
    * ``unknown``: the policy does not explain its switches (scripted policies, baselines).

    Attributes:
        variable: the control variable expected to switch.
        current: its MP when it should have switched.
        expected: the demonstrator's next MP.
        reason: why it did not fire (above).
        best_p: the highest ``p`` of the edge since ``current`` became active.
        best_t: when it was reached [s].
        final_p: its ``p`` at the last tick of ``current``.
        threshold: the switching threshold.
        fired: ``wrong_transition``: the MP switched to instead (empty otherwise).
        at: ``wrong_transition``: when it fired; ``given_up`` (and a ``below_threshold`` that
            was given up on): when the sequencer gave up [s]; ``nan`` otherwise.
        detail: more in words (what held the switch back, the successors there are).
    """

    variable: str
    current: str
    expected: str
    reason: CauseReason
    best_p: float = math.nan
    best_t: float = math.nan
    final_p: float = math.nan
    threshold: float = math.nan
    fired: str = ""
    at: float = math.nan
    detail: str = ""

    def __post_init__(self) -> None:
        if self.reason not in CAUSE_REASONS:
            raise DataError(
                f"a pending switch's reason is one of {', '.join(CAUSE_REASONS)}, "
                f"got {self.reason!r}"
            )

    @property
    def edge(self) -> str:
        """``variable current -> expected`` in words."""
        return f"{self.variable} {self.current} -> {self.expected or '(no switch)'}"

    def describe(self) -> str:
        """The cause in one line.

        E.g. ``right_pos lower -> home never fired: p reached 0.926 at 7.16 s, above 0.65 but
        still rising``.
        """
        reached = ""
        if math.isfinite(self.best_p):
            reached = f"p reached {self.best_p:.3f} at {self.best_t:.2f} s"
        thr = f"{self.threshold:g}" if math.isfinite(self.threshold) else "the threshold"
        reason = self.reason
        if reason == "task_unfinished":
            text = "every variable ran the demonstrated MPs; the task still did not finish"
        elif reason == "wrong_transition":
            text = f"{self.variable} {self.current} -> {self.fired} fired"
            text += f" at {self.at:.2f} s" if math.isfinite(self.at) else ""
            text += f" instead of -> {self.expected}" if self.expected else " (no switch due)"
            text += f" ({reached} for {self.expected})" if reached else ""
        elif reason == "not_a_successor":
            text = f"{self.edge} is not a transition of the sequence graph"
        elif reason == "unknown":
            text = f"{self.edge} never fired (the policy does not say why)"
        else:
            text = f"{self.edge} never fired: " + (reached or "no p")
            if reason == "below_threshold":
                text += f", below {thr}"
                if math.isfinite(self.at):
                    text += f"; the sequencer gave up at {self.at:.2f} s"
            elif reason == "still_improving":
                text += f", above {thr} but still rising"
            elif reason == "held":
                text += f", above {thr} but held back"
            else:  # given_up
                text += f", above {thr} only after the sequencer gave up at {self.at:.2f} s"
        if self.detail:
            text += f" ({self.detail})"
        return text

    def to_dict(self) -> dict[str, str | float | None]:
        """The fields as a JSON-ready dict (``nan`` as ``None``)."""
        out: dict[str, str | float | None] = {}
        for name, value in self.__dict__.items():
            out[name] = None if isinstance(value, float) and not math.isfinite(value) else value
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, object]) -> PendingSwitch:
        """The record of :meth:`to_dict` (``None`` as ``nan``).

        Raises:
            DataError: a field is missing or the reason is not one of :data:`CAUSE_REASONS`.
        """
        try:
            floats = {
                k: math.nan if data.get(k) is None else float(data[k])  # type: ignore[arg-type]
                for k in ("best_p", "best_t", "final_p", "threshold", "at")
            }
            return cls(
                str(data["variable"]),
                str(data["current"]),
                str(data["expected"]),
                data["reason"],  # type: ignore[arg-type]
                fired=str(data.get("fired", "")),
                detail=str(data.get("detail", "")),
                **floats,
            )
        except (KeyError, TypeError, ValueError) as err:
            raise DataError(f"not a pending switch: {data!r} ({err})") from err


class Divergence(NamedTuple):
    """Where an episode's MP sequences first leave the demonstrator's (:func:`divergence`).

    Attributes:
        variable: the control variable.
        index: the position in its sequence (``>= 1``): the switch number ``index``.
        current: its MP before that switch (``sequence[index - 1]``).
        expected: the demonstrator's MP there (empty: the demonstrator switched no more).
        fired: the MP the episode switched to there (empty: it has not switched yet).
    """

    variable: str
    index: int
    current: str
    expected: str
    fired: str


def divergence(
    sequences: Mapping[str, Sequence[str]], expected: Mapping[str, Sequence[str]]
) -> Divergence | None:
    """The first place the episode's MP sequences leave the demonstrator's.

    A wrong switch (a variable's sequence that is not a prefix of the demonstrator's) comes
    first; otherwise, of the variables whose sequence is shorter, the one with the most
    demonstrated switches still to make (the furthest behind: a variable left with only its
    last switch is usually waiting for the others, e.g. a helper arm that retreats once the
    task is done), the first in ``expected``'s order among equals.

    Args:
        sequences: variable -> the MPs the episode ran, in order.
        expected: variable -> the MPs the demonstrator ran on the same context.

    Returns:
        The divergence, or ``None`` when every sequence equals the demonstrator's or a
        variable started with another MP (a wrong start, not a missing switch).
    """
    pending: tuple[Divergence, int] | None = None
    for v, want in expected.items():
        ran = list(sequences.get(v, ()))
        if not ran or not want or ran[0] != want[0]:
            return None
        same = min(len(ran), len(want))
        k = next((i for i in range(same) if ran[i] != want[i]), same)
        if k < len(ran):  # a switch to another MP than the demonstrator's, or one too many
            return Divergence(v, k, ran[k - 1], want[k] if k < len(want) else "", ran[k])
        left = len(want) - k
        if left > 0 and (pending is None or left > pending[1]):
            pending = (Divergence(v, k, ran[k - 1], want[k], ""), left)
    return None if pending is None else pending[0]


def pending_switch(
    sequences: Mapping[str, Sequence[str]],
    expected: Mapping[str, Sequence[str]],
    events: Sequence[TransitionEvent] = (),
) -> PendingSwitch | None:
    """The cause of an incomplete episode from its MP sequences alone (any policy).

    Args:
        sequences: variable -> the MPs the episode ran, in order.
        expected: variable -> the MPs the demonstrator ran on the same context.
        events: the episode's transitions (for the time of a wrong one), if known.

    Returns:
        ``wrong_transition`` or ``unknown`` for the first :func:`divergence`;
        ``task_unfinished`` when the sequences are the demonstrator's; ``None`` after a wrong
        start.
    """
    found = divergence(sequences, expected)
    if found is None:
        same = all(list(sequences.get(v, ())) == list(w) for v, w in expected.items())
        return PendingSwitch("", "", "", "task_unfinished") if same else None
    if not found.fired:
        return PendingSwitch(found.variable, found.current, found.expected, "unknown")
    mine = [e for e in events if e.variable == found.variable]
    at = mine[found.index - 1].t if len(mine) >= found.index else math.nan
    return PendingSwitch(
        found.variable, found.current, found.expected, "wrong_transition", fired=found.fired, at=at
    )


def episode_cause(
    policy: object,
    sequences: Mapping[str, Sequence[str]],
    expected: Mapping[str, Sequence[str]],
    index: int | None = None,
    events: Sequence[TransitionEvent] = (),
) -> PendingSwitch | None:
    """The cause of an incomplete episode, explained by the policy where it can.

    A policy with ``explain`` (a fitted :class:`~cpmp.sequencer.ConcurrentSequencer`:
    ``explain(expected)``; a :class:`~cpmp.sequencer.BatchedSequencer`: ``explain(index,
    expected)``) names why the switch did not fire; any other gets :func:`pending_switch`.

    Args:
        policy: the policy that ran the episode (single, or the batch with ``index``).
        sequences: variable -> the MPs the episode ran, in order.
        expected: variable -> the MPs the demonstrator ran on the same context.
        index: the episode's index in a batched ``policy`` (``None``: a single policy).
        events: the episode's transitions, if known.

    Returns:
        The cause (``None`` after a wrong start).
    """
    explain = getattr(policy, "explain", None)
    cause = None
    if callable(explain):
        cause = explain(expected) if index is None else explain(index, expected)
    return cause if cause is not None else pending_switch(sequences, expected, events)


class Policy(Protocol):
    """What a closed loop drives, one episode: ``reset`` at the start, then ``step`` every tick.

    A fitted :class:`~cpmp.sequencer.ConcurrentSequencer` is one.
    """

    def reset(self, t: float, x: np.ndarray) -> Mapping[str, str]:
        """Start at time ``t`` [s] with features ``x (d,)``; variable -> initial MP."""
        ...

    def step(self, t: float, x: np.ndarray) -> Mapping[str, str]:
        """One control tick at time ``t`` [s] with features ``x (d,)``; variable -> active MP."""
        ...


class BatchedPolicy(Protocol):
    """:class:`Policy` for ``N`` episodes at once.

    E.g. :class:`~cpmp.sequencer.BatchedSequencer`. ``x`` is ``(N, d)``; ``live`` ``(N,)`` bool
    marks the episodes still running (the others' rows are to be ignored); the result holds
    one mapping variable -> MP per episode.
    """

    def __len__(self) -> int: ...

    def reset(
        self, t: float, x: np.ndarray, live: np.ndarray | None = None
    ) -> Sequence[Mapping[str, str]]:
        """Start the ``live`` episodes at time ``t`` [s] with features ``x (N, d)``."""
        ...

    def step(
        self, t: float, x: np.ndarray, live: np.ndarray | None = None
    ) -> Sequence[Mapping[str, str]]:
        """One control tick of the ``live`` episodes at time ``t`` [s], features ``x (N, d)``."""
        ...


__all__ = [
    "CAUSE_REASONS",
    "NOTE_KINDS",
    "SWITCH_KINDS",
    "BatchedPolicy",
    "CauseReason",
    "Divergence",
    "NoteKind",
    "PendingSwitch",
    "Policy",
    "RecoveryCounts",
    "ReplayResult",
    "SequencerNote",
    "StartDecision",
    "StartOption",
    "SwitchKind",
    "TickInfo",
    "TransitionEvent",
    "count_recoveries",
    "divergence",
    "episode_cause",
    "pending_switch",
]
