"""Benchmarks of fitting, the sequencer, the simulated closed loop and the main job
(``scripts/bench.py``; ``scripts/bench_sequencer.py`` uses :func:`bench_sequencer`).

Every function returns a JSON-ready dict of measurements; nothing here asserts a speed.
:func:`run_bench` runs the sections picked in :class:`BenchSettings` and writes
``bench.json``, ``bench.md`` and ``bench_scaling.png`` atomically.

Sections:

* ``fit``: the convex ``klr`` fit (cpmp's defaults) on the full experiment's training
  demonstrations against scikit-learn's ``LogisticRegression(solver="newton-cholesky")`` on
  the same kernel features (:func:`sklearn_peer`): times, ratio, both losses.
* ``sequencer``: cost per episode-tick of :meth:`ConcurrentSequencer.step` one episode at a
  time and of :class:`BatchedSequencer` over ``batch`` episodes.
* ``realtime``: real-time factor of closed-loop episodes, one at a time and batched.
* ``stages``: the main job (``scripts/experiment.py``) in a fresh process, its wall time and
  the time of every stage (its ``timings.json``).
* ``scaling``: fit time and tick cost as demonstrations and features grow (synthetic relay
  task, features padded with constant columns), with a log-log plot.
* ``gradient``: the Adam-trained predictors (``mlp``, ``klr_sparse``) on small data: fit
  time and epochs run.
"""

from __future__ import annotations

import logging
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from cpmp.errors import ConfigError, CpmpFileError

if TYPE_CHECKING:
    from cpmp.data import Demonstration
    from cpmp.sequencer import ConcurrentSequencer

log = logging.getLogger(__name__)

ROOT = Path(__file__).resolve().parents[2]
"""The repository (``scripts/experiment.py`` for the ``stages`` section)."""

SECTIONS = ("fit", "sequencer", "realtime", "stages", "scaling", "gradient")
"""The benchmark's sections, in the order they run."""

TICK_TARGET_MS = 0.1
"""Issue #9's target for the sequencer: <= 0.1 ms per episode-tick with 20 episodes batched."""


def bench_sequencer(
    demos: Sequence[Any],
    predictors: Sequence[str],
    n_ticks: int = 500,
    seed: int = 0,
    options: Mapping[str, Mapping[str, Any]] | None = None,
) -> dict[str, Any]:
    """Fit each predictor on ``demos`` and time :meth:`ConcurrentSequencer.step` over the first
    demo's feature stream (``n_ticks`` ticks, cycling).

    ``options``: per predictor kind, extra :meth:`ConcurrentSequencer.fit` options.

    Returns per predictor: fit time [s], epochs run (the fit summary's ``epochs``), final
    loss, step latency mean/p95 [ms], nodes, support points, parameter count and bytes.
    """
    import torch

    from cpmp.sequencer import ConcurrentSequencer

    out: dict[str, Any] = {
        "n_demos": len(demos),
        "n_features": int(demos[0].n_features),
        "torch_threads": torch.get_num_threads(),
        "predictors": {},
    }
    stream = demos[0].features
    for kind in predictors:
        extra = dict((options or {}).get(kind, {}))
        start = time.perf_counter()
        seq = ConcurrentSequencer.fit(list(demos), kind, seed=seed, logger=None, **extra)
        fit_s = time.perf_counter() - start
        seq.reset(0.0, stream[0])
        times = np.empty(n_ticks)
        for k in range(n_ticks):
            x = stream[(k + 1) % len(stream)]
            t0 = time.perf_counter()
            seq.step(0.01 * (k + 1), x)
            times[k] = time.perf_counter() - t0
        n_bytes = sum(t.numel() * t.element_size() for t in seq.predictor.state_dict().values())
        out["predictors"][kind] = {
            "fit_seconds": fit_s,
            "epochs": seq.fit_summary.get("epochs"),
            "max_epochs": extra.get("epochs", getattr(seq.predictor.config, "epochs", None)),
            "loss": seq.fit_summary.get("loss"),
            "step_ms_mean": float(times.mean() * 1e3),
            "step_ms_p95": float(np.percentile(times, 95) * 1e3),
            "n_nodes": len(seq.node_keys),
            "n_support_total": seq.fit_summary.get("n_support_total"),
            "solver": seq.fit_summary.get("solver"),
            "n_parameters": seq.predictor.n_parameters(),
            "state_bytes": int(n_bytes),
        }
    return out


