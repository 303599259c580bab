"""The ``fit`` and ``scaling`` sections of ``scripts/bench.py``.

Cpmp's convex ``klr`` fit against scikit-learn's ``LogisticRegression(solver="newton-cholesky")`` on
the same kernel features (:func:`sklearn_peer`, :func:`bench_fit`), and fit time and tick cost as
demonstrations and features grow (:func:`bench_scaling`, on the synthetic relay task). The
convex problems and the peer's fit are records (:class:`KernelProblems`, :class:`PeerFit`); every
section returns a JSON-ready dict of measurements; nothing here asserts a speed.
"""

from __future__ import annotations

import statistics
import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch
from sklearn.exceptions import ConvergenceWarning
from sklearn.linear_model import LogisticRegression
from threadpoolctl import threadpool_limits

from cpmp.benchmarks.report import package_version
from cpmp.benchmarks.sequencer import bench_ticks
from cpmp.benchmarks.settings import check_count
from cpmp.data.demonstration import Demonstration
from cpmp.errors import ConfigError
from cpmp.predictors.newton import NEWTON_TOL, newton_fit, penalised_loss
from cpmp.records import JsonValue
from cpmp.sequencer.fit_data import node_training_data
from cpmp.sequencer.sequencer import ConcurrentSequencer
from cpmp.worlds.relay.demonstrator import make_demonstrations


@dataclass(frozen=True)
class KernelProblems:
    """The convex problems of a fitted kernel predictor, one per node (:func:`node_kernels`).

    Attributes:
        kernels: per node the kernel matrix ``(n_i, S_i)`` of its training samples against its
            real supports.
        targets: per node the soft labels ``(n_i,)`` in [0, 1].
        l2: the L2 penalty shared by the nodes.
        bias: whether the nodes fit a bias.
    """

    kernels: list[torch.Tensor]
    targets: list[torch.Tensor]
    l2: float
    bias: bool


@dataclass(frozen=True)
class PeerFit:
    """scikit-learn's fit of every node (:func:`sklearn_peer`).

    Attributes:
        solutions: per node ``(w (S_i,), b)``.
        seconds: wall time [s] of building the weighted copies and fitting, summed over nodes.
        iterations: the largest iteration count of any node.
        converged: every node converged (no ``ConvergenceWarning``).
    """

    solutions: list[tuple[np.ndarray, float]]
    seconds: float
    iterations: int
    converged: bool


def node_kernels(seq: ConcurrentSequencer, demos: Sequence[Demonstration]) -> KernelProblems:
    """The convex problems of a fitted kernel predictor (``klr``, ``klr_full``).

    Per node the kernel matrix ``(n_i, S_i)`` of its training samples against its real supports, the
    soft labels ``(n_i,)``, and the shared ``l2`` and ``bias`` options.
    """
    predictor = seq.predictor
    if not hasattr(predictor, "support_mask"):
        raise ConfigError(f"predictor {predictor.kind!r} has no kernel; use klr or klr_full")
    data = node_training_data(seq.graphs, predictor)
    with torch.no_grad():
        kernels = [
            predictor.node_kernel(i, node.x)[:, predictor.support_mask[i]]
            for i, node in enumerate(data)
        ]
    return KernelProblems(
        kernels=kernels,
        targets=[node.target for node in data],
        l2=float(predictor.config.l2),
        bias=bool(predictor.config.bias),
    )


def problem_loss(
    problems: KernelProblems, solutions: Sequence[tuple[np.ndarray | torch.Tensor, float]]
) -> float:
    """The loss both solvers minimise, at ``solutions`` (per node ``(w (S_i,), b)``).

    The sum over nodes of the mean soft-label BCE plus ``½ l2 ||w||²``.
    """
    total = 0.0
    for kernel, target, (w, b) in zip(problems.kernels, problems.targets, solutions, strict=True):
        k = kernel.to(torch.float64)
        n = k.shape[0]
        weight = torch.full((n,), 1.0 / n, dtype=torch.float64)
        w = torch.as_tensor(np.asarray(w), dtype=torch.float64)
        total += float(penalised_loss(k, target.to(torch.float64), weight, w, b, problems.l2))
    return total


