"""The concurrent sequencer: one sequence graph per control variable.

Transition rule (paper section III): at the start each graph activates the initial node with
the highest entry probability ``1 - φ`` (or, with ``start_rule="joint"``, the demonstrated
combination of initial nodes with the highest summed log entry probability). At every tick, for
each successor ``s`` of the current node ``c`` the transition probability is
``p_s = φ_c(x) · (1 - φ_s(x))``; a switching rule (:mod:`cpmp.switching`) decides when the best
successor fires. In the paper the graphs are coupled only through the shared features ``x``;
cpmp's defaults also hold back transitions whose context (the other variables' MPs) was never
demonstrated, and resolve stalls (:mod:`cpmp.switching`).

``ConcurrentSequencer.fit(demos)`` with no options gives cpmp's recommended configuration;
``ConcurrentSequencer.fit(demos, predictor="klr", **PAPER_OPTIONS)`` the paper's method.
``seq.batched(n)`` (:class:`BatchedSequencer`) runs ``n`` independent episodes of a fitted
sequencer with one predictor call per tick for all of them (many rollouts at once).
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import torch

from cpmp.config import FitConfig, SequencerConfig
from cpmp.errors import (
    ConfigError,
    CpmpError,
    CpmpFileError,
    DataError,
    NotFittedError,
    UnknownMPError,
)
from cpmp.graph import SequenceGraph, build_graphs
from cpmp.io import atomic_path, load_checkpoint, to_builtin
from cpmp.predictors import (
    PREDICTORS,
    START_PREFIX,
    NodeData,
    ProgressPredictor,
    predictor_from_spec,
)
from cpmp.progress import path_length, progress_labels
from cpmp.records import SequencerNote, TickInfo, TransitionEvent
from cpmp.switching import (
    Coupling,
    StallDetector,
    SwitchRule,
    indicator_features,
    make_rule,
    recovery_choice,
)
from cpmp.training import fit_predictor

if TYPE_CHECKING:
    from cpmp.data import Demonstration

log = logging.getLogger(__name__)

CHECKPOINT_FORMAT = "cpmp-sequencer"
CHECKPOINT_VERSION = 2

PAPER_OPTIONS: dict[str, Any] = {
    "feature_weighting": "none",
    "feature_scaling": "none",
    "path_noise": "none",
    "start_kernel": "shared",
    "start_rule": "independent",
    "switch_rule": "paper",
    "coupling": "none",
    "recovery": False,
}
"""Fit options that turn :meth:`ConcurrentSequencer.fit`'s defaults into the paper's method:
``ConcurrentSequencer.fit(demos, predictor="klr", **PAPER_OPTIONS)`` (the main job's
``predictor=klr sequencer=paper``)."""


_PlanRow = tuple[str, str, list[str], list[int], int, list[int], list[tuple[int, int, float]]]
"""One variable's row of :meth:`ConcurrentSequencer._transition_plan`."""


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
        fit_summary: dict[str, Any] | None = None,
        initial_combinations: Sequence[Mapping[str, str]] | None = None,
        coupling: Coupling | None = None,
        feature_range: np.ndarray | None = None,
    ) -> None:
        self.graphs = dict(graphs)
        self.predictor = predictor.eval()
        self.feature_names = list(feature_names)
        self.config = config or SequencerConfig()
        self.fit_summary = fit_summary or {}
        self.initial_combinations = [dict(c) for c in initial_combinations or []]
        """Initial MP per variable of each demonstration (distinct; for ``start_rule=joint``)."""
        if len(self.feature_names) != predictor.n_features:
            raise ConfigError(
                f"{len(self.feature_names)} feature names for a predictor of "
                f"{predictor.n_features} features"
            )
        keys = [(v, mp) for v in sorted(self.graphs) for mp in self.graphs[v].ordered_nodes()]
        extra = predictor.node_keys[len(keys) :]
        if predictor.node_keys[: len(keys)] != keys or extra not in ([], start_keys(self.graphs)):
            raise ConfigError("the predictor's nodes do not match the sequence graphs' nodes")
        self._keys = keys
        self._index = {key: i for i, key in enumerate(keys)}
        self._start_index = {
            (v, mp[len(START_PREFIX) :]): len(keys) + i for i, (v, mp) in enumerate(extra)
        } or self._index
        self._successor_idx = {
            (v, mp): (
                self.graphs[v].successors(mp),
                [self._index[(v, s)] for s in self.graphs[v].successors(mp)],
            )
            for v, mp in keys
        }
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
        self._coupled = self.config.coupling == "context"
        self._episode = SequencerEpisode(self)

    def _new_rule(self) -> SwitchRule:
        c = self.config
        return make_rule(c.switch_rule, c.threshold, c.patience, c.min_improvement)

    # ----------------------------------------------------------------------------- fitting
    @classmethod
    def fit(
        cls,
        demos: Sequence[Demonstration],
        predictor: str = "klr",
        **options: Any,
    ) -> ConcurrentSequencer:
        """Build the sequence graphs and fit every node's progress predictor: the keyword form
        of :meth:`fit_config`, ``fit_config(demos, FitConfig.from_options(predictor,
        **options))``.

        Args:
            demos: labelled demonstrations sharing feature names and control variables.
            predictor: ``klr`` (paper), ``klr_full``, ``klr_sparse``, ``mlp`` or a baseline.
            **options: predictor options (e.g. ``gamma``, ``support_scale``, ``min_support``,
                ``l2``, ``feature_scaling``: the fields of its options class), sequencer
                options (:class:`~cpmp.config.SequencerConfig`), trainer options
                (:class:`~cpmp.config.TrainerConfig`), ``seed``, ``variables`` and
                ``subsample`` (:class:`~cpmp.config.FitConfig`); an unknown name raises
                :class:`~cpmp.errors.ConfigError`.
        """
        return cls.fit_config(demos, FitConfig.from_options(predictor, **options))

    @classmethod
    def fit_config(
        cls, demos: Sequence[Demonstration], config: FitConfig | None = None
    ) -> ConcurrentSequencer:
        """Build the sequence graphs and fit every node's progress predictor as ``config``
        says (``None``: cpmp's defaults, the main job's ``predictor=klr_path
        sequencer=coupled``)."""
        config = config or FitConfig()
        predictor = config.predictor
        demos = list(demos)
        if not demos:
            raise DataError("ConcurrentSequencer.fit needs at least one demonstration, got none")
        feature_names = list(demos[0].feature_names)
        for m, demo in enumerate(demos):
            if list(demo.feature_names) != feature_names:
                raise DataError(
                    f"{demo.name or f'demonstration {m}'} has features {list(demo.feature_names)}"
                    f" but the first demonstration has {feature_names}; all must match"
                )
        graphs = build_graphs(demos, config.variables)
        node_keys = [(v, mp) for v in sorted(graphs) for mp in graphs[v].ordered_nodes()]
        if config.sequencer.start_kernel == "isotropic":
            node_keys += start_keys(graphs)
        model = PREDICTORS[predictor](node_keys, len(feature_names), config.predictor_config)
        all_x = np.concatenate([d.features for d in demos], axis=0)
        model.scaler.fit(all_x, model.config.feature_scaling)
        data = node_training_data(graphs, model, config.subsample)
        summary = fit_predictor(model, data, config.trainer, seed=config.seed)
        bad = nonfinite_parameters(model)
        if bad:
            raise DataError(
                f"the {predictor} fit produced non-finite parameters ({', '.join(bad)}); "
                "check the feature magnitudes and the options gamma / l2 / lr"
            )
        summary["n_demos"] = len(demos)
        summary["warnings"] = glitch_warnings(graphs, demos) + fit_warnings(model, data)
        for text in summary["warnings"]:
            log.warning("%s", text)
        combos: list[dict[str, str]] = []
        for demo in demos:
            combo = {v: str(demo.labels[v][0]) for v in sorted(graphs)}
            if combo not in combos:
                combos.append(combo)
        coupling = Coupling.learn(
            demos, sorted(graphs), model.scaler.transform, getattr(model, "labels", "path")
        )
        feature_range = np.where(indicator_features(all_x), 0.0, np.ptp(all_x, axis=0))
        return cls(
            graphs, model, feature_names, config.sequencer, summary, combos, coupling, feature_range
        )

    # ----------------------------------------------------------------------------- inference
    def progress(self, x: np.ndarray | torch.Tensor) -> np.ndarray:
        """φ of every node for features ``x (..., d)``: ``(..., K)`` in :attr:`node_keys` order."""
        return self._heads(x, len(self._keys))

    def _heads(self, x: np.ndarray | torch.Tensor, heads: int | None = None) -> np.ndarray:
        """All predictor heads ``(..., H)``: the nodes' φ, then the start heads (if any);
        ``heads`` keeps only the first ``heads`` columns (and skips evaluating the others)."""
        xn = checked_features(x, self.feature_names)
        with torch.no_grad():
            return self.predictor(torch.from_numpy(np.ascontiguousarray(xn)), heads).numpy()

    @property
    def node_keys(self) -> list[tuple[str, str]]:
        """(variable, MP) of every node, in the order of :meth:`progress`'s columns."""
        return list(self._keys)

    def predict_progress(self, x: np.ndarray) -> dict[str, dict[str, float]]:
        """φ of every node for one feature vector ``x (d,)``: variable -> MP -> φ."""
        state = np.asarray(x, dtype=np.float64).reshape(-1)
        return self._phi_dict(self.progress(state))

    def reset(self, t: float, x: np.ndarray) -> dict[str, str]:
        """Start every graph at its initial node of highest entry probability ``1 - φ`` (or the
        demonstrated combination of initial nodes with the highest summed log entry probability
        when ``start_rule="joint"``)."""
        t = checked_time(t)
        self.predictor.reset_state(1)
        phi = self._heads(np.asarray(x, dtype=np.float64).reshape(-1))
        return self._episode.start(t, x, phi)

    def step(self, t: float, x: np.ndarray) -> dict[str, str]:
        """Advance one tick at time ``t`` [s] with features ``x (d,)``; returns the active MPs."""
        t = self._episode.check_time(t)
        state = np.asarray(x, dtype=np.float64).reshape(-1)
        phi = self.progress(state)
        return self._episode.advance(t, state, phi.tolist(), bool(np.isfinite(phi).all()))

    def batched(self, n: int) -> BatchedSequencer:
        """``n`` independent episodes of this sequencer, stepped together (see
        :class:`BatchedSequencer`)."""
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

    def _initial_mps(self, phi: np.ndarray) -> dict[str, str]:
        """The start rule (see :meth:`reset`) on every head's φ ``(H,)``: variable -> MP."""
        if self.config.start_rule == "joint" and self.initial_combinations:
            entry = np.clip(1.0 - phi, 1e-12, 1.0)
            scores = [
                sum(np.log(entry[self._start_index[(v, mp)]]) for v, mp in combo.items())
                for combo in self.initial_combinations
            ]
            return dict(self.initial_combinations[int(np.argmax(scores))])
        active = {}
        for v in sorted(self.graphs):
            initial = sorted(self.graphs[v].initial_nodes)
            entry_v = [1.0 - phi[self._start_index[(v, mp)]] for mp in initial]
            active[v] = initial[int(np.argmax(entry_v))]
        return active

    def _transition_plan(self, context: Mapping[str, str]) -> list[_PlanRow]:
        """What every tick needs while the active MPs are ``context``: per variable with
        successors (sorted), ``(variable, current MP, successors, their φ columns, the current
        MP's φ column, unseen, checks)`` (:meth:`~cpmp.switching.Coupling.gates`): per
        successor the number of other variables running an MP never seen at that switch, and
        ``(successor, φ column, bound)`` for every φ that adds one inconsistency while below
        its bound."""
        margin = self.config.progress_margin
        plan = []
        for v in sorted(self.graphs):
            current = context[v]
            names, idx = self._successor_idx[(v, current)]
            if not names:
                continue
            unseen_counts, checks = [], []
            for k, s in enumerate(names):
                unseen, bounds = self.coupling.gates((v, current, s), context, margin)
                unseen_counts.append(len(unseen))
                checks += [
                    (k, self._index[(u, context[u])], bound)
                    for u, _, bound in bounds
                    if u in context
                ]
            plan.append((v, current, names, idx, self._index[(v, current)], unseen_counts, checks))
        return plan

    def _phi_dict(self, phi: np.ndarray | list[float]) -> dict[str, dict[str, float]]:
        """Per-node φ ``(K,)`` as variable -> MP -> φ (start heads left out)."""
        out: dict[str, dict[str, float]] = {v: {} for v in sorted(self.graphs)}
        values = phi.tolist() if isinstance(phi, np.ndarray) else phi
        for (v, mp), value in zip(self._keys, values[: len(self._keys)], strict=True):
            out[v][mp] = value
        return out

    def replay(
        self, time: np.ndarray, features: np.ndarray
    ) -> tuple[dict[str, list[str]], list[TransitionEvent]]:
        """Run the sequencer open-loop over a recorded feature stream ``(n,), (n, d)``.

        Returns the MP sequence per variable and the transition events.
        """
        seqs = {v: [mp] for v, mp in self.reset(time[0], features[0]).items()}
        for t, x in zip(time[1:], features[1:], strict=True):
            before = dict(self.active)
            after = self.step(t, x)
            for v, mp in after.items():
                if mp != before[v]:
                    seqs[v].append(mp)
        return seqs, list(self.events)

    # ----------------------------------------------------------------------------- persistence
    def save(self, path: str | Path) -> Path:
        """Write a checkpoint (graphs, predictor weights, configs) atomically to ``path``."""
        payload = {
            "format": CHECKPOINT_FORMAT,
            "version": CHECKPOINT_VERSION,
            "feature_names": self.feature_names,
            "graphs": {v: g.to_dict() for v, g in self.graphs.items()},
            "predictor": {"spec": self.predictor.spec(), "state": self.predictor.state_dict()},
            "sequencer": dataclasses.asdict(self.config),
            "fit_summary": to_builtin(self.fit_summary),
            "initial_combinations": self.initial_combinations,
            "coupling": self.coupling.to_dict(),
            "feature_range": self.feature_range.tolist(),
        }
        path = Path(path)
        with atomic_path(path) as tmp:
            torch.save(payload, tmp)
        return path

    @classmethod
    def load(cls, path: str | Path) -> ConcurrentSequencer:
        """Load a checkpoint written by :meth:`save`."""
        payload = load_checkpoint(
            path,
            CHECKPOINT_FORMAT,
            label="cpmp",
            kind="cpmp sequencer",
            remedy="retrain the model with scripts/train.py, or load only files you wrote with "
            "ConcurrentSequencer.save",
        )
        version = payload.get("version")
        if version not in (1, CHECKPOINT_VERSION):
            raise CpmpFileError(
                f"{path} has checkpoint version {version}; this cpmp reads versions 1 and "
                f"{CHECKPOINT_VERSION}"
            )
        try:
            return cls._from_payload(payload, version)
        except (CpmpError, KeyError, TypeError, ValueError, RuntimeError, AttributeError) as err:
            raise CpmpFileError(
                f"{path} is a damaged or incompatible cpmp checkpoint "
                f"({type(err).__name__}: {err}); retrain it with scripts/train.py"
            ) from err

    @classmethod
    def _from_payload(cls, payload: dict[str, Any], version: int) -> ConcurrentSequencer:
        """Rebuild from a checkpoint payload, checking it against its own spec."""
        known = {"format", "version", "sequencer", "graphs", "predictor", "feature_names"}
        missing = sorted(known - set(payload))
        if missing:
            raise KeyError(f"missing entries {missing}")
        options = dict(payload["sequencer"])
        unknown = sorted(set(options) - {f.name for f in dataclasses.fields(SequencerConfig)})
        if unknown:
            raise ValueError(f"unknown sequencer options {unknown}")
        if version == 1:
            # Written before the switching rules, coupling and recovery existed: keep its
            # behaviour (the plateau rule, graphs coupled through the features only).
            options.update(switch_rule="plateau", coupling="none", recovery=False)
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
        return cls(
            graphs,
            predictor,
            payload["feature_names"],
            SequencerConfig(**options),
            payload.get("fit_summary", {}),
            payload.get("initial_combinations", []),
            Coupling.from_dict(payload.get("coupling", [])),
            feature_range,
        )

    def with_config(self, **options: Any) -> ConcurrentSequencer:
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
        )

    def describe(self) -> str:
        """All graphs as text, each followed by its learned switch contexts (the coupling)."""
        parts = []
        for v in sorted(self.graphs):
            parts.append(self.graphs[v].to_text())
            lines = self.coupling.describe(v)
            if lines:
                used = "" if self.config.coupling == "context" else " (not used: coupling=none)"
                parts.append(f"{v}: switch contexts{used}")
                parts += lines
        return "\n".join(parts)

    def check_variable(self, variable: str) -> SequenceGraph:
        if variable not in self.graphs:
            raise UnknownMPError(
                f"unknown control variable {variable!r}; known: {', '.join(sorted(self.graphs))}"
            )
        return self.graphs[variable]


