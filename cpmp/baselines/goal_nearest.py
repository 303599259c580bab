"""A sequencing baseline without learned progress: wait until done, then pick the nearest.

Wait until the active MP has converged, then take the successor whose demonstrated entry states
are nearest (``sequencer=goal_nearest``).

It shows what learned progress adds over "wait until done, then pick the closest":

* **convergence**: a variable's active MP has converged when every feature that moves while
  that MP runs (learned from the labels: a feature whose L1 path over the MP's training
  activations is at least ``motion_share`` of the largest feature's path; binary features such
  as touch signals never count) has moved slower than ``speed_threshold`` for ``hold_time``
  seconds. Features are measured in the scaled feature space (``feature_scaling``, as the
  progress predictors scale them), so the threshold is in scaled units per second; with
  ``global`` scaling and the simulator's features (largest range 1) that is about m/s.
* **successor**: among the successors of the active MP in the sequence graph, the one with a
  training entry state (the first sample of an activation that followed the active MP) nearest
  to the current features, Euclidean in the scaled space. If some demonstration *ended* in the
  active MP, staying competes too, with the last samples of those activations as its states
  (without it the unused hand's ``relax``, which other strategies follow by ``preshape``,
  could never stay relaxed); while staying is nearest the variable keeps its MP and decides
  again at the next converged tick. A terminal MP stays active.
* **start**: per variable the initial MP with the nearest training entry state (the first
  sample of a demonstration starting with it). Every demonstration's first sample is an entry
  state of its initial MP of every variable, so all variables start as the nearest
  demonstration did.

It has no progress predictor; for offline evaluation :meth:`GoalNearestSequencer.progress`
gives the nearest-neighbour estimate (:class:`~cpmp.baselines.NearestProgress`): the
expected progress (eq. 1) of the nearest training sample of each node. The switching rule never
uses it. Its options are :class:`~cpmp.config.GoalNearestConfig`.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from time import perf_counter

import numpy as np
import torch

from cpmp.baselines.episodic import EpisodicBaseline, baseline_data
from cpmp.baselines.nearest_progress import NearestProgress
from cpmp.config.goal_nearest import KIND, GoalNearestConfig, goal_nearest_options
from cpmp.config.validation import OptionValue
from cpmp.data import Demonstration
from cpmp.errors import ConfigError, DataError, NotFittedError
from cpmp.graph import SequenceGraph
from cpmp.io import CheckpointPayload, CheckpointSpec, load_checkpoint, save_checkpoint
from cpmp.records import BaselineFitReport, SequencerNote, TickInfo, TransitionEvent
from cpmp.sequencer import (
    checked_features,
    checked_time,
    indicator_features,
)

CHECKPOINT_FORMAT = "cpmp-goal-nearest"
CHECKPOINT_VERSION = 1
CHECKPOINT = CheckpointSpec(
    CHECKPOINT_FORMAT,
    (CHECKPOINT_VERSION,),
    "goal_nearest",
    "load a file written by "
    "GoalNearestSequencer.save, or fit it again with GoalNearestSequencer.fit",
)
"""The goal_nearest checkpoint kind."""

_EPS_T = 1e-9
"""Slack [s] when comparing tick times (ticks are sums of floating-point periods)."""


class GoalNearestSequencer(EpisodicBaseline):
    """The goal-nearest baseline (see the module doc).

    Build with :meth:`fit` or :meth:`load`; drive with :meth:`reset` then :meth:`step` once per
    control tick, like :class:`~cpmp.sequencer.ConcurrentSequencer`.

    Attributes:
        graphs: variable -> sequence graph (structure only after :meth:`load`).
        feature_names: the ``d`` feature names.
        config: the options.
        predictor: the nearest-neighbour progress estimate (offline evaluation only).
        motion: variable -> MP -> ``(d,)`` bool, the features that move while the MP runs.
        entries: ``(variable, source, target)`` -> ``(n, d)`` scaled entry states of the
            target after the source (``source`` is ``None`` for initial entry states).
        finals: ``(variable, MP)`` -> ``(n, d)`` scaled last states of the activations that
            ended a demonstration (the states of staying).
        active, events, notes, last_tick: the current episode (as the learned sequencer's).
    """

    kind = KIND

    def __init__(
        self,
        graphs: Mapping[str, SequenceGraph],
        feature_names: Sequence[str],
        config: GoalNearestConfig,
        predictor: NearestProgress,
        motion: Mapping[str, Mapping[str, np.ndarray]],
        entries: Mapping[tuple[str, str | None, str], np.ndarray],
        finals: Mapping[tuple[str, str], np.ndarray],
        fit_summary: BaselineFitReport | None = None,
    ) -> None:
        self.graphs = dict(graphs)
        self.feature_names = list(feature_names)
        self.config = config
        self.predictor = predictor
        self.motion = {
            v: {mp: np.asarray(m, dtype=bool) for mp, m in d.items()} for v, d in motion.items()
        }
        self.entries = {k: np.asarray(e, dtype=np.float64) for k, e in entries.items()}
        self.finals = {k: np.asarray(e, dtype=np.float64) for k, e in finals.items()}
        self.fit_summary = fit_summary
        d = len(self.feature_names)
        for v, g in self.graphs.items():
            for mp in g.nodes:
                if self.motion.get(v, {}).get(mp, np.zeros(0)).shape != (d,):
                    raise ConfigError(f"goal_nearest: no motion mask of {d} features for {v}/{mp}")
        for v, g in self.graphs.items():
            for source, target in g.edges:
                if (v, source, target) not in self.entries:
                    raise ConfigError(
                        f"goal_nearest: no entry states for {v}: {source} -> {target}"
                    )
            for mp in g.initial_nodes:
                if (v, None, mp) not in self.entries:
                    raise ConfigError(f"goal_nearest: no initial entry states for {v}/{mp}")
        self._motion_idx = {
            (v, mp): np.flatnonzero(m)
            for v, masks in self.motion.items()
            for mp, m in masks.items()
        }
        self._new_episode()

    def _new_episode(self) -> None:
        """Forget the current episode (a fresh state; the fitted data stays shared)."""
        self.active: dict[str, str] = {}
        self.events: list[TransitionEvent] = []
        self.notes: list[SequencerNote] = []
        self.last_tick: TickInfo | None = None
        self._still_since: dict[str, float | None] = {}
        self._z: np.ndarray | None = None
        self._last_t: float | None = None

    # ----------------------------------------------------------------------------- fitting
    @classmethod
    def fit(
        cls,
        demos: Sequence[Demonstration],
        *,
        seed: int = 0,
        variables: Sequence[str] | None = None,
        **options: OptionValue,
    ) -> GoalNearestSequencer:
        """Build the graphs; collect each node's moving features and entry states.

        Args:
            demos: labelled demonstrations sharing feature names and control variables.
            seed: accepted for a uniform interface (the fit is deterministic and draws
                nothing).
            variables: the control variables to sequence (``None``: all).
            **options: :class:`~cpmp.config.GoalNearestConfig` fields.

        Returns:
            The fitted baseline.
        """
        started = perf_counter()
        config = goal_nearest_options(options)
        data = baseline_data(demos, variables, config.feature_scaling, "GoalNearestSequencer.fit")
        demos, feature_names, graphs, predictor = (
            data.demos,
            data.feature_names,
            data.graphs,
            data.predictor,
        )
        binary = indicator_features(data.features)
        motion: dict[str, dict[str, np.ndarray]] = {v: {} for v in graphs}
        entries: dict[tuple[str, str | None, str], list[np.ndarray]] = {}
        finals: dict[tuple[str, str], list[np.ndarray]] = {}
        for v, mp in data.node_keys:
            path = np.zeros(len(feature_names))
            for a, z in zip(graphs[v].activations[mp], data.scaled[(v, mp)], strict=True):
                path += np.abs(np.diff(z, axis=0)).sum(axis=0)
                source = None if a.start == 0 else str(demos[a.demo].labels[v][a.start - 1])
                entries.setdefault((v, source, mp), []).append(z[0])
                if a.stop == demos[a.demo].n_samples:
                    finals.setdefault((v, mp), []).append(z[-1])
            path[binary] = 0.0
            top = float(path.max(initial=0.0))
            motion[v][mp] = (path >= config.motion_share * top) & (path > 0.0)
        summary = BaselineFitReport(
            kind=KIND,
            n_demos=len(demos),
            n_support_total=None,
            seconds=perf_counter() - started,
        )
        return cls(
            graphs,
            feature_names,
            config,
            predictor,
            motion,
            {k: np.stack(e) for k, e in entries.items()},
            {k: np.stack(e) for k, e in finals.items()},
            summary,
        )

    # ----------------------------------------------------------------------------- inference
    def _features(self, x: np.ndarray | torch.Tensor) -> np.ndarray:
        """``x`` as checked float64 features ``(..., d)``."""
        return checked_features(x, self.feature_names)

    @staticmethod
    def _nearest(z: np.ndarray, candidates: Sequence[np.ndarray]) -> int:
        """Index of the candidate state set ``(n, d)`` with a state nearest to ``z (d,)``.

        The first one on ties.
        """
        best = [float(np.min(np.linalg.norm(c - z, axis=1))) for c in candidates]
        return int(np.argmin(best))

    def reset(self, t: float, x: np.ndarray) -> dict[str, str]:
        """Start each variable at its initial MP with the nearest entry state."""
        t = checked_time(t)
        z = self.predictor.scaler.transform(self._features(x).reshape(-1))
        self.active = {}
        for v in sorted(self.graphs):
            initial = sorted(self.graphs[v].initial_nodes)
            states = [self.entries[(v, None, mp)] for mp in initial]
            self.active[v] = initial[self._nearest(z, states)]
        self.events = []
        self.notes = []
        self._still_since = {v: None for v in self.graphs}
        self._z = z
        self._last_t = t
        self.last_tick = TickInfo(t, {}, {v: {} for v in self.graphs}, dict(self.active))
        return dict(self.active)

    def step(self, t: float, x: np.ndarray) -> dict[str, str]:
        """Advance one tick at time ``t`` [s] with features ``x (d,)``; returns the active MPs."""
        if not self.active or self._z is None or self._last_t is None:
            raise NotFittedError("call reset(t, x) before step(t, x)")
        t = checked_time(t)
        if t < self._last_t:
            raise DataError(f"time went backwards: step at t={t} after t={self._last_t}")
        state = self._features(x).reshape(-1)
        z = self.predictor.scaler.transform(state)
        dt = t - self._last_t
        if dt > 0:
            speed = np.abs(z - self._z) / dt
            c = self.config
            for v in sorted(self.graphs):
                current = self.active[v]
                idx = self._motion_idx[(v, current)]
                if idx.size and float(speed[idx].max()) >= c.speed_threshold:
                    self._still_since[v] = None
                    continue
                since = self._still_since[v]
                if since is None:
                    self._still_since[v] = since = self._last_t
                successors = self.graphs[v].successors(current)
                if not successors or t - since < c.hold_time - _EPS_T:
                    continue
                states = [self.entries[(v, current, s)] for s in successors]
                if (v, current) in self.finals:
                    states.append(self.finals[(v, current)])
                k = self._nearest(z, states)
                if k == len(successors):
                    continue  # staying is nearest: decide again at the next tick
                target = successors[k]
                self.events.append(
                    TransitionEvent(t, v, current, target, math.nan, state.copy(), "switch")
                )
                self.active[v] = target
                self._still_since[v] = None
            self._z = z
            self._last_t = t
        self.last_tick = TickInfo(t, {}, {v: {} for v in self.graphs}, dict(self.active))
        return dict(self.active)

    def describe(self) -> str:
        """The graphs as text, each node followed by the features it waits on."""
        c = self.config
        parts = [
            f"goal_nearest: switch after every moving feature stayed below "
            f"{c.speed_threshold:g} scaled units/s for {c.hold_time:g} s; successor by the "
            f"nearest entry state ({c.feature_scaling} scaling)"
        ]
        for v in sorted(self.graphs):
            parts.append(self.graphs[v].to_text())
            for mp in self.graphs[v].ordered_nodes():
                names = [self.feature_names[i] for i in self._motion_idx[(v, mp)]]
                parts.append(f"  {mp} waits on: {', '.join(names) or '(nothing moves)'}")
        return "\n".join(parts)

    # ----------------------------------------------------------------------------- persistence
    def save(self, path: str | Path) -> Path:
        """Write a checkpoint atomically to ``path`` (read it with :meth:`load`)."""
        return save_checkpoint(
            path,
            {
                "format": CHECKPOINT_FORMAT,
                "version": CHECKPOINT_VERSION,
                "config": dataclasses.asdict(self.config),
                "feature_names": self.feature_names,
                "graphs": {v: g.to_dict() for v, g in self.graphs.items()},
                "node_keys": [list(k) for k in self.predictor.node_keys],
                "predictor": self.predictor.state_dict(),
                "motion": {
                    v: {mp: torch.from_numpy(m) for mp, m in masks.items()}
                    for v, masks in self.motion.items()
                },
                "entries": [
                    {"variable": v, "source": s, "target": t, "states": torch.from_numpy(e)}
                    for (v, s, t), e in sorted(self.entries.items(), key=lambda kv: str(kv[0]))
                ],
                "finals": [
                    {"variable": v, "mp": mp, "states": torch.from_numpy(e)}
                    for (v, mp), e in sorted(self.finals.items())
                ],
                "fit_summary": (
                    {}
                    if self.fit_summary is None
                    else {k: v for k, v in self.fit_summary.to_dict().items() if k != "warnings"}
                ),
            },
        )

    @classmethod
    def load(cls, path: str | Path) -> GoalNearestSequencer:
        """Load a checkpoint written by :meth:`save`."""
        return load_checkpoint(path, CHECKPOINT, cls._from_payload)

    @classmethod
    def _from_payload(cls, payload: CheckpointPayload, version: int) -> GoalNearestSequencer:
        """Rebuild from a checkpoint payload (of :data:`CHECKPOINT_VERSION`)."""
        graphs = {v: SequenceGraph.from_dict(g) for v, g in payload["graphs"].items()}
        state = payload["predictor"]
        predictor = NearestProgress(
            [tuple(k) for k in payload["node_keys"]],
            len(payload["feature_names"]),
            int(state["samples"].shape[0]),
        )
        predictor.load_state_dict(state)
        entries = {
            (r["variable"], r["source"], r["target"]): r["states"].numpy()
            for r in payload["entries"]
        }
        finals = {(r["variable"], r["mp"]): r["states"].numpy() for r in payload["finals"]}
        motion = {
            v: {mp: m.numpy() for mp, m in masks.items()} for v, masks in payload["motion"].items()
        }
        summary = payload.get("fit_summary") or {}
        return cls(
            graphs,
            payload["feature_names"],
            goal_nearest_options(payload["config"]),
            predictor,
            motion,
            entries,
            finals,
            BaselineFitReport.from_dict(summary) if summary else None,
        )