# --------------------------------------------------------------------------------- settings
@dataclass
class BenchSettings:
    """Sizes of :func:`run_bench` (the defaults are the issue's; :meth:`quick` is small).

    Attributes:
        sections: which of :data:`SECTIONS` to run.
        seed: seed of the demonstrations, boxes and fits.
        fit_demos: simulated training demonstrations of the ``fit`` and ``sequencer``
            sections, drawn as seed ``seed`` of the main job draws them (9: the full
            experiment's D = 9).
        repeats: timed repetitions of each fit (the report gives min and median).
        batch: episodes run together (sequencer and real-time sections).
        ticks: control ticks per episode of the ``sequencer`` section.
        max_time: episode time limit [s] of the ``realtime`` section (``None``: the task's).
        experiment: ``experiment=`` config of the ``stages`` section.
        experiment_overrides: further Hydra overrides of that run (``experiment.workers=2``).
        scaling_demos: demonstration counts of the ``scaling`` section.
        scaling_features: feature counts of the ``scaling`` section (>= 6, the relay task's).
        scaling_ticks: ticks per episode when timing the sequencer in ``scaling``.
        gradient_demos: synthetic demonstrations of the ``gradient`` section.
        gradient_predictors: the Adam-trained predictors timed there.
        gradient_epochs: cap on their epochs (``None``: each predictor's default).
        lbfgs: also time the LBFGS solver (``trainer.solver=lbfgs``) in ``fit``.
        threads: torch (and BLAS) threads.
    """

    sections: list[str] = field(default_factory=lambda: list(SECTIONS))
    seed: int = 0
    fit_demos: int = 9
    repeats: int = 3
    batch: int = 20
    ticks: int = 300
    max_time: float | None = None
    experiment: str = "quick"
    experiment_overrides: list[str] = field(default_factory=list)
    scaling_demos: list[int] = field(default_factory=lambda: [3, 6, 12, 25, 50])
    scaling_features: list[int] = field(default_factory=lambda: [24, 64, 128, 256])
    scaling_ticks: int = 100
    gradient_demos: int = 6
    gradient_predictors: list[str] = field(default_factory=lambda: ["mlp", "klr_sparse"])
    gradient_epochs: int | None = None
    lbfgs: bool = False
    threads: int = 1

    def __post_init__(self) -> None:
        unknown = [s for s in self.sections if s not in SECTIONS]
        if unknown or not self.sections:
            raise ConfigError(
                f"unknown or no bench sections {unknown or self.sections}; choose from "
                f"{', '.join(SECTIONS)}"
            )
        for name in ("fit_demos", "repeats", "batch", "ticks", "scaling_ticks", "threads"):
            _check_count(name, getattr(self, name))
        _check_count("gradient_demos", self.gradient_demos)
        if self.gradient_epochs is not None:
            _check_count("gradient_epochs", self.gradient_epochs)
        if self.seed < 0:
            raise ConfigError(f"seed must be >= 0, got {self.seed}")
        if self.max_time is not None and not self.max_time > 0:
            raise ConfigError(f"max_time must be > 0 seconds, got {self.max_time}")
        for name in ("scaling_demos", "scaling_features"):
            values = getattr(self, name)
            if not values:
                raise ConfigError(f"{name} needs at least one value")
            for value in values:
                _check_count(name, value)
        from cpmp.synthetic_relay import FEATURE_NAMES

        if min(self.scaling_features) < len(FEATURE_NAMES):
            raise ConfigError(
                f"scaling_features must be >= {len(FEATURE_NAMES)} (the relay task's features), "
                f"got {self.scaling_features}"
            )

    @classmethod
    def quick(cls, **overrides: Any) -> BenchSettings:
        """Small sizes (a minute or two): 3 demonstrations, 4 episodes, ``experiment=tiny``."""
        small = {
            "fit_demos": 3,
            "repeats": 1,
            "batch": 4,
            "ticks": 100,
            "max_time": 12.0,
            "experiment": "tiny",
            "scaling_demos": [3, 6],
            "scaling_features": [24, 48],
            "scaling_ticks": 50,
            "gradient_demos": 4,
            "gradient_epochs": 30,
        }
        return cls(**{**small, **overrides})


def _check_count(name: str, value: Any) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ConfigError(f"{name} must be a whole number >= 1, got {value!r}")


# ------------------------------------------------------------------------- the convex fit
def node_kernels(seq: ConcurrentSequencer, demos: Sequence[Demonstration]) -> dict[str, Any]:
    """The convex problems of a fitted kernel predictor (``klr``, ``klr_full``): per node the
    kernel matrix ``(n_i, S_i)`` of its training samples against its real supports, the soft
    labels ``(n_i,)``, and the shared ``l2`` and ``bias`` options."""
    import torch

    from cpmp.sequencer import node_training_data

    predictor = seq.predictor
    if not hasattr(predictor, "support_mask"):
        raise ConfigError(f"predictor {predictor.kind!r} has no kernel; use klr or klr_full")
    data = node_training_data(seq.graphs, predictor)
    with torch.no_grad():
        kernels = [
            predictor._node_kernel(i, node.x)[:, predictor.support_mask[i]]
            for i, node in enumerate(data)
        ]
    return {
        "kernels": kernels,
        "targets": [node.target for node in data],
        "l2": float(predictor.config.l2),
        "bias": bool(predictor.config.bias),
    }


