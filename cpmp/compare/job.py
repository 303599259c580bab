"""The comparison's job (``cpmp-compare``): predictors and baselines in several worlds.

In every world of ``compare.worlds`` (:mod:`cpmp.compare.worlds`: the simulator and its
harder variants, the synthetic worlds) the rows (:mod:`cpmp.compare.rows`: predictors, the
``goal_nearest`` baseline, the support-count axis) run on the same demonstrations, seeds and
episodes. Each (world, seed, row, D) is one job (:mod:`cpmp.compare.runs`: fit, progress MAE,
tick time, closed loop), run by the executor ``experiment.executor`` names
(:mod:`cpmp.experiment.executors`: ``local``, ``experiment.workers`` spawned processes, ``null``:
one per core; ``inline``; ``submitit``: local processes or SLURM jobs). Every job seeds itself
and depends only on its own inputs, so the numbers do not depend on the executor or the worker
count. :mod:`cpmp.compare.pooling` pools the seeds with bootstrap intervals
(:mod:`cpmp.compare.stats`) and tests the differences; :mod:`cpmp.compare.report` and
:mod:`cpmp.compare.figures` write the table and figures.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path

from omegaconf import DictConfig, ListConfig, OmegaConf

from cpmp.compare.figures import plot_c_vs_d, plot_claims, plot_supports
from cpmp.compare.pooling import pool
from cpmp.compare.report import job_episodes, job_timings, render_compare
from cpmp.compare.rows import fit_jobs, row_specs
from cpmp.compare.runs import run_jobs
from cpmp.compare.settings import CompareJob
from cpmp.compare.stats import BootstrapOptions
from cpmp.experiment.executors import job_slots, make_executor
from cpmp.experiment.output import write_json
from cpmp.io import atomic_write_text

log = logging.getLogger(__name__)

OUTPUT_FILES = (
    "compare.json",
    "compare.md",
    "compare_c_vs_d.png",
    "compare_claims.png",
    "compare_supports.png",
    "episodes.json",
    "timings.json",
)
"""The files :func:`run_compare` writes into its run directory (besides ``<world>/seed_<s>/``)."""


def run_compare(cfg: DictConfig, run_dir: str | Path) -> Path:
    """Run the comparison (see the module doc); returns the path of ``compare.json``.

    Writes :data:`OUTPUT_FILES` into ``run_dir`` (plus ``<world>/seed_<s>/demos.h5`` of the
    simulated worlds).

    Raises:
        ConfigError: a bad option (checked before any long work).
    """
    started = time.perf_counter()
    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    job = CompareJob.from_cfg(cfg)
    specs = row_specs(cfg, job)
    worlds = {w.name: w for w in job.worlds}
    plain = {
        key: OmegaConf.to_container(value, resolve=True)
        if isinstance(value, (DictConfig, ListConfig))
        else value
        for key, value in cfg.items()
        if key != "hydra"
    }
    jobs = fit_jobs(specs, worlds)
    tasks = len(jobs) + sum(len(w.seeds) for w in job.worlds if w.kind == "sim")
    name = job.settings.executor
    workers = job_slots(name, job.executor, job.settings.workers, tasks)
    log.info(
        "compare: %d rows in %d world(s) (%s), %d fits, %s executor, %d at once",
        len(specs),
        len(worlds),
        ", ".join(worlds),
        len(jobs),
        name,
        workers,
    )
    with make_executor(name, job.executor, workers) as executor:
        collected, results = run_jobs(plain, run_dir, worlds, jobs, executor, started)
    stats = job.compare.stats
    result = pool(
        specs,
        worlds,
        results,
        job.compare.claims,
        BootstrapOptions(stats.samples, stats.level, stats.seed),
        reference=job.compare.sweep.predictor,
    )
    seconds = time.perf_counter() - started
    write_json(
        run_dir / "timings.json", job_timings(collected, results, jobs, seconds, workers, name)
    )
    write_json(run_dir / "episodes.json", job_episodes(results, jobs))
    path = write_json(run_dir / "compare.json", result)
    plot_c_vs_d(result, run_dir / "compare_c_vs_d.png")
    plot_claims(result, run_dir / "compare_claims.png")
    plot_supports(result["rows"], run_dir / "compare_supports.png")
    text = render_compare(result, job.settings.name, seconds, workers)
    atomic_write_text(run_dir / "compare.md", text)
    log.info("compare: done in %.1f min", seconds / 60)
    return path
