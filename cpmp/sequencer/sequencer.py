"""The concurrent sequencer: one sequence graph per control variable.

Transition rule (paper section III): at the start each graph activates the initial node with
the highest entry probability ``1 - φ`` (cpmp's default, ``start_rule="learned"``: the
demonstrated combination of initial MPs that the demonstrations' first states say, a learned
choice on the features that separate them, :class:`~cpmp.sequencer.branches.StartChoice`;
``start_rule="joint"``: the demonstrated combination with the highest summed log entry
probability). At every tick, for
each successor ``s`` of the current node ``c`` the transition probability is
``p_s = φ_c(x) · (1 - φ_s(x))``; a switching rule (:mod:`cpmp.sequencer.switching`) decides when
the best successor fires. In the paper the graphs are coupled only through the shared features
``x``; cpmp's defaults also hold back transitions whose context (the other variables' MPs) was never
demonstrated, and resolve stalls (:mod:`cpmp.sequencer.switching`).

``ConcurrentSequencer.fit(demos)`` with no options gives cpmp's recommended configuration;
``ConcurrentSequencer.fit(demos, predictor="klr", **PAPER_OPTIONS)`` the paper's method.
``seq.batched(n)`` (:class:`~cpmp.sequencer.batch.BatchedSequencer`) runs ``n`` episodes with one
predictor call per tick. The fit itself: :mod:`cpmp.sequencer.fit` (the one module here that imports
Lightning, imported by :meth:`ConcurrentSequencer.fit_config` when it is called, so that loading and
stepping a checkpoint never do); what it trains on and checks: :mod:`cpmp.sequencer.fit_data`; the
state machine of one episode: :mod:`cpmp.sequencer.episode`.
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import torch

from cpmp.config import FitConfig, SequencerConfig, existing_sequencer_options
from cpmp.config.validation import OptionValue
from cpmp.data import Demonstration
from cpmp.errors import ConfigError
from cpmp.graph import SequenceGraph
from cpmp.io import (
    CheckpointPayload,
    CheckpointSpec,
    load_checkpoint,
    save_checkpoint,
    to_builtin,
)
from cpmp.predictors import ProgressPredictor, predictor_from_spec
from cpmp.records import (
    FitReport,
    PendingSwitch,
    ReplayResult,
    SequencerNote,
    StartDecision,
    TickInfo,
    TransitionEvent,
)
from cpmp.sequencer.batch import BatchedSequencer
from cpmp.sequencer.branches import BranchChoices, StartChoice, entry_scales, stay_examples
from cpmp.sequencer.episode import SequencerEpisode
from cpmp.sequencer.fit_data import nonfinite_parameters
from cpmp.sequencer.inputs import checked_features, checked_time
from cpmp.sequencer.model import NodeIndex, TransitionModel
from cpmp.sequencer.switching import Coupling

if TYPE_CHECKING:
    from lightning.pytorch.loggers import Logger

log = logging.getLogger(__name__)

CHECKPOINT_FORMAT = "cpmp-sequencer"
CHECKPOINT_VERSION = 2
CHECKPOINT = CheckpointSpec(
    CHECKPOINT_FORMAT,
    (CHECKPOINT_VERSION,),
    "cpmp sequencer",
    "load a file written by ConcurrentSequencer.save, or retrain the model with scripts/train.py",
)
"""The sequencer's checkpoint kind."""

PAPER_OPTIONS: dict[str, str | bool] = {
    "feature_weighting": "none",
    "feature_scaling": "none",
    "path_noise": "none",
    "start_rule": "independent",
    "switch_rule": "paper",
    "coupling": "none",
    "recovery": False,
    "branch": "none",
    "joint": False,
}
"""Fit options that turn :meth:`ConcurrentSequencer.fit`'s defaults into the paper's method:
``ConcurrentSequencer.fit(demos, predictor="klr", **PAPER_OPTIONS)`` (the main job's
``predictor=paper sequencer=paper``)."""


