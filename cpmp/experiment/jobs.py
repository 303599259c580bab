"""The main job (``cpmp-experiment``), stage by stage.

Collect each seed's demonstrations (:mod:`~cpmp.experiment.collection`), then per training
size D fit
(:mod:`~cpmp.experiment.fitting`), evaluate offline
(:func:`cpmp.evaluation.offline.evaluate_offline`), reproduce
(:mod:`~cpmp.experiment.reproduction`) and draw the strategy map
(:mod:`~cpmp.experiment.strategies`); pool the seeds and write the report
(:mod:`~cpmp.experiment.report`). Each seed's collection and each (seed, D) training size is a
job, run by the executor ``experiment.executor`` names (:mod:`~cpmp.experiment.executors`:
this process, spawned worker processes, or submitit's local processes or SLURM jobs).
"""

from __future__ import annotations

import logging
import time
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

import numpy as np
from omegaconf import DictConfig

from cpmp.evaluation.offline import evaluate_offline
from cpmp.experiment.collection import SeedData, collect_seed
from cpmp.experiment.config import experiment_job
from cpmp.experiment.console import timed
from cpmp.experiment.executors import JobExecutor, Submission, job_slots, make_executor, run_queue
from cpmp.experiment.fitting import train_sequencer
from cpmp.experiment.report import (
    SeedRow,
    TrainSizeRow,
    experiment_files,
    pool_seeds,
    write_figures,
    write_json,
    write_report,
    write_timings,
)
from cpmp.experiment.reproduction import reproduce_seed, summarize_episodes
from cpmp.experiment.settings import ExperimentJob
from cpmp.experiment.strategies import StrategyMap, balanced_subset, strategy_map

log = logging.getLogger(__name__)


class JobResults(NamedTuple):
    """What the main job's stages gave: each seed's collection and each training size's result."""

    collected: dict[int, SeedData]
    """What the collection returned, by seed."""
    results: dict[tuple[int, int], TrainSizeResult]
    """What each training size returned, by (seed, D)."""


@dataclass
class TrainSizeResult:
    """What one seed and training size D gives the report (:func:`run_train_size`).

    Attributes:
        row: the report's per-seed numbers at D (``progress``, ``replay``, ``reproduction``,
            ``fit``, and at the largest D ``strategy_map_accuracy``).
        pairs: Fig. 6's ``(expected (n,), predicted (n,))`` progress per held-out activation.
        episodes: one dict per reproduction episode, with its seed and D.
        strategy_map: the strategy map (at the largest D only, else ``None``).
        train_boxes: (width, depth) [m] of the training demonstrations.
        seconds: wall time [s] per stage.
    """

    row: TrainSizeRow
    pairs: list[tuple[np.ndarray, np.ndarray]]
    episodes: list[dict[str, object]]
    strategy_map: StrategyMap | None
    train_boxes: list[tuple[float, float]]
    seconds: dict[str, float] = field(default_factory=dict)


@dataclass
class _Gathered:
    """The jobs' results in seed and D order (:func:`_gather`).

    Attributes:
        per_seed: the report's per-seed rows.
        pairs_by_d: the Fig. 6 pairs by D.
        episodes: every episode.
        stage_seconds: wall seconds per stage, summed over seeds and training sizes.
    """

    per_seed: list[SeedRow]
    pairs_by_d: dict[int, list[tuple[np.ndarray, np.ndarray]]]
    episodes: list[dict[str, object]]
    stage_seconds: dict[str, float]


def run_experiment(cfg: DictConfig, run_dir: str | Path) -> Path:
    """Run the main job; returns the path of ``report.json``.

    Collect demos in the simulator, train on D = train_sizes, evaluate progress prediction,
    reproduction (Table I) and the strategy map; write the report.

    Each seed's collection and each (seed, D) training size is a job, run by the executor of
    ``experiment.executor`` (``local``: ``experiment.workers`` spawned processes, one torch
    thread each, logs prefixed with their seed and D; ``inline``: this process; ``submitit``:
    submitit jobs); every number in the report is the same on each. ``timings.json`` holds the
    wall time of every stage.
    """
    run_dir = Path(run_dir)
    job = experiment_job(cfg)
    settings = job.settings
    started = time.perf_counter()
    n_jobs = len(settings.seeds) * len(settings.train_sizes)
    name = settings.executor
    workers = job_slots(name, job.executor, settings.workers, n_jobs, len(settings.seeds))
    if workers > 1 or name != "local":
        log.info("running seeds %s on the %s executor, %d at once", settings.seeds, name, workers)
    with make_executor(name, job.executor, workers) as executor:
        ran = run_jobs(job, run_dir, executor)
    gathered = _gather(job, ran)

    files = experiment_files(job)
    first = ran.results[settings.seeds[0], max(settings.train_sizes)]
    assert first.strategy_map is not None  # drawn at the largest D
    with timed(gathered.stage_seconds, "plots", "plots"):
        figures = write_figures(
            job, run_dir, gathered.pairs_by_d, first.strategy_map, first.train_boxes
        )
        files.update(figures)
    write_json(run_dir / "episodes.json", gathered.episodes)
    report = pool_seeds(job, gathered.per_seed)
    report["files"] = files
    report["seconds"] = time.perf_counter() - started
    write_timings(run_dir, report["seconds"], workers, gathered.stage_seconds, name)
    return write_report(report, run_dir)