def newton_solve_all(
    problems: KernelProblems, tol: float | None = None
) -> tuple[list[tuple[torch.Tensor, float]], float]:
    """Cpmp's Newton solver (:func:`~cpmp.predictors.newton.newton_fit`) on every node from zero.

    Returns:
        The solutions (per node ``(w (S_i,), b)``) and the wall time [s].
    """
    start = time.perf_counter()
    solutions, _ = newton_fit(
        problems.kernels,
        problems.targets,
        problems.l2,
        fit_bias=problems.bias,
        tol=NEWTON_TOL if tol is None else tol,
    )
    return solutions, time.perf_counter() - start


def sklearn_peer(
    problems: KernelProblems, tol: float | None = None, max_iter: int = 100
) -> PeerFit:
    """scikit-learn's ``LogisticRegression(solver="newton-cholesky")`` on every node's kernels.

    Soft labels ``y`` as two weighted copies of each sample (class 1 with weight
    ``y``, class 0 with weight ``1 - y``) and ``C = 1 / (l2 n)``, so that its objective
    (``1/n Σ weighted log-loss + l2/2 ||w||²``, intercept unpenalised) is cpmp's loss exactly.

    Returns per node ``(w, b)`` as ``solutions``, the wall time [s] of building the copies and
    fitting (one BLAS thread), the largest iteration count and whether every node converged.
    """
    solutions: list[tuple[np.ndarray, float]] = []
    iterations, converged, seconds = 0, True, 0.0
    with threadpool_limits(1), warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", ConvergenceWarning)
        for kernel, target in zip(problems.kernels, problems.targets, strict=True):
            k = kernel.detach().cpu().numpy()
            y = target.detach().cpu().numpy()
            n = len(y)
            l2 = problems.l2
            start = time.perf_counter()
            x2 = np.concatenate([k, k])
            labels = np.concatenate([np.ones(n), np.zeros(n)])
            weight = np.concatenate([y, 1.0 - y])
            model = LogisticRegression(
                solver="newton-cholesky",
                C=np.inf if l2 == 0 else 1.0 / (l2 * n),
                fit_intercept=problems.bias,
                tol=NEWTON_TOL if tol is None else tol,
                max_iter=max_iter,
            )
            model.fit(x2, labels, sample_weight=weight)
            seconds += time.perf_counter() - start
            b = float(model.intercept_[0]) if problems.bias else 0.0
            solutions.append((model.coef_[0].copy(), b))
            iterations = max(iterations, int(np.max(model.n_iter_)))
        converged = not any(issubclass(w.category, ConvergenceWarning) for w in caught)
    return PeerFit(solutions, seconds, iterations, converged)


