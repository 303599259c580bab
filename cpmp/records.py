"""The records every layer shares: transitions, notes, ticks, replays, fit reports, protocols.

A transition, a sequencer note, a start decision, a control tick, an open-loop replay, the
policy protocols a closed loop drives, an episode's recoveries judged against the demonstrator
(:func:`count_recoveries`), the cause of an incomplete episode (:class:`PendingSwitch`,
:func:`pending_switch`, :func:`episode_cause`) and what a fit reports (:class:`FitReport` for
the learned sequencer, filled by the predictor's training and the sequencer's fit;
:class:`BaselineFitReport` for the baselines); the closed sets of transition, note and cause
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
from typing import Literal, NamedTuple, Protocol, TypeAlias, get_args

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
            state; otherwise ``Σ log(1 - φ)`` of its MPs' nodes, φ read through their progress
            predictors: the log-likelihood that each MP is at its beginning (higher is more
            likely; 0 is certain).
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


JsonValue: TypeAlias = "str | int | float | bool | list[JsonValue] | dict[str, JsonValue] | None"
"""A value a JSON file holds (what a fit report's free-form facts are made of)."""


@dataclass(frozen=True)
class NewtonOutcome:
    """How the damped Newton steps of a convex fit ended, for the worst node.

    Attributes:
        iterations: the most Newton iterations any node took.
        grad_max: the largest final gradient max-norm over the nodes.
        converged: every node reached the trainer's ``newton_tol``.
    """

    iterations: int
    grad_max: float
    converged: bool


_TRAINING_KEYS = (
    "loss",
    "loss_history",
    "val_loss",
    "val_mae",
    "val_mae_final",
    "lr_history",
    "epochs",
    "max_epochs",
    "stopped_early",
    "monitor",
    "device",
    "seconds",
    "solver",
    "kind",
    "n_nodes",
    "n_parameters",
)
_SUPPORT_KEYS = ("support_counts", "n_support_total")
_NEWTON_KEYS = ("newton_iterations", "newton_grad_max", "newton_converged")
_SEQUENCER_KEYS = ("n_demos", "label_glitches", "warnings", "stay_choices", "entry_scale")
_FIT_REPORT_KEYS = frozenset(_TRAINING_KEYS + _SUPPORT_KEYS + _NEWTON_KEYS + _SEQUENCER_KEYS)


@dataclass(frozen=True)
class FitReport:
    """What the fit of a learned sequencer reports (``ConcurrentSequencer.fit_summary``).

    The progress predictor's training (:func:`cpmp.predictors.training.fit_predictor`) fills
    the fields down to ``newton``; the sequencer's fit (:func:`cpmp.sequencer.fit.fit_parts`,
    :meth:`~cpmp.sequencer.ConcurrentSequencer.fit_config`) adds the ones after it. Sequences
    are kept as tuples. :meth:`to_dict` is the JSON form (``report.json``, the checkpoints'
    ``fit_summary``, the benchmarks), :meth:`from_dict` reads it back, also as checkpoints
    written before a field existed hold it.

    Attributes:
        loss: the training loss of the fitted bank (after its ``finalize``; soft-label
            cross-entropy, eq. 5, or the predictor's own training loss).
        loss_history: the training loss of each epoch, in order.
        val_loss: the validation loss of each epoch (empty without validation data).
        val_mae: the held-out progress MAE of each epoch (empty without validation data).
        val_mae_final: the held-out progress MAE of the fitted bank (after ``finalize``);
            ``None`` without validation data.
        lr_history: the learning rate of each epoch (Adam and LBFGS; empty for Newton).
        epochs: the epochs actually run.
        max_epochs: the epoch budget.
        stopped_early: early stopping ended an Adam fit before ``max_epochs``.
        monitor: the quantity early stopping and the rate decay watch (``val/loss`` with
            validation data, ``train/loss`` without).
        device: the device the fit ran on (``cpu``, ``cuda:0``).
        seconds: the wall time of the predictor's fit [s].
        solver: how the parameters were fitted: ``adam``, ``newton`` or ``lbfgs``.
        kind: the predictor's kind (``klr``, ``mlp``, ...).
        n_nodes: the bank's heads, one per graph node.
        n_parameters: the bank's parameter entries (trainable or not).
        support_counts: kernel banks: ``"variable/mp"`` -> its support points; ``None`` for
            the others.
        n_support_total: kernel banks: the support points of all heads; ``None`` otherwise.
        predictor_facts: the rest of the predictor's own facts
            (:meth:`~cpmp.predictors.ProgressPredictor.summary`, in its order): e.g.
            ``hidden`` (mlp), ``window`` (dtw), ``sparsity_path``, ``sparsity_level``
            (klr_sparse).
        newton: convex fits by Newton steps: how they ended; ``None`` for the others.
        n_demos: the training demonstrations (validation ones taken out).
        label_glitches: the label glitches repaired before the graphs were built, each as
            :meth:`cpmp.sequencer.glitches.LabelGlitch.to_dict`.
        warnings: what the fit warned about (short activations, still nodes, ...), readable.
        stay_choices: ``"variable: mp"`` of each node with a learned stay choice.
        entry_scale: ``"variable: source -> target"`` -> the factor dividing that edge's
            entry probability (the edges whose demonstrated switches φ would not make).
    """

    loss: float
    loss_history: tuple[float, ...]
    val_loss: tuple[float, ...]
    val_mae: tuple[float, ...]
    val_mae_final: float | None
    lr_history: tuple[float, ...]
    epochs: int
    max_epochs: int
    stopped_early: bool
    monitor: str
    device: str
    seconds: float
    solver: str
    kind: str
    n_nodes: int
    n_parameters: int
    support_counts: Mapping[str, int] | None = None
    n_support_total: int | None = None
    predictor_facts: Mapping[str, JsonValue] = field(default_factory=dict)
    newton: NewtonOutcome | None = None
    n_demos: int = 0
    label_glitches: tuple[Mapping[str, JsonValue], ...] = ()
    warnings: tuple[str, ...] = ()
    stay_choices: tuple[str, ...] = ()
    entry_scale: Mapping[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for name in ("loss_history", "val_loss", "val_mae", "lr_history", "warnings"):
            object.__setattr__(self, name, tuple(getattr(self, name)))
        object.__setattr__(self, "stay_choices", tuple(self.stay_choices))
        object.__setattr__(self, "label_glitches", tuple(dict(g) for g in self.label_glitches))
        object.__setattr__(self, "predictor_facts", dict(self.predictor_facts))
        object.__setattr__(self, "entry_scale", dict(self.entry_scale))
        if self.support_counts is not None:
            object.__setattr__(self, "support_counts", dict(self.support_counts))
        clash = sorted(_FIT_REPORT_KEYS & set(self.predictor_facts))
        if clash:
            raise DataError(f"predictor facts {clash} are fields of the fit report itself")

    def to_dict(self) -> dict[str, JsonValue]:
        """The report as the JSON-ready dict the fit has always written, in its key order.

        The training's keys, the predictor's facts (``kind``, ``n_nodes``, ``n_parameters``,
        ``support_counts`` and ``n_support_total`` where set, then :attr:`predictor_facts`),
        Newton's outcome as ``newton_iterations``, ``newton_grad_max`` and
        ``newton_converged`` (convex Newton fits only), then ``n_demos``, ``label_glitches``,
        ``warnings``, ``stay_choices`` and ``entry_scale``. Values are as the fit gave them
        (:func:`cpmp.io.to_builtin` makes them plain for a checkpoint).
        """
        out: dict[str, JsonValue] = {}
        for key in _TRAINING_KEYS:  # the histories are tuples here, lists in JSON
            value = getattr(self, key)
            out[key] = list(value) if isinstance(value, tuple) else value
        if self.support_counts is not None:
            out["support_counts"] = dict(self.support_counts)
        if self.n_support_total is not None:
            out["n_support_total"] = self.n_support_total
        out.update(self.predictor_facts)
        if self.newton is not None:
            out["newton_iterations"] = self.newton.iterations
            out["newton_grad_max"] = self.newton.grad_max
            out["newton_converged"] = self.newton.converged
        out["n_demos"] = self.n_demos
        out["label_glitches"] = [dict(g) for g in self.label_glitches]
        out["warnings"] = list(self.warnings)
        out["stay_choices"] = list(self.stay_choices)
        out["entry_scale"] = dict(self.entry_scale)
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, object]) -> FitReport:
        """The report of :meth:`to_dict`, or of a checkpoint's ``fit_summary``.

        Keys a checkpoint written before they existed lacks take the value that says so:
        empty histories, ``val_mae_final`` ``None``, ``max_epochs`` the epochs run,
        ``stopped_early`` false, ``monitor``, ``device`` and ``solver`` empty, no Newton
        outcome, no glitches, warnings, stay choices or entry factors. Keys the report has no
        field for are kept among :attr:`predictor_facts`.

        Raises:
            DataError: ``loss``, ``seconds``, ``epochs`` or ``kind`` missing, or a value of
                the wrong type.
        """
        get = data.get
        try:
            newton = None
            if "newton_iterations" in data:
                newton = NewtonOutcome(
                    _int(data["newton_iterations"]),
                    _float(get("newton_grad_max")),
                    bool(get("newton_converged", False)),
                )
            counts = get("support_counts")
            total = get("n_support_total")
            val_final = get("val_mae_final")
            epochs = _int(data["epochs"])
            return cls(
                loss=_float(data["loss"]),
                loss_history=tuple(_float(v) for v in _items(get("loss_history", []))),
                val_loss=tuple(_float(v) for v in _items(get("val_loss", []))),
                val_mae=tuple(_float(v) for v in _items(get("val_mae", []))),
                val_mae_final=None if val_final is None else _float(val_final),
                lr_history=tuple(_float(v) for v in _items(get("lr_history", []))),
                epochs=epochs,
                max_epochs=_int(get("max_epochs", epochs)),
                stopped_early=bool(get("stopped_early", False)),
                monitor=str(get("monitor", "")),
                device=str(get("device", "")),
                seconds=_float(data["seconds"]),
                solver=str(get("solver", "")),
                kind=str(data["kind"]),
                n_nodes=_int(get("n_nodes", 0)),
                n_parameters=_int(get("n_parameters", 0)),
                support_counts=(
                    None if counts is None else {k: _int(v) for k, v in _mapping(counts).items()}
                ),
                n_support_total=None if total is None else _int(total),
                predictor_facts={
                    k: v for k, v in _mapping(data).items() if k not in _FIT_REPORT_KEYS
                },
                newton=newton,
                n_demos=_int(get("n_demos", 0)),
                label_glitches=tuple(_mapping(g) for g in _items(get("label_glitches", []))),
                warnings=tuple(str(w) for w in _items(get("warnings", []))),
                stay_choices=tuple(str(s) for s in _items(get("stay_choices", []))),
                entry_scale={
                    str(k): _float(v) for k, v in _mapping(get("entry_scale", {})).items()
                },
            )
        except (KeyError, TypeError, ValueError) as err:
            raise DataError(f"not a fit report ({type(err).__name__}: {err})") from err