class ConcurrentSequencer:
    """Concurrent sequence graphs with learned progress predictors.

    Build one with :meth:`fit` (from demonstrations) or :meth:`load` (from a checkpoint); drive it
    with :meth:`reset` then :meth:`step` once per control tick.
    """

    def __init__(
        self,
        graphs: Mapping[str, SequenceGraph],
        predictor: ProgressPredictor,
        feature_names: Sequence[str],
        config: SequencerConfig | None = None,
        fit_summary: FitReport | None = None,
        initial_combinations: Sequence[Mapping[str, str]] | None = None,
        coupling: Coupling | None = None,
        feature_range: np.ndarray | None = None,
        branches: BranchChoices | None = None,
    ) -> None:
        self.graphs = dict(graphs)
        self.predictor = predictor.eval()
        self.feature_names = list(feature_names)
        self.config = config or SequencerConfig()
        self.fit_summary = fit_summary
        """What the fit reported; ``None`` for a sequencer built by hand or loaded from a
        checkpoint without one."""
        self.initial_combinations = [dict(c) for c in initial_combinations or []]
        """Initial MP per variable of each demonstration (distinct; for ``start_rule=joint``)."""
        if len(self.feature_names) != predictor.n_features:
            raise ConfigError(
                f"{len(self.feature_names)} feature names for a predictor of "
                f"{predictor.n_features} features"
            )
        self.nodes = NodeIndex.build(self.graphs, predictor.node_keys)
        """Where each node's φ sits among the predictor's heads, and the successor tables."""
        self.coupling = coupling or Coupling()
        """Learned contexts of the demonstrated switches (used with ``coupling="context"``)."""
        self.feature_range = (
            np.ones(len(self.feature_names))
            if feature_range is None
            else np.asarray(feature_range, dtype=np.float64).reshape(-1)
        )
        """(d,) range of each feature in the training data (stall detection's unit)."""
        if self.feature_range.shape != (len(self.feature_names),):
            raise ConfigError(
                f"feature_range has {self.feature_range.size} entries for "
                f"{len(self.feature_names)} features"
            )
        self.learned_branches = (
            BranchChoices.learn(self.coupling, self.feature_range) if branches is None else branches
        )
        """The choices learned at the fit (:mod:`cpmp.sequencer.branches`; without them, those
        at the nodes with several demonstrated successors, from the coupling)."""
        self.branches = (
            self.learned_branches
            if self.config.branch == "learned"
            else BranchChoices({}, self.learned_branches.start)
        )
        """The choices the transition rule uses: with ``branch=none`` (the paper's) no branch
        or stay choice and no entry scaling; the start is read with ``start_rule=learned``."""
        self.transition_model = TransitionModel(
            self.graphs,
            self.nodes,
            self.config,
            self.coupling,
            self.feature_range,
            self.initial_combinations,
            self.branches,
            list(self.feature_names),
        )
        """What each episode reads (:class:`~cpmp.sequencer.model.TransitionModel`)."""
        self._episode = SequencerEpisode(self.transition_model)
        self._held: np.ndarray | None = None

    # ----------------------------------------------------------------------------- fitting
    @classmethod
    def fit(
        cls,
        demos: Sequence[Demonstration],
        predictor: str = "klr",
        *,
        validation: Sequence[Demonstration] | None = None,
        logger: Logger | str | None = None,
        **options: OptionValue,
    ) -> ConcurrentSequencer:
        """Build the sequence graphs and fit every node's progress predictor, by keyword.

        The keyword form of :meth:`fit_config`: ``fit_config(demos,
        FitConfig.from_options(predictor, **options), validation=..., logger=...)``.

        Args:
            demos: labelled demonstrations sharing feature names and control variables.
            predictor: ``klr`` (default), ``klr_full``, ``klr_sparse``, ``mlp`` or a baseline.
            **options: predictor options (e.g. ``gamma``, ``support_scale``, ``min_support``,
                ``l2``, ``feature_scaling``: the fields of its options class), sequencer
                options (:class:`~cpmp.config.SequencerConfig`), trainer options
                (:class:`~cpmp.config.TrainerConfig`), ``seed``, ``variables`` and
                ``subsample`` (:class:`~cpmp.config.FitConfig`); an unknown name raises
                :class:`~cpmp.errors.ConfigError`.
            validation: held-out demonstrations: every epoch logs the progress MAE on them
                (``val/mae``), and early stopping follows their loss (see :meth:`fit_config`).
            logger: a Lightning ``Logger``, ``"csv"`` or ``"tensorboard"`` (writing into the
                trainer option ``log_dir``), or ``None``: no logging.

        Returns:
            The fitted sequencer.
        """
        config = FitConfig.from_options(predictor, **options)
        return cls.fit_config(demos, config, validation=validation, logger=logger)

    @classmethod
    def fit_config(
        cls,
        demos: Sequence[Demonstration],
        config: FitConfig | None = None,
        *,
        validation: Sequence[Demonstration] | None = None,
        logger: Logger | str | None = None,
    ) -> ConcurrentSequencer:
        """Build the sequence graphs and fit every node's progress predictor as ``config`` says.

        Args:
            demos: labelled demonstrations sharing feature names and control variables.
            config: predictor, rule, trainer and seed (``None``: cpmp's defaults, the main
                job's ``predictor=klr sequencer=coupled``).
            validation: the fit's held-out demonstrations (``None``: the trainer's
                ``val_fraction`` of ``demos``, none by default): the progress MAE on them is
                logged every epoch (``fit_summary.val_mae``) and Adam fits stop on their
                loss.
            logger: a Lightning ``Logger``, ``"csv"``, ``"tensorboard"`` (both writing into
                the trainer's ``log_dir``) or ``None`` (no logging).

        Label glitches (``A A X A A``) are repaired first unless ``config.repair_glitches`` is
        off; ``fit_summary.label_glitches`` lists each, with the node and edges it would
        have added.

        Returns:
            The fitted sequencer.

        Raises:
            DataError: bad demonstrations, or a fit with non-finite parameters.
            ConfigError: a bad option or logger.
        """
        from cpmp.sequencer.fit import fit_parts  # lazy: Lightning, only to fit, not to step

        config = config or FitConfig()
        fitted = fit_parts(demos, config, validation, logger)
        for text in [g.describe() for g in fitted.glitches] + list(fitted.summary.warnings):
            log.warning("%s", text)
        graphs = fitted.graphs
        seq = cls(
            graphs,
            fitted.predictor,
            fitted.feature_names,
            config.sequencer,
            fitted.summary,
            fitted.initial_combinations,
            fitted.coupling,
            fitted.feature_range,
        )
        stays = seq._confusing(stay_examples(fitted.demos, sorted(graphs)))
        start = StartChoice.learn(
            fitted.demos, sorted(graphs), fitted.feature_range, fitted.coupling.ambient
        )
        scales = seq._entry_scales()
        coupling = seq._carried(scales)
        seq.fit_summary = dataclasses.replace(
            fitted.summary,
            stay_choices=tuple(sorted(f"{v}: {mp}" for v, mp in stays)),
            entry_scale={f"{v}: {a} -> {b}": g for (v, a, b), g in scales.items()},
        )
        return seq._with_branches(
            BranchChoices.learn(fitted.coupling, fitted.feature_range, stays, start, scales),
            coupling,
        )

    def _entry_scales(self) -> dict[tuple[str, str, str], float]:
        """The entry factors of the demonstrated switches φ would not make.

        See :func:`~cpmp.sequencer.branches.entry_scales`; none for a stateful predictor.
        """
        if self.predictor.stateful:
            return {}
        exit_phi, entry = {}, {}
        for (v, source), instances in sorted(self.coupling.instances.items()):
            phi = self.progress(np.stack([inst.state for inst in instances]))
            for k, inst in enumerate(instances):
                key = (v, source, inst.target)
                if (v, inst.target) not in self.nodes.index:
                    continue
                exit_phi.setdefault(key, []).append(phi[k, self.nodes.index[(v, source)]])
                entry.setdefault(key, []).append(1.0 - phi[k, self.nodes.index[(v, inst.target)]])
        return entry_scales(
            {k: np.asarray(e) for k, e in exit_phi.items()},
            {k: np.asarray(e) for k, e in entry.items()},
            self.config.threshold,
        )

    def _carried(self, scales: Mapping[tuple[str, str, str], float]) -> Coupling:
        """The coupling with the joint partners its switches take along marked.

        See :meth:`~cpmp.sequencer.switching.Coupling.with_carried`; none for a stateful
        predictor, whose φ of a state alone means nothing.
        """
        if self.predictor.stateful:
            return self.coupling
        return self.coupling.with_carried(
            self.progress, self.nodes.index, self.config.threshold, scales
        )

    def _confusing(
        self, stays: Mapping[tuple[str, str], list[np.ndarray]]
    ) -> dict[tuple[str, str], list[np.ndarray]]:
        """The nodes among ``stays`` at one of whose stay states a transition's ``p`` is high.

        There the progress predictor alone would have switched where the demonstrator stayed
        (:func:`~cpmp.sequencer.branches.stay_examples`); the others need no stay choice. A
        stateful predictor (``dtw``) has no φ of a state on its own: none then.
        """
        out: dict[tuple[str, str], list[np.ndarray]] = {}
        if self.predictor.stateful:
            return out
        for (v, mp), states in sorted(stays.items()):
            _, columns = self.nodes.successors[(v, mp)]
            if not columns:
                continue
            phi = self.progress(np.stack(states))
            p = phi[:, [self.nodes.index[(v, mp)]]] * (1.0 - phi[:, columns])
            if float(p.max()) > self.config.threshold:
                out[(v, mp)] = list(states)
        return out

    def _with_branches(
        self, branches: BranchChoices, coupling: Coupling | None = None
    ) -> ConcurrentSequencer:
        """This sequencer with the learned choices ``branches`` (and ``coupling``, if given)."""
        return ConcurrentSequencer(
            self.graphs,
            self.predictor,
            self.feature_names,
            self.config,
            self.fit_summary,
            self.initial_combinations,
            self.coupling if coupling is None else coupling,
            self.feature_range,
            branches,
        )

    # ----------------------------------------------------------------------------- inference
    def progress(self, x: np.ndarray | torch.Tensor) -> np.ndarray:
        """φ of every node for features ``x (..., d)``: ``(..., K)`` in :attr:`node_keys` order.

        Raises:
            DataError: the features do not match :attr:`feature_names` or are not finite.
        """
        xn = checked_features(x, self.feature_names)
        with torch.no_grad():
            return self.predictor(torch.from_numpy(np.ascontiguousarray(xn))).numpy()

    @property
    def node_keys(self) -> list[tuple[str, str]]:
        """(variable, MP) of every node, in the order of :meth:`progress`'s columns."""
        return list(self.nodes.keys)

    def predict_progress(self, x: np.ndarray) -> dict[str, dict[str, float]]:
        """φ of every node for one feature vector ``x (d,)``: variable -> MP -> φ."""
        state = np.asarray(x, dtype=np.float64).reshape(-1)
        return self.nodes.phi_dict(self.progress(state))

    def reset(self, t: float, x: np.ndarray) -> dict[str, str]:
        """Start every graph at its initial node of highest entry probability ``1 - φ``.

        With ``start_rule="joint"``, the demonstrated combination of initial nodes with the
        highest summed log entry probability instead.

        Args:
            t: the time [s].
            x: the features ``(d,)``.

        Returns:
            Variable -> initial MP.
        """
        t = checked_time(t)
        self.predictor.reset_state(1)
        state = np.asarray(x, dtype=np.float64).reshape(-1)
        phi = self.progress(state)
        self._held = state
        return self._episode.start(t, state, phi)

    def step(self, t: float, x: np.ndarray, *, stamp: float | None = None) -> dict[str, str]:
        """Advance one tick at time ``t`` [s] with features ``x (d,)``.

        The switching rule runs on the time the features were measured
        (:mod:`cpmp.sequencer.switching`): features that are not a new measurement (``stamp``
        not advanced; without ``stamp``, the same vector as the last tick's) add no evidence.

        Args:
            t: the time [s], not before the last tick's.
            x: the features ``(d,)``. With a NaN or inf, every MP is kept and noted once per
                run of such ticks (``nonfinite="hold"``, the default), or
                :class:`~cpmp.errors.DataError` is raised (``nonfinite="raise"``).
            stamp: when ``x`` was measured [s], on the clock of ``t``, at or before ``t``
                (e.g. a camera frame's time); ``None``: unknown.

        Returns:
            Variable -> active MP after the tick.
        """
        t = self._episode.check_time(t, stamp)
        state = checked_features(np.asarray(x).reshape(-1), self.feature_names, finite=False)
        if not np.isfinite(state).all():
            if getattr(self.predictor, "stateful", False) and self._held is not None:
                self.progress(self._held)  # a stateful stream gets the last finite features
            return self._episode.advance(t, state, None, False, stamp)
        self._held = state
        phi = self.progress(state)
        between = None if getattr(self.predictor, "stateful", False) else self.progress
        return self._episode.advance(
            t, state, phi.tolist(), bool(np.isfinite(phi).all()), stamp, between
        )

    def batched(self, n: int) -> BatchedSequencer:
        """``n`` independent episodes of this sequencer, stepped together.

        See :class:`~cpmp.sequencer.batch.BatchedSequencer`.
        """
        return BatchedSequencer(self, n)

    @property
    def active(self) -> dict[str, str]:
        """Variable -> active MP of the current episode (empty before :meth:`reset`)."""
        return self._episode.active

    @property
    def events(self) -> list[TransitionEvent]:
        """The transitions of the current episode, in order."""
        return self._episode.events

    @property
    def notes(self) -> list[SequencerNote]:
        """The notes of the current episode (held transitions, recoveries, non-finite φ)."""
        return self._episode.notes

    @property
    def last_tick(self) -> TickInfo | None:
        """What the last :meth:`reset` or :meth:`step` computed (``None`` before a reset)."""
        return self._episode.last_tick

    @property
    def start_decision(self) -> StartDecision | None:
        """How the last :meth:`reset` chose the initial MPs, with every start's score."""
        return self._episode.start_decision

    def explain(self, expected: Mapping[str, Sequence[str]]) -> PendingSwitch | None:
        """Why the current episode has not run ``expected``: the switch that never came.

        Args:
            expected: variable -> the MPs the demonstrator ran on the same context.

        Returns:
            The cause (:meth:`SequencerEpisode.explain`), or ``None`` when there is none.
        """
        return self._episode.explain(expected)

    def replay(self, time: np.ndarray, features: np.ndarray) -> ReplayResult:
        """Run the sequencer open-loop over a recorded feature stream.

        Args:
            time: ``(n,)`` sample times [s].
            features: ``(n, d)`` features.

        Returns:
            The MP sequence per variable and the transition events.
        """
        seqs = {v: [mp] for v, mp in self.reset(time[0], features[0]).items()}
        for t, x in zip(time[1:], features[1:], strict=True):
            before = dict(self.active)
            after = self.step(t, x)
            for v, mp in after.items():
                if mp != before[v]:
                    seqs[v].append(mp)
        return ReplayResult(seqs, list(self.events))

    # ----------------------------------------------------------------------------- persistence
    def save(self, path: str | Path) -> Path:
        """Write a checkpoint (graphs, predictor weights, configs) atomically to ``path``."""
        return save_checkpoint(
            path,
            {
                "format": CHECKPOINT_FORMAT,
                "version": CHECKPOINT_VERSION,
                "feature_names": self.feature_names,
                "graphs": {v: g.to_dict() for v, g in self.graphs.items()},
                "predictor": {"spec": self.predictor.spec(), "state": self.predictor.state_dict()},
                "sequencer": dataclasses.asdict(self.config),
                "fit_summary": (
                    {} if self.fit_summary is None else to_builtin(self.fit_summary.to_dict())
                ),
                "initial_combinations": self.initial_combinations,
                "coupling": self.coupling.to_dict(),
                "feature_range": self.feature_range.tolist(),
                "branches": self.learned_branches.to_dict(),
                "entry_scale": self.learned_branches.entry_rows(),
                "start_choice": (
                    None
                    if self.learned_branches.start is None
                    else self.learned_branches.start.to_dict()
                ),
            },
        )

    @classmethod
    def load(cls, path: str | Path) -> ConcurrentSequencer:
        """Load a checkpoint written by :meth:`save`."""
        return load_checkpoint(path, CHECKPOINT, cls._from_payload)

    @classmethod
    def _from_payload(cls, payload: CheckpointPayload, version: int) -> ConcurrentSequencer:
        """Rebuild from a checkpoint payload, checking it against its own spec."""
        known = {"format", "version", "sequencer", "graphs", "predictor", "feature_names"}
        missing = sorted(known - set(payload))
        if missing:
            raise KeyError(f"missing entries {missing}")
        # an option removed since, at the value where it did nothing, loads as before
        options = existing_sequencer_options(payload["sequencer"], inert=True)
        unknown = sorted(set(options) - {f.name for f in dataclasses.fields(SequencerConfig)})
        if unknown:
            raise ValueError(f"unknown sequencer options {unknown}")
        if "branches" not in payload:
            # Written before branch choices and joint switches existed: keep its behaviour.
            options.setdefault("branch", "none")
            options.setdefault("joint", False)
        graphs = {v: SequenceGraph.from_dict(g) for v, g in payload["graphs"].items()}
        predictor = predictor_from_spec(payload["predictor"]["spec"])
        state = payload["predictor"]["state"]
        expected = predictor.state_dict()
        problems = [f"missing {k}" for k in expected if k not in state]
        problems += [f"unexpected {k}" for k in state if k not in expected]
        problems += [
            f"{k} has shape {tuple(state[k].shape)}, the spec needs {tuple(v.shape)}"
            for k, v in expected.items()
            if k in state and (not isinstance(state[k], torch.Tensor) or state[k].shape != v.shape)
        ]
        if problems:
            raise ValueError("predictor state does not match its spec: " + "; ".join(problems))
        predictor.load_state_dict(state)
        bad = nonfinite_parameters(predictor)
        if bad:
            raise ValueError(f"non-finite predictor parameters: {', '.join(bad)}")
        feature_range = payload.get("feature_range")
        if feature_range is not None:
            feature_range = np.asarray(feature_range, dtype=np.float64)
            if (
                feature_range.shape != (predictor.n_features,)
                or not np.isfinite(feature_range).all()
            ):
                raise ValueError(
                    f"feature_range must be {predictor.n_features} finite numbers, got shape "
                    f"{feature_range.shape}"
                )
        summary = payload.get("fit_summary") or {}
        return cls(
            graphs,
            predictor,
            payload["feature_names"],
            SequencerConfig(**options),
            FitReport.from_dict(summary) if summary else None,
            payload.get("initial_combinations", []),
            Coupling.from_dict(payload.get("coupling", [])),
            feature_range,
            BranchChoices.from_dict(
                payload.get("branches", []),
                payload.get("start_choice"),
                payload.get("entry_scale"),
            ),
        )

    def with_config(self, **options: OptionValue) -> ConcurrentSequencer:
        """A sequencer sharing graphs and predictor but with other transition-rule options."""
        config = dataclasses.replace(self.config, **options)
        return ConcurrentSequencer(
            self.graphs,
            self.predictor,
            self.feature_names,
            config,
            self.fit_summary,
            self.initial_combinations,
            self.coupling,
            self.feature_range,
            self.learned_branches,
        )

    def describe(self) -> str:
        """All graphs as text, each followed by its learned switch contexts (the coupling)."""
        parts = []
        start = self.branches.start
        if start is not None and self.config.start_rule == "learned":
            parts.append(start.describe(self.feature_names))
        for v in sorted(self.graphs):
            parts.append(self.graphs[v].to_text())
            lines = self.coupling.describe(v, self.feature_names)
            if lines:
                used = "" if self.config.coupling == "context" else " (not used: coupling=none)"
                parts.append(f"{v}: switch contexts{used}")
                parts += lines
            lines = self.branches.describe(v, self.feature_names)
            if lines:
                parts.append(f"{v}: branch choices")
                parts += lines
        ambient = self.coupling.ambient
        if ambient is not None and ambient.any():
            names = ", ".join(self.feature_names[j] for j in np.flatnonzero(ambient))
            parts.append(
                "ambient features (move alike under every MP, unbent by its switches; left out"
                f" of progress and every learned choice, not a stall's motion): {names}"
            )
        return "\n".join(parts)