def bench_fit(
    demos: Sequence[Demonstration], repeats: int = 3, seed: int = 0, lbfgs: bool = False
) -> dict[str, JsonValue]:
    """Fit ``klr`` (cpmp's defaults) on ``demos`` ``repeats`` times, timed against the peer.

    The peer is :func:`sklearn_peer` on the same kernel features.

    Returns ``klr``: ``fit_seconds`` (the predictor's Lightning fit: supports, kernels, Newton),
    ``sequencer_fit_seconds`` (all of :meth:`ConcurrentSequencer.fit`), ``solve_seconds``
    (the Newton solve alone on the kernels), each as min and median over the repeats, and the
    loss; ``sklearn``: its time, iterations and loss; ``ratio`` of the times (klr / sklearn,
    < 1: klr is faster) and the relative loss difference; with ``lbfgs`` the LBFGS fit too.
    """
    check_count("repeats", repeats)
    fits, totals, solves, peers = [], [], [], []
    for _ in range(repeats):
        start = time.perf_counter()
        seq = ConcurrentSequencer.fit(list(demos), "klr", seed=seed, logger=None)
        totals.append(time.perf_counter() - start)
        fits.append(float(seq.fit_summary.seconds))
    problems = node_kernels(seq, demos)
    for _ in range(repeats):
        solutions, seconds = newton_solve_all(problems)
        solves.append(seconds)
        peers.append(sklearn_peer(problems))
    klr_loss = problem_loss(problems, solutions)
    peer = peers[-1]
    peer_loss = problem_loss(problems, peer.solutions)
    peer_seconds = [p.seconds for p in peers]
    newton = seq.fit_summary.newton
    out: dict[str, JsonValue] = {
        "n_demos": len(demos),
        "n_features": int(demos[0].n_features),
        "n_heads": len(problems.kernels),
        "n_support_total": int(sum(k.shape[1] for k in problems.kernels)),
        "n_samples_total": int(sum(k.shape[0] for k in problems.kernels)),
        "repeats": repeats,
        "klr": {
            "fit_seconds": timing_stats(fits),
            "sequencer_fit_seconds": timing_stats(totals),
            "solve_seconds": timing_stats(solves),
            "loss": float(seq.fit_summary.loss),
            "solve_loss": klr_loss,
            "newton_iterations": None if newton is None else newton.iterations,
        },
        "sklearn": {
            "seconds": timing_stats(peer_seconds),
            "loss": peer_loss,
            "iterations": peer.iterations,
            "converged": peer.converged,
            "version": package_version("sklearn"),
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
            "fit_seconds": float(slow.fit_summary.seconds),
            "loss": float(slow.fit_summary.loss),
        }
    return out


def timing_stats(values: Sequence[float]) -> dict[str, float]:
    """``min`` and ``median`` of repeated timings [s]."""
    return {"min": float(min(values)), "median": float(statistics.median(values))}


# ------------------------------------------------------------------------------- scaling
def pad_features(demos: Sequence[Demonstration], d: int) -> list[Demonstration]:
    """``demos`` with constant zero columns appended up to ``d`` features.

    Path lengths, and so the support points, stay the same; the kernel's feature dimension grows
    (with ``feature_weighting=path`` the moving features' weights ``d · share`` grow with it).
    """
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
) -> dict[str, JsonValue]:
    """Fit time (``klr`` and the scikit-learn peer) and tick cost as demos and features grow.

    The training set grows (``demo_counts`` demonstrations of the synthetic relay task, padded to
    the smallest feature count) and as features grow (``feature_counts``, at the middle
    demonstration count). Each point: one fit, support count, samples, Newton solve and peer times
    [s], single and batched tick cost [ms per episode-tick].
    """
    base_d = min(feature_counts)
    base_n = sorted(demo_counts)[len(demo_counts) // 2]
    pool = make_demonstrations(max(max(demo_counts), base_n) + batch, seed=seed)
    held_out = pool[-batch:]

    def point(n: int, d: int) -> dict[str, JsonValue]:
        demos = pad_features(pool[:n], d)
        seq, row = _fit_point(demos, seed)
        streams = [demo.features for demo in pad_features(held_out, d)]
        tick = bench_ticks(seq, streams, ticks)
        row.update(
            n_demos=n,
            n_features=d,
            tick_single_ms=tick["single_ms"],
            tick_batched_ms=tick["batched_ms"],
        )
        return row

    return {
        "task": "synthetic relay (cpmp.worlds.relay.world), features padded with zero columns",
        "batch": batch,
        "ticks": ticks,
        "demos": [point(n, base_d) for n in sorted(demo_counts)],
        "demos_at_features": base_d,
        "features": [point(base_n, d) for d in sorted(feature_counts)],
        "features_at_demos": base_n,
    }


def _fit_point(
    demos: Sequence[Demonstration], seed: int
) -> tuple[ConcurrentSequencer, dict[str, JsonValue]]:
    """One scaling point: ``klr`` fitted on ``demos``, its Newton solve and the peer's, timed.

    Returns:
        The fitted sequencer and the point's row: ``fit_seconds``, ``solve_seconds`` and
        ``sklearn_seconds`` [s], ``n_support_total``, ``n_samples_total``.
    """
    seq = ConcurrentSequencer.fit(list(demos), "klr", seed=seed, logger=None)
    problems = node_kernels(seq, demos)
    _, solve = newton_solve_all(problems)
    peer = sklearn_peer(problems)
    return seq, {
        "fit_seconds": float(seq.fit_summary.seconds),
        "solve_seconds": solve,
        "sklearn_seconds": peer.seconds,
        "n_support_total": int(sum(k.shape[1] for k in problems.kernels)),
        "n_samples_total": int(sum(k.shape[0] for k in problems.kernels)),
    }