class SequencerEpisode:
    """The state of one episode of a :class:`ConcurrentSequencer`: the active MPs, the events,
    the notes, the switching rules' histories and the stall detector.

    :class:`ConcurrentSequencer` drives one, :class:`BatchedSequencer` many; both evaluate the
    predictor themselves and hand each episode its φ, so one episode decides the same way in
    either.
    """

    def __init__(self, seq: ConcurrentSequencer) -> None:
        self.seq = seq
        self.active: dict[str, str] = {}
        """Variable -> active MP (empty before :meth:`start`)."""
        self.events: list[TransitionEvent] = []
        self.notes: list[SequencerNote] = []
        self._rules = {v: seq._new_rule() for v in seq.graphs}
        c = seq.config
        self._stall = StallDetector(seq.feature_range, c.stall_time, c.rest_speed)
        self._holding: dict[str, str | None] = {}
        self._last_t: float | None = None
        self._plan: tuple[dict[str, str], list[_PlanRow]] | None = None
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
            self._tick = TickInfo(t, seq._phi_dict(phi), probs, active, held)
            self._pending = None
        return self._tick

    def start(self, t: float, x: np.ndarray, phi: np.ndarray) -> dict[str, str]:
        """Begin the episode at time ``t`` [s] with features ``x (d,)`` and every head's φ
        ``(H,)``; returns the initial MPs."""
        if not np.isfinite(phi).all():
            raise DataError(
                "the progress predictor gave a non-finite φ at reset; the model is broken "
                "(check its parameters) or the features are far outside the training data"
            )
        seq = self.seq
        self.active = seq._initial_mps(phi)
        self.events = []
        self.notes = []
        for rule in self._rules.values():
            rule.reset()
        self._holding = {v: None for v in seq.graphs}
        self._stall.reset(t, np.asarray(x, dtype=np.float64).reshape(-1))
        self._last_t = t
        self._plan = None
        self._pending = None
        self._tick = TickInfo(t, seq._phi_dict(phi), {v: {} for v in seq.graphs}, dict(self.active))
        return dict(self.active)

    def check_time(self, t: float) -> float:
        """``t`` [s] as a float; raises unless the episode was started and ``t`` is finite and
        does not go back in time."""
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
        and whether all of them are finite. Returns the active MPs after the tick."""
        seq = self.seq
        c = seq.config
        self._last_t = t
        if not finite:
            bad = [
                f"{v}/{mp}"
                for (v, mp), f in zip(seq._keys, phi, strict=True)
                if not math.isfinite(f)
            ]
            text = f"non-finite φ for {', '.join(bad[:5])}; every MP kept"
            if c.nonfinite == "raise":
                raise DataError(f"at t={t}: {text} (sequencer option nonfinite='raise')")
            if not self.notes or self.notes[-1].kind != "nonfinite":
                self.notes.append(SequencerNote(t, "nonfinite", "", text))
            self._tick = TickInfo(t, seq._phi_dict(phi), {}, dict(self.active))
            self._pending = None
            return dict(self.active)
        self._stall.observe(t, state)
        if self._plan is None:
            context = dict(self.active)
            self._plan = (context, seq._transition_plan(context))
        context, plan = self._plan
        coupled = seq._coupled
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
        done = {u: phi[seq._index[(u, mp)]] for u, mp in context.items()}
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


class EpisodeBatch:
    """What every batched policy shares: ``episodes``, one object per episode with its
    ``active`` MPs, ``events`` and ``notes``, and per-episode views of them."""

    episodes: list[Any]

    @property
    def n_episodes(self) -> int:
        """N, the number of episodes."""
        return len(self.episodes)

    def __len__(self) -> int:
        return len(self.episodes)

    @property
    def active(self) -> list[dict[str, str]]:
        """Per episode, variable -> active MP (empty before its first reset)."""
        return [dict(ep.active) for ep in self.episodes]

    @property
    def events(self) -> list[list[TransitionEvent]]:
        """Per episode, its transitions."""
        return [ep.events for ep in self.episodes]

    @property
    def notes(self) -> list[list[SequencerNote]]:
        """Per episode, its notes."""
        return [ep.notes for ep in self.episodes]


class BatchedSequencer(EpisodeBatch):
    """``n`` independent episodes of one fitted :class:`ConcurrentSequencer`, stepped together.

    Every tick evaluates all nodes' predictors in one call over the features ``(N, d)`` of the
    live episodes; each episode then decides exactly as a :class:`ConcurrentSequencer` of its
    own would (same events, notes and tick information; φ may differ in the last bits, ~1e-14,
    where the predictor rounds a batch of rows differently). Build one with
    ``seq.batched(n)`` or ``BatchedSequencer(seq, n)``::

        batch = seq.batched(len(x0))
        active = batch.reset(0.0, x0)  # x0 (N, d) -> one dict variable -> MP per episode
        active = batch.step(0.01, x1, live=running)  # running: (N,) bool, others skipped
        batch.episodes[i].events, batch.episodes[i].notes, batch.episodes[i].last_tick

    ``live`` (optional, ``(N,)`` bool) leaves the other episodes untouched (finished
    rollouts). A stateful predictor (``predictor.stateful``, e.g. ``dtw``) runs one stream
    per episode: :meth:`reset` restarts all ``N`` streams and every call evaluates all
    ``N`` rows (so every row must hold finite features), whatever ``live`` says.
    """

    def __init__(self, seq: ConcurrentSequencer, n: int) -> None:
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
            raise ConfigError(f"a batched sequencer needs n >= 1 episodes, got {n!r}")
        self.sequencer = seq
        self.episodes = [SequencerEpisode(seq) for _ in range(int(n))]
        """One :class:`SequencerEpisode` per episode (``active``, ``events``, ``notes``,
        ``last_tick``)."""

    def reset(
        self,
        t: float | np.ndarray,
        x: np.ndarray | torch.Tensor,
        live: np.ndarray | Sequence[bool] | None = None,
    ) -> list[dict[str, str]]:
        """Start the ``live`` episodes (default: all) at time ``t`` [s] (scalar or ``(N,)``)
        with features ``x (N, d)``; returns every episode's active MPs."""
        seq = self.sequencer
        ts, xn, rows = self._inputs(t, x, live)
        stateful = getattr(seq.predictor, "stateful", False)
        if stateful:
            seq.predictor.reset_state(len(self.episodes))
        if rows:
            phi = seq._heads(xn if stateful else xn[rows])
            for j, i in enumerate(rows):
                self.episodes[i].start(ts[i], xn[i], phi[i if stateful else j])
        return self.active

    def step(
        self,
        t: float | np.ndarray,
        x: np.ndarray | torch.Tensor,
        live: np.ndarray | Sequence[bool] | None = None,
    ) -> list[dict[str, str]]:
        """Advance the ``live`` episodes (default: all) one tick at time ``t`` [s] (scalar or
        ``(N,)``) with features ``x (N, d)``; returns every episode's active MPs."""
        seq = self.sequencer
        ts, xn, rows = self._inputs(t, x, live)
        for i in rows:
            try:
                self.episodes[i].check_time(ts[i])
            except CpmpError as err:
                raise type(err)(f"episode {i}: {err}") from err
        if not rows:
            return self.active
        stateful = getattr(seq.predictor, "stateful", False)
        phi = seq.progress(xn if stateful else xn[rows])
        if stateful:
            phi = phi[rows]
        finite = np.isfinite(phi).all(axis=1).tolist()
        for i, row, ok in zip(rows, phi.tolist(), finite, strict=True):
            try:
                self.episodes[i].advance(ts[i], xn[i], row, ok)
            except CpmpError as err:
                raise type(err)(f"episode {i}: {err}") from err
        return self.active

    def _inputs(
        self,
        t: float | np.ndarray,
        x: np.ndarray | torch.Tensor,
        live: np.ndarray | Sequence[bool] | None,
    ) -> tuple[list[float], np.ndarray, list[int]]:
        """Checked times ``(N,)`` as floats, features ``(N, d)`` float64 and live rows."""
        n, d = len(self.episodes), len(self.sequencer.feature_names)
        if isinstance(x, torch.Tensor):
            x = x.detach().cpu().numpy()
        xn = np.asarray(x, dtype=np.float64)
        if xn.shape != (n, d):
            raise DataError(
                f"a batch of {n} episodes needs features of shape ({n}, {d}), got {tuple(xn.shape)}"
            )
        try:
            times = np.broadcast_to(np.asarray(t, dtype=np.float64), (n,))
        except ValueError as err:
            raise DataError(f"t must be one time or {n} times, got shape {np.shape(t)}") from err
        if not np.isfinite(times).all():
            raise DataError(f"time must be finite, got t={t}")
        if live is None:
            rows = list(range(n))
        else:
            mask = np.asarray(live)
            if mask.shape != (n,) or mask.dtype != np.bool_:
                raise DataError(
                    f"live must be a boolean mask of shape ({n},), got {mask.dtype} of shape "
                    f"{mask.shape}"
                )
            rows = np.flatnonzero(mask).tolist()
        return times.tolist(), xn, rows


