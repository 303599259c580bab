"""The main job, stage by stage: collect each seed's demonstrations
(:mod:`~cpmp.experiment.collection`), then per training size D fit
(:mod:`~cpmp.experiment.fitting`), evaluate offline
(:func:`cpmp.evaluation.offline.evaluate_offline`), reproduce
(:mod:`~cpmp.experiment.reproduction`) and draw the strategy map
(:mod:`~cpmp.experiment.strategies`); pool the seeds and write the report
(:mod:`~cpmp.experiment.report`). With ``experiment.workers > 1`` the seeds and training sizes run
on a process pool (:mod:`~cpmp.experiment.workers`).
"""

from __future__ import annotations

import logging
import time
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np

from cpmp.evaluation.offline import evaluate_offline
from cpmp.experiment.collection import SeedData, collect_seed
from cpmp.experiment.config import experiment_job
from cpmp.experiment.console import timed
from cpmp.experiment.fitting import train_sequencer
from cpmp.experiment.report import (
    experiment_files,
    pool_seeds,
    write_figures,
    write_json,
    write_report,
    write_timings,
)
from cpmp.experiment.reproduction import reproduce_seed, summarize_episodes
from cpmp.experiment.settings import ExperimentJob
from cpmp.experiment.strategies import balanced_subset, strategy_map
from cpmp.experiment.workers import default_workers, run_parallel

log = logging.getLogger(__name__)


def run_experiment(cfg: Any, run_dir: str | Path) -> Path:
    """Collect demos in the simulator, train on D = train_sizes, evaluate progress prediction,
    reproduction (Table I) and the strategy map; write the report. Returns ``report.json``.

    Each seed's collection and each (seed, D) training size is a job; with
    ``experiment.workers > 1`` they run in that many worker processes (one torch thread
    each, logs prefixed with their seed and D), and every number in the report is the same as
    in a serial run. ``timings.json`` holds the wall time of every stage.

    A config with a ``compare`` node (``experiment=compare``) runs
    :func:`cpmp.compare.job.run_compare` instead and returns ``compare.json``.
    """
    if cfg.get("compare") is not None:
        from cpmp.compare.job import run_compare

        return run_compare(cfg, run_dir)
    run_dir = Path(run_dir)
    job = experiment_job(cfg)
    settings = job.settings
    started = time.perf_counter()
    workers = settings.workers or default_workers(len(settings.seeds))
    workers = min(workers, len(settings.seeds) * len(settings.train_sizes))
    if workers > 1:
        log.info("running seeds %s on %d worker processes", settings.seeds, workers)
        collected, results = run_parallel(job, run_dir, workers, collect_seed, run_train_size)
    else:
        collected, results = _run_serial(job, run_dir)
    per_seed, pairs_by_d, episodes, stage_seconds = _gather(job, collected, results)

    files = experiment_files(job)
    first = results[settings.seeds[0], max(settings.train_sizes)]
    with timed(stage_seconds, "plots", "plots"):
        smap = {**first["strategy_map"], "train_boxes": first["train_boxes"]}
        files.update(write_figures(job, run_dir, pairs_by_d, smap))
    write_json(run_dir / "episodes.json", episodes)
    report = pool_seeds(job, per_seed)
    report["files"] = files
    report["seconds"] = time.perf_counter() - started
    write_timings(run_dir, report["seconds"], workers, stage_seconds)
    return write_report(report, run_dir)


