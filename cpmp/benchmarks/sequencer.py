"""The sequencer's cost without the simulator, and closed-loop outcomes on synthetic tasks.

Each predictor fitted and stepped (:func:`bench_sequencer`, ``scripts/bench_sequencer.py``), one
episode at a time against batched episodes (:func:`bench_ticks`, the ``sequencer`` section of
``scripts/bench.py``) and the Adam-trained predictors (:func:`bench_gradient`, the ``gradient``
section); the closed-loop outcomes on the synthetic worlds are :mod:`cpmp.benchmarks.synthetic`.
Every function returns a JSON-ready dict; nothing here asserts a speed.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence

import numpy as np
import torch

from cpmp.benchmarks.settings import BenchSettings, check_count
from cpmp.data.demonstration import Demonstration
from cpmp.records import JsonValue
from cpmp.sequencer.sequencer import ConcurrentSequencer
from cpmp.worlds.two_point import make_demonstrations as two_point_demos

TICK_TARGET_MS = 0.1
"""Issue #9's target for the sequencer: <= 0.1 ms per episode-tick with 20 episodes batched."""


def bench_sequencer(
    demos: Sequence[Demonstration],
    predictors: Sequence[str],
    n_ticks: int = 500,
    seed: int = 0,
    options: Mapping[str, Mapping[str, JsonValue]] | None = None,
) -> dict[str, JsonValue]:
    """Fit each predictor on ``demos`` and time :meth:`ConcurrentSequencer.step`.

    The steps run over the first demo's feature stream (``n_ticks`` ticks, cycling).

    ``options``: per predictor kind, extra :meth:`ConcurrentSequencer.fit` options.

    Returns per predictor: fit time [s], epochs run (the fit summary's ``epochs``), final
    loss, step latency mean/p95 [ms], nodes, support points, parameter count and bytes.
    """
    rows: dict[str, JsonValue] = {}
    out: dict[str, JsonValue] = {
        "n_demos": len(demos),
        "n_features": int(demos[0].n_features),
        "torch_threads": torch.get_num_threads(),
        "predictors": rows,
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
        report = seq.fit_summary
        rows[kind] = {
            "fit_seconds": fit_s,
            "epochs": report.epochs,
            "max_epochs": extra.get("epochs", getattr(seq.predictor.config, "epochs", None)),
            "loss": report.loss,
            "step_ms_mean": float(times.mean() * 1e3),
            "step_ms_p95": float(np.percentile(times, 95) * 1e3),
            "n_nodes": len(seq.node_keys),
            "n_support_total": report.n_support_total,
            "solver": report.solver,
            "n_parameters": seq.predictor.n_parameters(),
            "state_bytes": int(n_bytes),
        }
    return out


# ------------------------------------------------------------------------ sequencer ticks
def bench_ticks(
    seq: ConcurrentSequencer,
    streams: Sequence[np.ndarray],
    ticks: int,
    dt: float = 0.01,
) -> dict[str, JsonValue]:
    """Cost of the sequencer per episode-tick, one episode at a time and batched.

    ``len(streams)`` episodes of ``ticks`` ticks, episode ``i`` fed ``streams[i] (n_i, d)`` (its
    last row once it ends), first one episode at a time with :meth:`ConcurrentSequencer.step`, then
    all together with one :class:`~cpmp.sequencer.batch.BatchedSequencer` call per tick.

    Returns ``single`` and ``batched`` cost [ms per episode-tick] (mean; single also p95) and
    whether both made the same transitions (``same_decisions``).
    """
    n = len(streams)
    check_count("streams", n)
    check_count("ticks", ticks)
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


def bench_gradient(settings: BenchSettings) -> dict[str, JsonValue]:
    """The Adam-trained predictors on ``gradient_demos`` synthetic demonstrations.

    As :func:`bench_sequencer`: fit time, epochs run, loss, step cost.
    """
    demos = two_point_demos(settings.gradient_demos, seed=settings.seed)
    epochs = settings.gradient_epochs
    options = {
        kind: ({} if epochs is None else {"epochs": epochs})
        for kind in settings.gradient_predictors
    }
    return bench_sequencer(
        demos, settings.gradient_predictors, settings.ticks, settings.seed, options
    )