def problem_loss(problems: Mapping[str, Any], solutions: Sequence[tuple[Any, float]]) -> float:
    """Sum over nodes of the mean soft-label BCE plus ``½ l2 ||w||²`` at ``solutions``
    (per node ``(w (S_i,), b)``): the loss both solvers minimise."""
    import torch

    from cpmp.predictors.newton import penalised_loss

    total = 0.0
    for kernel, target, (w, b) in zip(
        problems["kernels"], problems["targets"], solutions, strict=True
    ):
        k = kernel.to(torch.float64)
        n = k.shape[0]
        weight = torch.full((n,), 1.0 / n, dtype=torch.float64)
        w = torch.as_tensor(np.asarray(w), dtype=torch.float64)
        total += float(penalised_loss(k, target.to(torch.float64), weight, w, b, problems["l2"]))
    return total


def newton_solve_all(
    problems: Mapping[str, Any], tol: float | None = None
) -> tuple[list[tuple[Any, float]], float]:
    """cpmp's Newton solver (:func:`~cpmp.predictors.newton.newton_fit`) on every node from
    zero; returns the solutions and the wall time [s]."""
    from cpmp.predictors.newton import NEWTON_TOL, newton_fit

    start = time.perf_counter()
    solutions, _ = newton_fit(
        problems["kernels"],
        problems["targets"],
        problems["l2"],
        fit_bias=problems["bias"],
        tol=NEWTON_TOL if tol is None else tol,
    )
    return solutions, time.perf_counter() - start


def sklearn_peer(
    problems: Mapping[str, Any], tol: float | None = None, max_iter: int = 100
) -> dict[str, Any]:
    """scikit-learn's ``LogisticRegression(solver="newton-cholesky")`` on every node's kernel
    features: soft labels ``y`` as two weighted copies of each sample (class 1 with weight
    ``y``, class 0 with weight ``1 - y``) and ``C = 1 / (l2 n)``, so that its objective
    (``1/n Σ weighted log-loss + l2/2 ||w||²``, intercept unpenalised) is cpmp's loss exactly.

    Returns per node ``(w, b)`` as ``solutions``, the wall time [s] of building the copies and
    fitting (one BLAS thread), the largest iteration count and whether every node converged.
    """
    from sklearn.exceptions import ConvergenceWarning
    from sklearn.linear_model import LogisticRegression
    from threadpoolctl import threadpool_limits

    from cpmp.predictors.newton import NEWTON_TOL

    solutions: list[tuple[Any, float]] = []
    iterations, converged, seconds = 0, True, 0.0
    with threadpool_limits(1), warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", ConvergenceWarning)
        for kernel, target in zip(problems["kernels"], problems["targets"], strict=True):
            k = kernel.detach().cpu().numpy()
            y = target.detach().cpu().numpy()
            n = len(y)
            l2 = problems["l2"]
            start = time.perf_counter()
            x2 = np.concatenate([k, k])
            labels = np.concatenate([np.ones(n), np.zeros(n)])
            weight = np.concatenate([y, 1.0 - y])
            model = LogisticRegression(
                solver="newton-cholesky",
                C=np.inf if l2 == 0 else 1.0 / (l2 * n),
                fit_intercept=problems["bias"],
                tol=NEWTON_TOL if tol is None else tol,
                max_iter=max_iter,
            )
            model.fit(x2, labels, sample_weight=weight)
            seconds += time.perf_counter() - start
            b = float(model.intercept_[0]) if problems["bias"] else 0.0
            solutions.append((model.coef_[0].copy(), b))
            iterations = max(iterations, int(np.max(model.n_iter_)))
        converged = not any(issubclass(w.category, ConvergenceWarning) for w in caught)
    return {
        "solutions": solutions,
        "seconds": seconds,
        "iterations": iterations,
        "converged": converged,
    }