def run_train_size(
    job: ExperimentJob | Any, run_dir: str | Path, data: SeedData, d: int
) -> dict[str, Any]:
    """Stage 2 of one seed and training size ``d``: train (``seed_<s>/model_D<d>.pt``), evaluate
    progress offline, reproduce the boxes closed-loop and, at the largest D, the strategy map.

    Returns ``row`` (the report's per-seed numbers), ``pairs`` (Fig. 6 ``(expected,
    predicted)`` arrays), ``episodes`` (dicts), ``strategy_map`` (or ``None``), ``train_boxes``
    ((width, depth) of the training demos) and ``seconds`` per stage. ``job``: the typed job
    (or its composed config, converted here).
    """
    job = experiment_job(job)
    settings, task, kind = job.settings, job.task, job.fit.predictor
    seed = data.seed
    seed_dir = Path(run_dir) / f"seed_{seed}"
    seed_dir.mkdir(parents=True, exist_ok=True)
    seconds: dict[str, float] = {}
    subset = balanced_subset(data.train, d)
    with timed(seconds, "train", f"seed {seed}: train {kind} on {d} demos"):
        log_dir = seed_dir / "lightning" / f"D{d}"
        seq = train_sequencer(subset, job.fit, seed, log_dir=log_dir, validation=data.test)
        seq.save(seed_dir / f"model_D{d}.pt")
    with timed(seconds, "evaluate", f"seed {seed}: evaluate progress (D={d})"):
        offline = evaluate_offline(seq, data.test)
    with timed(seconds, "reproduce", f"seed {seed}: reproduce {settings.n_boxes} boxes (D={d})"):
        episodes = reproduce_seed(
            seq,
            data,
            task,
            record_dir=seed_dir / "recordings",
            record=settings.record,
            max_time=settings.max_time,
            label=f"D{d}_",
        )
    row = {
        "progress": {k: offline["progress"][k] for k in ("mae", "mae_first", "mae_last")},
        "replay": {
            k: offline["replay"][k]
            for k in ("all_match", "sequence_match", "distance_mean", "distance_std")
        },
        "reproduction": summarize_episodes(episodes),
        "fit": {
            k: seq.fit_summary.get(k) for k in ("loss", "seconds", "n_support_total", "warnings")
        },
    }
    smap = None
    if d == max(settings.train_sizes):
        with timed(seconds, "strategy_map", f"seed {seed}: strategy map"):
            smap = strategy_map(seq, task, data.signatures, settings.strategy_grid)
        row["strategy_map_accuracy"] = smap["accuracy"]
    return {
        "row": row,
        "pairs": offline["pairs"],
        "episodes": [{"seed": seed, "D": d, **e.to_dict()} for e in episodes],
        "strategy_map": smap,
        "train_boxes": [(s.metadata["box_width"], s.metadata["box_depth"]) for s in subset],
        "seconds": seconds,
    }


def _run_serial(
    job: ExperimentJob, run_dir: Path
) -> tuple[dict[int, SeedData], dict[tuple[int, int], dict[str, Any]]]:
    """Every seed's collection and each of its training sizes in this process, in order."""
    collected: dict[int, SeedData] = {}
    results: dict[tuple[int, int], dict[str, Any]] = {}
    for seed in job.settings.seeds:
        collected[seed] = collect_seed(job, run_dir, seed)
        for d in job.settings.train_sizes:
            results[seed, d] = run_train_size(job, run_dir, collected[seed], d)
    return collected, results


def _gather(
    job: ExperimentJob,
    collected: dict[int, SeedData],
    results: dict[tuple[int, int], dict[str, Any]],
) -> tuple[
    list[dict[str, Any]],
    dict[int, list[tuple[np.ndarray, np.ndarray]]],
    list[dict[str, Any]],
    dict[str, float],
]:
    """The jobs' results in seed and D order: the per-seed rows, the Fig. 6 pairs by D, every
    episode, and the wall seconds per stage summed over seeds and training sizes.
    """
    per_seed: list[dict[str, Any]] = []
    pairs_by_d: dict[int, list[tuple[np.ndarray, np.ndarray]]] = defaultdict(list)
    episodes: list[dict[str, Any]] = []
    stage_seconds: dict[str, float] = defaultdict(float)
    for seed in job.settings.seeds:
        for key, value in collected[seed].seconds.items():
            stage_seconds[key] += value
        seed_row: dict[str, Any] = {"seed": seed, "by_train_size": {}}
        for d in job.settings.train_sizes:
            result = results[seed, d]
            pairs_by_d[d] += result["pairs"]
            episodes += result["episodes"]
            seed_row["by_train_size"][str(d)] = result["row"]
            for key, value in result["seconds"].items():
                stage_seconds[key] += value
        per_seed.append(seed_row)
    return per_seed, pairs_by_d, episodes, stage_seconds