def checked_time(t: float) -> float:
    """``t`` [s] as a float; :class:`~cpmp.errors.DataError` unless it is finite."""
    t = float(t)
    if not math.isfinite(t):
        raise DataError(f"time must be finite, got t={t}")
    return t


def checked_features(x: np.ndarray | torch.Tensor, feature_names: Sequence[str]) -> np.ndarray:
    """Features ``x (..., d)`` as a float64 array, checked against ``feature_names`` (d of them)
    and for finiteness; :class:`~cpmp.errors.DataError` says what is wrong."""
    if isinstance(x, torch.Tensor):
        x = x.detach().cpu().numpy()
    xn = np.asarray(x, dtype=np.float64)
    if xn.ndim == 0 or xn.shape[-1] != len(feature_names):
        raise DataError(
            f"expected features with {len(feature_names)} entries "
            f"({', '.join(list(feature_names)[:4])}, ...), got shape {tuple(xn.shape)}"
        )
    if not np.isfinite(xn).all():
        raise DataError("features contain NaN or inf; the sequencer needs finite features")
    return xn


def start_keys(graphs: Mapping[str, SequenceGraph]) -> list[tuple[str, str]]:
    """Keys of the start heads: ``(variable, START_PREFIX + mp)`` per initial node."""
    return [
        (v, START_PREFIX + mp) for v in sorted(graphs) for mp in sorted(graphs[v].initial_nodes)
    ]