def bench_fit(
    demos: Sequence[Demonstration], repeats: int = 3, seed: int = 0, lbfgs: bool = False
) -> dict[str, Any]:
    """Fit ``klr`` (cpmp's defaults) on ``demos`` ``repeats`` times and time it against
    :func:`sklearn_peer` on the same kernel features.

    Returns ``klr``: ``fit_seconds`` (the predictor's Lightning fit: supports, kernels, Newton),
    ``sequencer_fit_seconds`` (all of :meth:`ConcurrentSequencer.fit`), ``solve_seconds``
    (the Newton solve alone on the kernels), each as min and median over the repeats, and the
    loss; ``sklearn``: its time, iterations and loss; ``ratio`` of the times (klr / sklearn,
    < 1: klr is faster) and the relative loss difference; with ``lbfgs`` the LBFGS fit too.
    """
    from cpmp.sequencer import ConcurrentSequencer

    _check_count("repeats", repeats)
    fits, totals, solves, peers = [], [], [], []
    for _ in range(repeats):
        start = time.perf_counter()
        seq = ConcurrentSequencer.fit(list(demos), "klr", seed=seed, logger=None)
        totals.append(time.perf_counter() - start)
        fits.append(float(seq.fit_summary["seconds"]))
    problems = node_kernels(seq, demos)
    for _ in range(repeats):
        solutions, seconds = newton_solve_all(problems)
        solves.append(seconds)
        peers.append(sklearn_peer(problems))
    klr_loss = problem_loss(problems, solutions)
    peer = peers[-1]
    peer_loss = problem_loss(problems, peer["solutions"])
    peer_seconds = [p["seconds"] for p in peers]
    out: dict[str, Any] = {
        "n_demos": len(demos),
        "n_features": int(demos[0].n_features),
        "n_heads": len(problems["kernels"]),
        "n_support_total": int(sum(k.shape[1] for k in problems["kernels"])),
        "n_samples_total": int(sum(k.shape[0] for k in problems["kernels"])),
        "repeats": repeats,
        "klr": {
            "fit_seconds": _stats(fits),
            "sequencer_fit_seconds": _stats(totals),
            "solve_seconds": _stats(solves),
            "loss": float(seq.fit_summary["loss"]),
            "solve_loss": klr_loss,
            "newton_iterations": seq.fit_summary.get("newton_iterations"),
        },
        "sklearn": {
            "seconds": _stats(peer_seconds),
            "loss": peer_loss,
            "iterations": peer["iterations"],
            "converged": peer["converged"],
            "version": _version("sklearn"),
        },
        "ratio": {
            "fit_over_sklearn": min(fits) / min(peer_seconds),
            "solve_over_sklearn": min(solves) / min(peer_seconds),
        },
        "loss_rel_diff": abs(klr_loss - peer_loss) / abs(peer_loss),
    }
    if lbfgs:
        start = time.perf_counter()
        slow = ConcurrentSequencer.fit(list(demos), "klr", seed=seed, logger=None, solver="lbfgs")
        out["lbfgs"] = {
            "sequencer_fit_seconds": time.perf_counter() - start,
            "fit_seconds": float(slow.fit_summary["seconds"]),
            "loss": float(slow.fit_summary["loss"]),
        }
    return out


# ------------------------------------------------------------------------ sequencer ticks
def bench_ticks(
    seq: ConcurrentSequencer,
    streams: Sequence[np.ndarray],
    ticks: int,
    dt: float = 0.01,
) -> dict[str, Any]:
    """Cost of the sequencer per episode-tick: ``len(streams)`` episodes of ``ticks`` ticks,
    episode ``i`` fed ``streams[i] (n_i, d)`` (its last row once it ends), first one episode at
    a time with :meth:`ConcurrentSequencer.step`, then all together with one
    :class:`~cpmp.sequencer.BatchedSequencer` call per tick.

    Returns ``single`` and ``batched`` cost [ms per episode-tick] (mean; single also p95) and
    whether both made the same transitions (``same_decisions``).
    """
    n = len(streams)
    _check_count("streams", n)
    _check_count("ticks", ticks)
    inputs = np.stack(  # (ticks + 1, N, d)
        [np.stack([s[min(k, len(s) - 1)] for s in streams]) for k in range(ticks + 1)]
    )
    per_call = np.empty((n, ticks))
    single_events = []
    for i in range(n):
        seq.reset(0.0, inputs[0, i])
        for k in range(1, ticks + 1):
            start = time.perf_counter()
            seq.step(k * dt, inputs[k, i])
            per_call[i, k - 1] = time.perf_counter() - start
        single_events.append([(e.t, e.variable, e.target) for e in seq.events])
    batch = seq.batched(n)
    batch.reset(0.0, inputs[0])
    start = time.perf_counter()
    for k in range(1, ticks + 1):
        batch.step(k * dt, inputs[k])
    batched = time.perf_counter() - start
    batched_events = [[(e.t, e.variable, e.target) for e in ev] for ev in batch.events]
    return {
        "n_episodes": n,
        "ticks": ticks,
        "n_heads": len(seq.predictor.node_keys),
        "single_ms": float(per_call.mean() * 1e3),
        "single_ms_p95": float(np.percentile(per_call, 95) * 1e3),
        "batched_ms": 1e3 * batched / (n * ticks),
        "speedup": float(per_call.sum() / batched),
        "target_ms": TICK_TARGET_MS,
        "meets_target": 1e3 * batched / (n * ticks) <= TICK_TARGET_MS,
        "same_decisions": single_events == batched_events,
        "transitions": int(sum(len(e) for e in batched_events)),
    }


# ------------------------------------------------------------------------------- scaling
def pad_features(demos: Sequence[Demonstration], d: int) -> list[Demonstration]:
    """``demos`` with constant zero columns appended up to ``d`` features. Path lengths, and
    so the support points, stay the same; the kernel's feature dimension grows (with
    ``feature_weighting=path`` the moving features' weights ``d · share`` grow with it)."""
    from cpmp.data import Demonstration

    out = []
    for demo in demos:
        extra = d - demo.n_features
        if extra < 0:
            raise ConfigError(f"cannot pad {demo.n_features} features down to {d}")
        names = list(demo.feature_names) + [f"pad_{j}" for j in range(extra)]
        features = np.concatenate([demo.features, np.zeros((demo.n_samples, extra))], axis=1)
        out.append(
            Demonstration(
                time=demo.time,
                features=features,
                labels=demo.labels,
                feature_names=names,
                name=demo.name,
                metadata=dict(demo.metadata or {}),
            )
        )
    return out


