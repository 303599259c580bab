"""Speed and size of fitting and running sequencers (``scripts/bench_sequencer.py``)."""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

import numpy as np


def bench_sequencer(
    demos: Sequence[Any], predictors: Sequence[str], n_ticks: int = 500, seed: int = 0
) -> dict[str, Any]:
    """Fit each predictor on ``demos`` and time :meth:`ConcurrentSequencer.step` over the first
    demo's feature stream (``n_ticks`` ticks, cycling).

    Returns per predictor: fit time [s], step latency mean/p95 [ms], nodes, support points,
    parameter count and bytes.
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
        start = time.perf_counter()
        seq = ConcurrentSequencer.fit(list(demos), kind, seed=seed, logger=None)
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
            "step_ms_mean": float(times.mean() * 1e3),
            "step_ms_p95": float(np.percentile(times, 95) * 1e3),
            "n_nodes": len(seq.node_keys),
            "n_support_total": seq.fit_summary.get("n_support_total"),
            "solver": seq.fit_summary.get("solver"),
            "n_parameters": seq.predictor.n_parameters(),
            "state_bytes": int(n_bytes),
        }
    return out
