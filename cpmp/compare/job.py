"""The comparison's job (``cpmp-compare``): every predictor and baseline on the same data.

Every progress predictor and the ``goal_nearest`` baseline run on the same demonstrations,
seeds and boxes, plus a support-density sweep of one predictor; :mod:`cpmp.compare.rows` says
which rows. Per seed the demonstrations and the demonstrator's runs on the reproduction boxes
are collected once and every row uses them; each (seed, row, D) is one job
(:mod:`cpmp.compare.runs`: fit, progress MAE, tick time, closed-loop reproduction), run on
``experiment.workers`` spawned processes (``null``: one per core). Every job seeds itself and
depends only on its own inputs, so the numbers do not depend on the worker count.
:mod:`cpmp.compare.report` pools the seeds and writes the table and figures.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, ListConfig, OmegaConf

from cpmp.compare.report import (
    aggregate_rows,
    job_episodes,
    job_timings,
    plot_c_vs_d,
    plot_supports,
    render_compare,
)
from cpmp.compare.rows import fit_jobs, row_specs
from cpmp.compare.runs import run_jobs
from cpmp.compare.settings import CompareJob
from cpmp.experiment.output import write_json
from cpmp.experiment.workers import default_workers
from cpmp.io import atomic_write_text

log = logging.getLogger(__name__)

OUTPUT_FILES = (
    "compare.json",
    "compare.md",
    "compare_c_vs_d.png",
    "compare_supports.png",
    "episodes.json",
    "timings.json",
)
"""The files :func:`run_compare` writes into its run directory (besides ``seed_<s>/``)."""


def run_compare(cfg: Any, run_dir: str | Path) -> Path:
    """Run the comparison (see the module doc); returns the path of ``compare.json``.

    Writes :data:`OUTPUT_FILES` into ``run_dir`` (plus ``seed_<s>/demos.h5``).

    Raises:
        ConfigError: a bad option (checked before any long work).
    """
    started = time.perf_counter()
    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    job = CompareJob.from_cfg(cfg)
    settings = job.settings
    specs = row_specs(cfg, settings, job.compare)
    plain = {
        key: OmegaConf.to_container(value, resolve=True)
        if isinstance(value, (DictConfig, ListConfig))
        else value
        for key, value in cfg.items()
        if key != "hydra"
    }
    jobs = fit_jobs(specs, settings.seeds)
    tasks = len(jobs) + len(settings.seeds)
    workers = min(settings.workers or default_workers(tasks), tasks)
    log.info(
        "compare: %d rows, %d fits over seeds %s and D = %s, %d boxes each, %d worker(s)",
        len(specs),
        len(jobs),
        settings.seeds,
        settings.train_sizes,
        settings.n_boxes,
        workers,
    )
    collected, results = run_jobs(plain, run_dir, settings, jobs, workers, started)
    rows = aggregate_rows(specs, settings, results)
    seconds = time.perf_counter() - started
    timings = job_timings(collected, results, jobs, seconds, workers)
    write_json(run_dir / "timings.json", timings)
    write_json(run_dir / "episodes.json", job_episodes(results, jobs))
    path = write_json(run_dir / "compare.json", rows)
    plot_c_vs_d(rows, settings, run_dir / "compare_c_vs_d.png")
    plot_supports(rows, settings, run_dir / "compare_supports.png")
    atomic_write_text(run_dir / "compare.md", render_compare(rows, settings, seconds, workers))
    log.info("compare: done in %.1f min", seconds / 60)
    return path