def run_train_size(
    job: ExperimentJob | DictConfig, run_dir: str | Path, data: SeedData, d: int
) -> TrainSizeResult:
    """Stage 2 of one seed and training size ``d``: train, evaluate, reproduce, map.

    Train (``seed_<s>/model_D<d>.pt``), evaluate progress offline, reproduce the boxes
    closed-loop and, at the largest D, draw the strategy map.

    Args:
        job: the typed job (or its composed config, converted here).
        run_dir: the run directory.
        data: the seed's collected data.
        d: the training size.
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
            train=subset,
        )
    fit = {} if seq.fit_summary is None else seq.fit_summary.to_dict()
    row: TrainSizeRow = {
        "progress": {k: offline["progress"][k] for k in ("mae", "mae_first", "mae_last")},
        "replay": {
            k: offline["replay"][k]
            for k in ("all_match", "sequence_match", "distance_mean", "distance_std")
        },
        "reproduction": summarize_episodes(episodes),
        "fit": {k: fit.get(k) for k in ("loss", "seconds", "n_support_total", "warnings")},
    }
    smap = None
    if d == max(settings.train_sizes):
        with timed(seconds, "strategy_map", f"seed {seed}: strategy map"):
            smap = strategy_map(seq, task, data.signatures, settings.strategy_grid)
        row["strategy_map_accuracy"] = smap.accuracy
    return TrainSizeResult(
        row=row,
        pairs=offline["pairs"],
        episodes=[{"seed": seed, "D": d, **e.to_dict()} for e in episodes],
        strategy_map=smap,
        train_boxes=[(s.metadata["box_width"], s.metadata["box_depth"]) for s in subset],
        seconds=seconds,
    )


def run_jobs(job: ExperimentJob, run_dir: Path, executor: JobExecutor) -> JobResults:
    """Every seed's collection, then each of its training sizes, on ``executor``.

    The collections are queued first; a seed's training sizes are queued, largest first, as
    soon as its collection is done. ``executor.slots`` jobs run at once.

    Args:
        job: the typed job.
        run_dir: the run directory.
        executor: an entered executor.

    Returns:
        The collections by seed and the results by (seed, D).
    """
    settings = job.settings
    ran = JobResults({}, {})
    queue = [
        Submission((seed, None), collect_seed, (job, run_dir, seed), f"seed {seed}")
        for seed in settings.seeds
    ]

    def finished(key: tuple[int, int | None], result: SeedData | TrainSizeResult) -> None:
        seed, d = key
        if d is not None:
            assert isinstance(result, TrainSizeResult)  # a training size's job
            ran.results[seed, d] = result
            return
        assert isinstance(result, SeedData)  # a collection job
        ran.collected[seed] = result
        for size in sorted(settings.train_sizes, reverse=True):
            args = (job, run_dir, result, size)
            queue.append(Submission((seed, size), run_train_size, args, f"seed {seed} D={size}"))

    run_queue(executor, lambda: queue.pop(0) if queue else None, finished)
    return ran


def _gather(job: ExperimentJob, ran: JobResults) -> _Gathered:
    """The jobs' results in seed and D order, with the wall seconds per stage summed."""
    collected, results = ran
    per_seed: list[SeedRow] = []
    pairs_by_d: dict[int, list[tuple[np.ndarray, np.ndarray]]] = defaultdict(list)
    episodes: list[dict[str, object]] = []
    stage_seconds: dict[str, float] = defaultdict(float)
    for seed in job.settings.seeds:
        for key, value in collected[seed].seconds.items():
            stage_seconds[key] += value
        seed_row: SeedRow = {"seed": seed, "by_train_size": {}}
        for d in job.settings.train_sizes:
            result = results[seed, d]
            pairs_by_d[d] += result.pairs
            episodes += result.episodes
            seed_row["by_train_size"][str(d)] = result.row
            for key, value in result.seconds.items():
                stage_seconds[key] += value
        per_seed.append(seed_row)
    return _Gathered(per_seed, pairs_by_d, episodes, stage_seconds)