def bench_scaling(
    demo_counts: Sequence[int],
    feature_counts: Sequence[int],
    seed: int = 0,
    batch: int = 20,
    ticks: int = 100,
) -> dict[str, Any]:
    """Fit time (``klr`` and the scikit-learn peer) and tick cost as the training set grows
    (``demo_counts`` demonstrations of the synthetic relay task, padded to the smallest
    feature count) and as features grow (``feature_counts``, at the middle demonstration
    count). Each point: one fit, support count, samples, Newton solve and peer times [s],
    single and batched tick cost [ms per episode-tick]."""
    from cpmp.synthetic_relay import make_demonstrations

    base_d = min(feature_counts)
    base_n = sorted(demo_counts)[len(demo_counts) // 2]
    pool = make_demonstrations(max(max(demo_counts), base_n) + batch, seed=seed)
    held_out = pool[-batch:]

    def point(n: int, d: int) -> dict[str, Any]:
        demos = pad_features(pool[:n], d)
        row = _fit_point(demos, seed)
        streams = [demo.features for demo in pad_features(held_out, d)]
        seq = row.pop("sequencer")
        tick = bench_ticks(seq, streams, ticks)
        row.update(
            n_demos=n,
            n_features=d,
            tick_single_ms=tick["single_ms"],
            tick_batched_ms=tick["batched_ms"],
        )
        return row

    return {
        "task": "synthetic relay (cpmp.synthetic_relay), features padded with zero columns",
        "batch": batch,
        "ticks": ticks,
        "demos": [point(n, base_d) for n in sorted(demo_counts)],
        "demos_at_features": base_d,
        "features": [point(base_n, d) for d in sorted(feature_counts)],
        "features_at_demos": base_n,
    }


def _fit_point(demos: Sequence[Demonstration], seed: int) -> dict[str, Any]:
    from cpmp.sequencer import ConcurrentSequencer

    seq = ConcurrentSequencer.fit(list(demos), "klr", seed=seed, logger=None)
    problems = node_kernels(seq, demos)
    _, solve = newton_solve_all(problems)
    peer = sklearn_peer(problems)
    return {
        "sequencer": seq,
        "fit_seconds": float(seq.fit_summary["seconds"]),
        "solve_seconds": solve,
        "sklearn_seconds": peer["seconds"],
        "n_support_total": int(sum(k.shape[1] for k in problems["kernels"])),
        "n_samples_total": int(sum(k.shape[0] for k in problems["kernels"])),
    }


# ------------------------------------------------------------------ simulator and main job
class _SimData:
    """The simulated data the ``fit``, ``sequencer`` and ``realtime`` sections share, made
    once on first use: training demonstrations, the fitted sequencer, reproduction boxes and
    their expected demonstrations."""

    def __init__(self, settings: BenchSettings) -> None:
        from cpmp.sim import TaskConfig

        self.settings = settings
        self.task = TaskConfig()
        self._train: list[Demonstration] | None = None
        self._seq: ConcurrentSequencer | None = None
        self._boxes: tuple[list[Any], list[Demonstration]] | None = None

    @property
    def train(self) -> list[Demonstration]:
        """The main job's training demonstrations of seed ``seed`` at D = ``fit_demos``."""
        if self._train is None:
            from cpmp.experiment.pipeline import balanced_subset
            from cpmp.sim import record_demonstration
            from cpmp.sim.collect import sample_boxes

            s = self.settings
            rng = np.random.default_rng(s.seed)
            boxes = sample_boxes(rng, self.task, s.fit_demos, balanced=True)
            demos = [
                record_demonstration(b, self.task, name=f"demo_{i:03d}")
                for i, b in enumerate(boxes)
            ]
            self._train = balanced_subset(demos, s.fit_demos)
        return self._train

    @property
    def sequencer(self) -> ConcurrentSequencer:
        if self._seq is None:
            from cpmp.sequencer import ConcurrentSequencer

            self._seq = ConcurrentSequencer.fit(
                self.train, "klr", seed=self.settings.seed, logger=None
            )
        return self._seq

    @property
    def boxes(self) -> tuple[list[Any], list[Demonstration]]:
        """``batch`` reproduction boxes (the main job's, seed ``seed``) and the demonstrator's
        recording of each."""
        if self._boxes is None:
            from cpmp.sim import record_demonstration, sample_box

            rng = np.random.default_rng(self.settings.seed + 1000)
            boxes = [sample_box(rng, self.task) for _ in range(self.settings.batch)]
            self._boxes = boxes, [record_demonstration(b, self.task) for b in boxes]
        return self._boxes


def bench_realtime(sim: _SimData) -> dict[str, Any]:
    """Real-time factor of ``batch`` closed-loop episodes with the fitted sequencer, one at a
    time and batched (:func:`cpmp.sim.bench.time_rollouts`)."""
    from cpmp.sim.bench import TARGET_REAL_TIME_FACTOR, time_rollouts

    boxes, expected = sim.boxes
    seq, task, max_time = sim.sequencer, sim.task, sim.settings.max_time
    single = time_rollouts(boxes, seq, task, expected, batched=False, max_time=max_time)
    batched = time_rollouts(boxes, seq, task, expected, batched=True, max_time=max_time)
    return {
        "n_episodes": len(boxes),
        "target_real_time_factor": TARGET_REAL_TIME_FACTOR,
        "single": single,
        "batched": batched,
        "speedup": single["wall_time_s"] / batched["wall_time_s"],
        "same_outcomes": single["outcomes"] == batched["outcomes"],
    }


def bench_stages(
    experiment: str, threads: int = 1, overrides: Sequence[str] = ()
) -> dict[str, Any]:
    """Run the main job ``scripts/experiment.py experiment=<experiment> [overrides]`` in a
    fresh process (as a user does) and report its wall time and its ``timings.json``: seconds
    per stage (kinematics set-up, collect, expected, train, evaluate, reproduce, strategy map,
    plots)."""
    import json

    script = ROOT / "scripts" / "experiment.py"
    if not script.is_file():
        raise CpmpFileError(f"{script} not found: the stages section needs the repository")
    with tempfile.TemporaryDirectory(prefix="cpmp-bench-") as tmp:
        run_dir = Path(tmp) / "run"
        command = [
            sys.executable,
            str(script),
            f"experiment={experiment}",
            f"hydra.run.dir={run_dir}",
            f"++threads={threads}",
            *overrides,
        ]
        start = time.perf_counter()
        proc = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, check=False)
        wall = time.perf_counter() - start
        if proc.returncode != 0:
            error = ConfigError if proc.returncode == 2 else RuntimeError
            raise error(
                f"the main job failed (exit {proc.returncode}): {' '.join(command)}\n"
                f"{proc.stderr[-2000:]}"
            )
        timings = json.loads((run_dir / "timings.json").read_text())
        report = json.loads((run_dir / "report.json").read_text())
    return {
        "experiment": experiment,
        "command": " ".join(
            ["python scripts/experiment.py", f"experiment={experiment}", *overrides]
        ),
        "process_wall_s": wall,
        "job_seconds": timings["seconds"],
        "workers": timings["workers"],
        "stages": timings["stages"],
        "reproduction": {
            d: {k: row[k] for k in ("W", "I", "C")} for d, row in report["reproduction"].items()
        },
    }