def node_training_data(
    graphs: Mapping[str, SequenceGraph], predictor: ProgressPredictor, subsample: int = 1
) -> list[NodeData]:
    """Per-node training samples (scaled features) and progress targets (eq. 1, or normalised
    time for a predictor with ``labels = "time"``), in the predictor's node order;
    ``subsample`` keeps every k-th sample (and the last) for the loss."""
    out = []
    for v, key_mp in predictor.node_keys:
        mp = key_mp.removeprefix(START_PREFIX)
        acts = graphs[v].activations[mp]
        if not acts:
            raise DataError(f"node {v}/{mp} has no activation data to train on")
        scaled = [predictor.scaler.transform(a.features) for a in acts]
        labels = predictor.labels
        targets = [progress_labels(f, a.time, labels) for f, a in zip(scaled, acts, strict=True)]
        keep = [_stride(len(f), subsample) for f in scaled]
        x = np.concatenate([f[k] for f, k in zip(scaled, keep, strict=True)])
        y = np.concatenate([y[k] for y, k in zip(targets, keep, strict=True)])
        dt = predictor.dtype_
        out.append(
            NodeData(
                key=(v, key_mp),
                x=torch.as_tensor(x, dtype=dt),
                target=torch.as_tensor(y, dtype=dt),
                activations=scaled,
            )
        )
    return out