@dataclass(frozen=True)
class BaselineFitReport:
    """What the fit of a sequencing baseline reports (its ``fit_summary``).

    The baselines (:mod:`cpmp.baselines`: ``goal_nearest``, ``bc``) learn no progress
    predictor in Lightning; they report what every fit does. :meth:`to_dict` is the JSON form,
    :meth:`from_dict` reads it back.

    Attributes:
        kind: the baseline's kind (``goal_nearest``, ``bc``).
        n_demos: the training demonstrations.
        n_support_total: ``bc``: the support points of all node classifiers; ``None`` for a
            baseline without supports.
        seconds: the wall time of the fit [s].
        nodes: ``bc``: ``"variable/mp"`` -> its classifier's fit
            (:class:`cpmp.baselines.bc.NodeFit` as a dict); ``None`` for the others.
        warnings: what the fit warned about, readable (not kept in a checkpoint).
    """

    kind: str
    n_demos: int
    n_support_total: int | None
    seconds: float
    nodes: Mapping[str, Mapping[str, JsonValue]] | None = None
    warnings: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "warnings", tuple(self.warnings))
        if self.nodes is not None:
            object.__setattr__(self, "nodes", {k: dict(v) for k, v in self.nodes.items()})

    def to_dict(self) -> dict[str, JsonValue]:
        """The report as the JSON-ready dict the baselines have always written.

        ``kind``, ``n_demos``, ``n_support_total``, ``seconds``, ``nodes`` (where set) and
        ``warnings``, in that order.
        """
        out: dict[str, JsonValue] = {
            "kind": self.kind,
            "n_demos": self.n_demos,
            "n_support_total": self.n_support_total,
            "seconds": self.seconds,
        }
        if self.nodes is not None:
            out["nodes"] = {k: dict(v) for k, v in self.nodes.items()}
        out["warnings"] = list(self.warnings)
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, object]) -> BaselineFitReport:
        """The report of :meth:`to_dict` (a checkpoint's, without ``warnings``: none).

        Raises:
            DataError: ``kind``, ``n_demos`` or ``seconds`` missing, or a value of the wrong
                type.
        """
        try:
            total = data.get("n_support_total")
            nodes = data.get("nodes")
            return cls(
                kind=str(data["kind"]),
                n_demos=_int(data["n_demos"]),
                n_support_total=None if total is None else _int(total),
                seconds=_float(data["seconds"]),
                nodes=(
                    None if nodes is None else {k: _mapping(v) for k, v in _mapping(nodes).items()}
                ),
                warnings=tuple(str(w) for w in _items(data.get("warnings", []))),
            )
        except (KeyError, TypeError, ValueError) as err:
            raise DataError(f"not a baseline's fit report ({type(err).__name__}: {err})") from err


def _float(value: object) -> float:
    """``value`` as a float (``None``, as a checkpoint stores a non-finite one: ``nan``)."""
    if value is None:
        return math.nan
    if not isinstance(value, int | float | str):
        raise TypeError(f"expected a number, got {type(value).__name__}")
    return float(value)


def _int(value: object) -> int:
    """``value`` as an int (a JSON number)."""
    if not isinstance(value, int | float | str):
        raise TypeError(f"expected a number, got {type(value).__name__}")
    return int(value)


def _items(value: object) -> list[object]:
    """The items of a JSON list (or tuple)."""
    if not isinstance(value, list | tuple):
        raise TypeError(f"expected a list, got {type(value).__name__}")
    return list(value)


def _mapping(value: object) -> dict[str, JsonValue]:
    """A JSON object as a dict."""
    if not isinstance(value, Mapping):
        raise TypeError(f"expected a mapping, got {type(value).__name__}")
    return {str(k): v for k, v in value.items()}


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
    "BaselineFitReport",
    "BatchedPolicy",
    "CauseReason",
    "Divergence",
    "FitReport",
    "JsonValue",
    "NewtonOutcome",
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
