"""The jobs of the comparison (``cpmp-compare``) and their scheduler.

Per seed the demonstrations and the demonstrator's runs on the reproduction boxes are collected
once (:func:`cpmp.experiment.collection.collect_seed`); each (seed, row, D) is then one job
(:func:`run_row`): fit on the balanced subset of D training demos, progress MAE on the
held-out demos, mean ``step()`` time over one held-out demonstration replayed open loop, and
the closed-loop reproduction of every box. :func:`run_jobs` runs them serially or on spawned
worker processes; every job seeds itself and depends only on its own inputs, so the numbers do
not depend on the worker count or the order.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Mapping
from concurrent.futures import FIRST_COMPLETED, Future, wait
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

import torch
from omegaconf import OmegaConf

from cpmp.compare.rows import FitJob, RowSpec
from cpmp.config import TaskConfig
from cpmp.errors import CpmpError
from cpmp.evaluation.offline import activation_progress, progress_errors
from cpmp.experiment.collection import SeedData, collect_seed
from cpmp.experiment.fitting import fit_sequencer
from cpmp.experiment.reproduction import reproduce_seed, summarize_episodes
from cpmp.experiment.settings import ExperimentSettings, to_dict
from cpmp.experiment.strategies import balanced_subset
from cpmp.experiment.workers import spawned_pool

log = logging.getLogger(__name__)

_BY_TABLE_NAME = {"W": "wrong_start", "I": "incomplete", "C": "complete"}
"""The attributes of :class:`RowResult` that ``compare.json`` names as in Table I."""


@dataclass
class RowResult:
    """The numbers of one (seed, row, D) job (:func:`run_row`).

    A refused fit leaves every number ``None`` but ``fit_s`` (also ``None``) and says why in
    ``error``.

    Attributes:
        wrong_start: boxes whose episode started with the wrong strategy (W).
        incomplete: boxes not completed (I; diverged physics included).
        complete: boxes completed (C).
        diverged: of the incomplete, those whose physics diverged.
        mae: progress MAE on the held-out demonstrations, in [0, 1].
        fit_s: wall time of the fit [s].
        tick_ms: mean wall time of one ``step()`` [ms] (:func:`tick_ms`).
        supports: support points of all nodes (``None`` for a sequencer without them).
        error: the refused fit's error (``"ConfigError: ..."``), else ``None``.
        episodes: one summary dict per box (outcome, reason, chosen strategy, ...).
        seconds: wall time [s] per stage (``fit``, ``evaluate``, ``reproduce``).
        cpu_seconds: process time [s] per stage.
    """

    wrong_start: int | None = None
    incomplete: int | None = None
    complete: int | None = None
    diverged: int | None = None
    mae: float | None = None
    fit_s: float | None = None
    tick_ms: float | None = None
    supports: int | None = None
    error: str | None = None
    episodes: list[dict[str, Any]] = field(default_factory=list)
    seconds: dict[str, float] = field(default_factory=dict)
    cpu_seconds: dict[str, float] = field(default_factory=dict)

    def number(self, key: str) -> float | None:
        """The number ``compare.json`` calls ``key`` (``W``, ``I``, ``C``, ``mae``, ...)."""
        return getattr(self, _BY_TABLE_NAME.get(key, key))


class CompareRuns(NamedTuple):
    """What :func:`run_jobs` returns."""

    collected: dict[int, SeedData]
    """The collected data by seed."""
    results: dict[str, RowResult]
    """Each job's result by fit key."""


def _collect(cfg: dict[str, Any], run_dir: Path, seed: int) -> SeedData:
    """One seed's demonstrations and reproduction boxes (``cfg``: plain containers)."""
    return collect_seed(OmegaConf.create(cfg), run_dir, seed)


def tick_ms(seq: Any, demo: Any) -> float:
    """Mean wall time [ms] of one ``step()`` over ``demo``'s feature stream replayed open loop.

    The sequencer is ``reset`` on the demonstration's first sample first.
    """
    seq.reset(float(demo.time[0]), demo.features[0])
    elapsed = 0.0
    for t, x in zip(demo.time[1:], demo.features[1:], strict=True):
        start = time.perf_counter()
        seq.step(float(t), x)
        elapsed += time.perf_counter() - start
    return 1e3 * elapsed / max(len(demo.time) - 1, 1)