def nonfinite_parameters(module: torch.nn.Module) -> list[str]:
    """Names of the floating-point parameters and buffers of ``module`` holding NaN or inf."""
    return [
        name
        for name, value in module.state_dict().items()
        if value.is_floating_point() and not torch.isfinite(value).all()
    ]


DEGENERATE_PATH = 1e-9
"""Total L1 path length (scaled features) below which a node's activations count as still."""
UNSEPARATED_MAE = 0.2
"""Mean absolute progress error on a node's own training data above which it is reported."""


GLITCH_SAMPLES = 2
"""Activations of at most this many samples between two other MPs are reported as likely
label glitches."""


def glitch_warnings(
    graphs: Mapping[str, SequenceGraph], demos: Sequence[Demonstration]
) -> list[str]:
    """One message per node with an activation of at most :data:`GLITCH_SAMPLES` samples in
    the middle of a demonstration (A...A, B, C...C): such a node can hardly ever be entered in
    closed loop, and the sequencer would wait there."""
    out = []
    for v in sorted(graphs):
        for mp, acts in sorted(graphs[v].activations.items()):
            short = [
                a
                for a in acts
                if a.stop - a.start <= GLITCH_SAMPLES
                and a.start > 0
                and a.stop < demos[a.demo].n_samples
            ]
            if short:
                a = short[0]
                name = demos[a.demo].name or f"demonstration {a.demo}"
                out.append(
                    f"node {v}/{mp}: its activation in {name} lasts {a.stop - a.start} "
                    f"sample(s) (from sample {a.start}); if that is a label glitch, relabel it, "
                    "or the sequencer may wait in this MP"
                )
    return out