def bench_gradient(settings: BenchSettings) -> dict[str, Any]:
    """The Adam-trained predictors on ``gradient_demos`` synthetic demonstrations
    (:func:`bench_sequencer`): fit time, epochs run, loss, step cost."""
    from cpmp.synthetic import make_demonstrations

    demos = make_demonstrations(settings.gradient_demos, seed=settings.seed)
    epochs = settings.gradient_epochs
    options = {
        kind: {} if epochs is None else {"epochs": epochs} for kind in settings.gradient_predictors
    }
    return bench_sequencer(
        demos, settings.gradient_predictors, settings.ticks, settings.seed, options
    )


# ------------------------------------------------------------------------------ the run
def run_bench(settings: BenchSettings, out_dir: str | Path) -> Path:
    """Run the sections of ``settings`` and write ``bench.json``, ``bench.md`` and (with the
    ``scaling`` section) ``bench_scaling.png`` into ``out_dir``; returns ``bench.json``."""
    import torch
    from threadpoolctl import threadpool_limits

    from cpmp.experiment.report import write_json
    from cpmp.io import atomic_write_text

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    torch.set_num_threads(settings.threads)
    started = time.perf_counter()
    result: dict[str, Any] = {
        "settings": asdict(settings),
        "machine": _machine(settings.threads),
        "sections": {},
    }
    sim = _SimData(settings)
    with threadpool_limits(settings.threads):
        result["warm_up_seconds"] = _warm_up(settings.seed)
        for name in SECTIONS:
            if name not in settings.sections:
                continue
            log.info("bench section %s: start", name)
            start = time.perf_counter()
            if name == "fit":
                section = bench_fit(sim.train, settings.repeats, settings.seed, settings.lbfgs)
            elif name == "sequencer":
                streams = [demo.features for demo in sim.boxes[1]]
                section = bench_ticks(sim.sequencer, streams, settings.ticks)
                section["n_demos"] = len(sim.train)
            elif name == "realtime":
                section = bench_realtime(sim)
            elif name == "stages":
                section = bench_stages(
                    settings.experiment, settings.threads, settings.experiment_overrides
                )
            elif name == "scaling":
                section = bench_scaling(
                    settings.scaling_demos,
                    settings.scaling_features,
                    settings.seed,
                    settings.batch,
                    settings.scaling_ticks,
                )
            else:
                section = bench_gradient(settings)
            section["section_seconds"] = time.perf_counter() - start
            result["sections"][name] = section
            log.info("bench section %s: done in %.1f s", name, section["section_seconds"])
    result["seconds"] = time.perf_counter() - started
    result["machine"]["load_average_end"] = _load_average()
    files = {"bench.json": "every number", "bench.md": "the tables"}
    if "scaling" in result["sections"]:
        plot_scaling(result["sections"]["scaling"], out / "bench_scaling.png")
        files["bench_scaling.png"] = "log-log: fit time and tick cost against demos and features"
    result["files"] = files
    atomic_write_text(out / "bench.md", bench_markdown(result))
    return write_json(out / "bench.json", result)