def run_row(cfg: Mapping[str, Any], spec: RowSpec, data: SeedData, d: int) -> RowResult:
    """One (seed, row, D) job: fit, progress MAE, tick time and closed-loop reproduction.

    Args:
        cfg: the job's composed config as plain containers.
        spec: the row.
        data: the seed's collected data.
        d: the training size.

    Returns:
        The row's numbers for this seed; a refused fit (a :class:`~cpmp.errors.CpmpError`)
        is a result with its ``error``.
    """
    torch.manual_seed(data.seed)  # fits draw from their own generators; this is a safety net
    settings = ExperimentSettings.from_cfg(cfg["experiment"])
    task = TaskConfig.from_dict(cfg["task"])
    trainer = {**to_dict(cfg.get("trainer")), "progress_bar": False}  # no log_dir: no logger
    out = RowResult()
    seconds, cpu = out.seconds, out.cpu_seconds

    def timed(key: str, start: float, start_cpu: float) -> None:
        seconds[key] = time.perf_counter() - start
        cpu[key] = time.process_time() - start_cpu

    subset = balanced_subset(data.train, d)
    start, start_cpu = time.perf_counter(), time.process_time()
    try:
        seq = fit_sequencer(subset, spec.predictor_cfg, spec.sequencer_cfg, trainer, data.seed)
    except CpmpError as err:
        timed("fit", start, start_cpu)
        out.error = f"{type(err).__name__}: {err}"
        return out
    timed("fit", start, start_cpu)
    out.fit_s = seconds["fit"]
    out.supports = seq.fit_summary.get("n_support_total")
    start, start_cpu = time.perf_counter(), time.process_time()
    out.mae = progress_errors(activation_progress(seq, data.test))["mae"]
    out.tick_ms = tick_ms(seq, data.test[0])
    timed("evaluate", start, start_cpu)
    start, start_cpu = time.perf_counter(), time.process_time()
    episodes = reproduce_seed(
        seq,
        data,
        task,
        record="none",
        max_time=settings.max_time,
        label=f"seed {data.seed} D{d} {spec.label()}: ",
    )
    timed("reproduce", start, start_cpu)
    summary = summarize_episodes(episodes)
    out.wrong_start, out.incomplete, out.complete = summary["W"], summary["I"], summary["C"]
    out.diverged = summary["diverged"]
    out.episodes = [e.to_dict() for e in episodes]
    return out


# ----------------------------------------------------------------------------- scheduler
def _say(text: str) -> None:
    """A progress line (the Hydra entry points show the ``cpmp`` log on the console)."""
    log.info("%s", text)


def run_jobs(
    plain: dict[str, Any],
    run_dir: Path,
    settings: ExperimentSettings,
    jobs: Mapping[str, FitJob],
    workers: int,
    started: float,
) -> CompareRuns:
    """Collect every seed, then run its jobs, in this process or on spawned workers.

    With one worker everything runs serially in this process; else on ``workers`` spawned
    processes, each given the next job as it frees up: collections first, then the job
    expected to take longest (the same row and D of an earlier seed tells; rows not yet
    measured go first, largest D first). The order changes no number.

    Args:
        plain: the job's composed config as plain containers (what the workers get).
        run_dir: where each seed's ``seed_<s>/demos.h5`` goes.
        settings: the ``experiment`` group.
        jobs: fit key -> its job, one entry per fit (:func:`~cpmp.compare.rows.fit_jobs`).
        workers: worker processes (1: everything in this process).
        started: ``time.perf_counter()`` at the run's start (for the progress lines).

    Returns:
        The collected data by seed, and each job's :func:`run_row` result by fit key.
    """
    collected: dict[int, SeedData] = {}
    results: dict[str, RowResult] = {}
    order = {key: i for i, key in enumerate(sorted(jobs, key=lambda k: -jobs[k].d))}
    done = 0

    def report(key: str, result: RowResult) -> None:
        nonlocal done
        done += 1
        spec, seed, d = jobs[key]
        if result.error:
            what = f"refused: {result.error}"
        else:
            counts = f"{result.wrong_start}/{result.incomplete}/{result.complete}"
            what = (
                f"W/I/C {counts} of {settings.n_boxes}, "
                f"MAE {result.mae:.3f}, fit {result.fit_s:.1f} s, "
                f"tick {result.tick_ms:.2f} ms"
            )
        elapsed = time.perf_counter() - started
        _say(f"[{done}/{len(jobs)}] seed {seed} D={d} {spec.label()}: {what} ({elapsed:.0f} s)")

    def collected_now(seed: int) -> None:
        _say(f"seed {seed}: demonstrations collected ({time.perf_counter() - started:.0f} s)")

    if workers <= 1:
        for seed in settings.seeds:
            collected[seed] = _collect(plain, run_dir, seed)
            collected_now(seed)
            for key in sorted((k for k in jobs if jobs[k].seed == seed), key=order.__getitem__):
                spec, _, d = jobs[key]
                results[key] = run_row(plain, spec, collected[seed], d)
                report(key, results[key])
        return CompareRuns(collected, results)

    def identity(key: str) -> tuple[Any, ...]:
        spec, _, d = jobs[key]
        return (spec.group, spec.predictor, spec.sequencer, spec.support_scale, d)

    measured: dict[tuple[Any, ...], float] = {}
    seeds = list(settings.seeds)
    ready: list[str] = []

    def next_job() -> tuple[str, Any] | None:
        if seeds:
            return "collect", seeds.pop(0)
        if not ready:
            return None
        key = min(ready, key=lambda k: (-measured.get(identity(k), math.inf), order[k]))
        ready.remove(key)
        return "row", key

    pending: dict[Future, tuple[str, Any]] = {}
    with spawned_pool(workers) as pool:

        def fill() -> None:
            while len(pending) < workers and (job := next_job()) is not None:
                what, key = job
                if what == "collect":
                    future = pool.submit(_collect, plain, run_dir, key)
                else:
                    spec, seed, d = jobs[key]
                    future = pool.submit(run_row, plain, spec, collected[seed], d)
                pending[future] = job

        fill()
        while pending:
            finished, _ = wait(pending, return_when=FIRST_COMPLETED)
            for future in sorted(finished, key=lambda f: str(pending[f])):
                what, key = pending.pop(future)
                if what == "row":
                    results[key] = future.result()
                    measured.setdefault(identity(key), sum(results[key].seconds.values()))
                    report(key, results[key])
                    continue
                collected[key] = future.result()
                collected_now(key)
                ready.extend(k for k in jobs if jobs[k].seed == key)
            fill()
    return CompareRuns(collected, results)