def fit_warnings(predictor: ProgressPredictor, data: Sequence[NodeData]) -> list[str]:
    """Degenerate nodes, one message each: activations without feature change (their progress
    falls back to normalised time, which the features cannot show) and nodes whose fitted φ
    misses their own targets by more than :data:`UNSEPARATED_MAE` on average."""
    out = []
    with torch.no_grad():
        for i, node in enumerate(data):
            v, mp = node.key
            if mp.startswith(START_PREFIX):
                continue  # the same activations as the node itself
            name = f"node {v}/{mp}"
            length = sum(path_length(a) for a in node.activations)
            if length < DEGENERATE_PATH:
                out.append(
                    f"{name}: the features do not change during its activations, so its "
                    "progress cannot be predicted from them; add a feature that moves while "
                    "this MP runs"
                )
                continue
            logit = predictor.node_logits(node.x, i)
            mae = float((torch.sigmoid(logit) - node.target).abs().mean())
            if mae > UNSEPARATED_MAE:
                out.append(
                    f"{name}: the predictor cannot fit its progress (training MAE {mae:.2f}); "
                    "its activations may look alike at start and end in these features"
                )
    return out


def _stride(n: int, k: int) -> np.ndarray:
    """Indices ``0, k, 2k, ...`` of ``n`` samples, always including the last one."""
    idx = np.arange(0, n, k)
    return idx if idx[-1] == n - 1 else np.append(idx, n - 1)