def _warm_up(seed: int) -> float:
    """One small untimed fit, so that no section pays for importing Lightning and
    scikit-learn; returns its wall time [s]."""
    import sklearn.linear_model  # noqa: F401

    from cpmp.sequencer import ConcurrentSequencer
    from cpmp.synthetic import make_demonstrations

    start = time.perf_counter()
    ConcurrentSequencer.fit(make_demonstrations(2, seed=seed), "klr", seed=seed, logger=None)
    return time.perf_counter() - start


def _stats(values: Sequence[float]) -> dict[str, float]:
    return {"min": float(min(values)), "median": float(statistics.median(values))}


def _version(module: str) -> str | None:
    try:
        return __import__(module).__version__
    except ImportError:
        return None


def _load_average() -> list[float] | None:
    try:
        return [round(v, 2) for v in os.getloadavg()]
    except OSError:
        return None


def _machine(threads: int) -> dict[str, Any]:
    import torch

    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:
        cores = os.cpu_count()
    return {
        "cores": cores,
        "threads": threads,
        "python": platform.python_version(),
        "torch": torch.__version__,
        "sklearn": _version("sklearn"),
        "platform": platform.platform(),
        "load_average_start": _load_average(),
        "note": "load average: other processes on the machine (1, 5, 15 min); timings taken "
        "under load are slower than on an idle machine",
    }


