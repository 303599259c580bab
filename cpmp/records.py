"""The records every layer shares: transitions, notes, ticks, replays and policy protocols.

A transition, a sequencer note, a start decision, a control tick, an open-loop replay, the
policy protocols a closed loop drives, and an episode's recoveries judged against the demonstrator
(:func:`count_recoveries`); the closed sets of transition and note kinds (:data:`SwitchKind`,
:data:`NoteKind`) are checked where a record is made.

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
    "NOTE_KINDS",
    "SWITCH_KINDS",
    "BatchedPolicy",
    "NoteKind",
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
]