# ------------------------------------------------------------------------ plot, markdown
def plot_scaling(scaling: Mapping[str, Any], path: str | Path) -> Path:
    """Log-log plot of the ``scaling`` section: fit time (klr fit, Newton solve, scikit-learn
    peer) [s] and tick cost (single, batched) [ms] against demonstrations and features."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from cpmp.io import atomic_path

    figure = Figure(figsize=(10, 7), dpi=120, layout="constrained")
    FigureCanvasAgg(figure)
    axes = figure.subplots(2, 2)
    for col, (key, label) in enumerate((("demos", "n_demos"), ("features", "n_features"))):
        rows = scaling[key]
        x = [row[label] for row in rows]
        fit_ax, tick_ax = axes[0, col], axes[1, col]
        for field_name, name in (
            ("fit_seconds", "klr fit (Lightning)"),
            ("solve_seconds", "klr Newton solve"),
            ("sklearn_seconds", "scikit-learn newton-cholesky"),
        ):
            fit_ax.loglog(x, [row[field_name] for row in rows], marker="o", label=name)
        for field_name, name in (
            ("tick_single_ms", "one episode"),
            ("tick_batched_ms", f"{scaling['batch']} episodes batched"),
        ):
            tick_ax.loglog(x, [row[field_name] for row in rows], marker="o", label=name)
        tick_ax.axhline(TICK_TARGET_MS, color="grey", linestyle="--", label="target 0.1 ms")
        other = (
            f"{scaling['demos_at_features']} features"
            if key == "demos"
            else f"{scaling['features_at_demos']} demos"
        )
        fit_ax.set(xlabel=f"{key} ({other})", ylabel="fit time [s]")
        tick_ax.set(xlabel=f"{key} ({other})", ylabel="sequencer [ms per episode-tick]")
        for ax in (fit_ax, tick_ax):
            ax.set_xticks(x, [str(v) for v in x])
            ax.set_xticks([], minor=True)
            ax.grid(alpha=0.3, which="both")
            ax.legend(fontsize="small")
    figure.suptitle("Scaling on the synthetic relay task (log-log)")
    with atomic_path(path) as tmp:
        figure.savefig(tmp, format="png")
    figure.clear()
    return Path(path)


def bench_markdown(result: Mapping[str, Any]) -> str:
    """The benchmark as Markdown tables."""
    m = result["machine"]
    lines = [
        "# cpmp benchmark",
        "",
        f"{m['cores']} cores, {m['threads']} torch thread(s), torch {m['torch']}, scikit-learn "
        f"{m['sklearn']}, Python {m['python']}; load average at start {m['load_average_start']}, "
        f"at end {m.get('load_average_end')} (other processes slow every timing down). "
        f"Total {result['seconds']:.0f} s.",
    ]
    sections = result["sections"]
    if "fit" in sections:
        f = sections["fit"]
        k, s = f["klr"], f["sklearn"]
        lines += [
            "",
            f"## Convex fit: klr vs scikit-learn ({f['n_demos']} simulated demos, "
            f"{f['n_heads']} heads, {f['n_support_total']} supports, "
            f"{f['n_samples_total']} samples)",
            "",
            "| what | min [s] | median [s] | loss |",
            "| --- | --- | --- | --- |",
            _row("klr: `ConcurrentSequencer.fit`", k["sequencer_fit_seconds"], k["loss"]),
            _row("klr: predictor fit (Lightning, Newton)", k["fit_seconds"], k["loss"]),
            _row("klr: Newton solve alone", k["solve_seconds"], k["solve_loss"]),
            _row("scikit-learn newton-cholesky", s["seconds"], s["loss"]),
        ]
        if "lbfgs" in f:
            lb = f["lbfgs"]
            lines.append(
                f"| klr with `solver=lbfgs` (predictor fit) | {lb['fit_seconds']:.3f} | – | "
                f"{lb['loss']:.6f} |"
            )
        lines += [
            "",
            f"Ratio klr / scikit-learn: predictor fit {f['ratio']['fit_over_sklearn']:.2f}, "
            f"Newton solve {f['ratio']['solve_over_sklearn']:.2f} (< 1: klr faster); relative "
            f"loss difference {f['loss_rel_diff']:.1e}.",
        ]
    if "sequencer" in sections:
        q = sections["sequencer"]
        lines += [
            "",
            f"## Sequencer cost ({q['n_heads']} heads, {q['n_episodes']} episodes x "
            f"{q['ticks']} ticks)",
            "",
            "| mode | ms per episode-tick |",
            "| --- | --- |",
            f"| one episode at a time | {q['single_ms']:.4f} (p95 {q['single_ms_p95']:.4f}) |",
            f"| {q['n_episodes']} batched | {q['batched_ms']:.4f} |",
            "",
            f"Target <= {q['target_ms']} ms batched: {'met' if q['meets_target'] else 'missed'}; "
            f"same transitions single and batched: {q['same_decisions']}.",
        ]
    if "realtime" in sections:
        r = sections["realtime"]
        lines += [
            "",
            f"## Real-time factor ({r['n_episodes']} closed-loop episodes)",
            "",
            "| mode | sim time [s] | wall [s] | real-time factor | physics / kinematics / "
            "policy / other [ms per episode-tick] |",
            "| --- | --- | --- | --- | --- |",
        ]
        for mode in ("single", "batched"):
            t = r[mode]
            ms = t["ms_per_tick"]
            parts = ("physics", "kinematics", "policy", "other")
            cost = " / ".join(f"{ms.get(key, 0.0):.3f}" for key in parts)
            lines.append(
                f"| {mode} | {t['sim_time_s']:.1f} | {t['wall_time_s']:.1f} | "
                f"{t['real_time_factor']:.1f} | {cost} |"
            )
        lines += ["", f"Same outcomes single and batched: {r['same_outcomes']}."]
    if "stages" in sections:
        st = sections["stages"]
        lines += [
            "",
            f"## Main job `{st['command']}` ({st['workers']} worker(s))",
            "",
            f"Process wall time {st['process_wall_s']:.1f} s (the job itself "
            f"{st['job_seconds']:.1f} s).",
            "",
            "| stage | seconds |",
            "| --- | --- |",
        ]
        lines += [f"| {k} | {v:.1f} |" for k, v in st["stages"].items()]
    if "scaling" in sections:
        sc = sections["scaling"]
        lines += ["", "## Scaling (synthetic relay task; `bench_scaling.png`)"]
        for key, label, other in (
            ("demos", "demos", f"{sc['demos_at_features']} features"),
            ("features", "features", f"{sc['features_at_demos']} demos"),
        ):
            lines += [
                "",
                f"By {label} ({other}):",
                "",
                f"| {label} | supports | fit [s] | Newton [s] | scikit-learn [s] | tick single "
                "[ms] | tick batched [ms] |",
                "| --- | --- | --- | --- | --- | --- | --- |",
            ]
            lines += [
                f"| {row['n_' + label]} | {row['n_support_total']} | {row['fit_seconds']:.3f} | "
                f"{row['solve_seconds']:.3f} | {row['sklearn_seconds']:.3f} | "
                f"{row['tick_single_ms']:.4f} | {row['tick_batched_ms']:.4f} |"
                for row in sc[key]
            ]
    if "gradient" in sections:
        g = sections["gradient"]
        lines += [
            "",
            f"## Gradient-trained predictors ({g['n_demos']} synthetic demos)",
            "",
            "| predictor | fit [s] | epochs run | max epochs | loss | step [ms] |",
            "| --- | --- | --- | --- | --- | --- |",
        ]
        lines += [
            f"| {kind} | {p['fit_seconds']:.2f} | {p['epochs']} | {p['max_epochs']} | "
            f"{p['loss']:.5f} | {p['step_ms_mean']:.3f} |"
            for kind, p in g["predictors"].items()
        ]
    return "\n".join(lines) + "\n"


def _row(name: str, seconds: Mapping[str, float], loss: float) -> str:
    return f"| {name} | {seconds['min']:.3f} | {seconds['median']:.3f} | {loss:.6f} |"


__all__ = [
    "SECTIONS",
    "BenchSettings",
    "bench_fit",
    "bench_realtime",
    "bench_scaling",
    "bench_sequencer",
    "bench_stages",
    "bench_ticks",
    "node_kernels",
    "pad_features",
    "plot_scaling",
    "problem_loss",
    "run_bench",
    "sklearn_peer",
]
