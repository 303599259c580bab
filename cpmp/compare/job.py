"""``experiment=compare``: every progress predictor and the ``goal_nearest`` baseline on the same
demonstrations, seeds and boxes, plus a support-density sweep of one predictor.

Rows (``compare.json``, one per predictor/sequencer/D, support scale for the sweep):

* ``predictors``: every option of the ``predictor`` config group (and any registered predictor
  kind no option uses, with its built-in defaults), each with its default options, run with the
  job's ``sequencer``;
* ``baselines``: each listed ``sequencer`` option that needs no predictor (``goal_nearest``);
* ``support_sweep``: ``compare.sweep.predictor`` at each ``compare.sweep.support_scale``, at the
  training sizes ``compare.sweep.train_sizes`` (default: the largest D).

This module chooses the rows (:func:`row_specs`, from the ``compare`` node,
:class:`~cpmp.compare.settings.CompareSettings`) and runs them
(:func:`run_compare`). Per seed the demonstrations and the demonstrator's runs on the
reproduction boxes are collected once and every row uses them; each (seed, row, D) is one job
(:mod:`cpmp.compare.runs`: fit, progress MAE, tick time, closed-loop reproduction),
run on ``experiment.workers`` spawned processes (``null``: one per core). Every job seeds
itself and depends only on its own inputs, so the numbers do not depend on the worker count.
:mod:`cpmp.compare.report` pools the seeds and writes the table and figures.
"""

from __future__ import annotations

import json
import logging
import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from cpmp.compare.settings import CompareSettings
from cpmp.errors import ConfigError
from cpmp.experiment.config import to_dict
from cpmp.experiment.settings import ExperimentSettings

log = logging.getLogger(__name__)

NO_PREDICTOR = "none"
"""The ``predictor`` of a baseline row that uses no progress predictor."""

OUTPUT_FILES = (
    "compare.json",
    "compare.md",
    "compare_c_vs_d.png",
    "compare_supports.png",
    "episodes.json",
    "timings.json",
)
"""The files :func:`run_compare` writes into its run directory (besides ``seed_<s>/``)."""

_CONF_DIR = Path(__file__).resolve().parents[2] / "conf"


@dataclass(frozen=True)
class RowSpec:
    """One compared configuration.

    Attributes:
        group: ``predictors``, ``baselines`` or ``support_sweep``.
        predictor: ``predictor`` option name (:data:`NO_PREDICTOR` for a baseline).
        sequencer: ``sequencer`` option name.
        predictor_cfg: the predictor options (with ``kind``).
        sequencer_cfg: the sequencer options.
        train_sizes: the training sizes D this row runs at.
        support_scale: the swept value (sweep rows only).
    """

    group: str
    predictor: str
    sequencer: str
    predictor_cfg: Mapping[str, Any]
    sequencer_cfg: Mapping[str, Any]
    train_sizes: tuple[int, ...]
    support_scale: float | None = None

    def fit_key(self, seed: int, d: int) -> str:
        """Identifies the fit and evaluation this row needs at ``(seed, d)``: rows with equal
        keys (the sweep's point at the default scale) share one job.
        """
        options = {
            "predictor": dict(self.predictor_cfg) if self.predictor != NO_PREDICTOR else None,
            "sequencer": dict(self.sequencer_cfg),
        }
        return json.dumps({"seed": seed, "D": d, **options}, sort_keys=True, default=str)

    def label(self) -> str:
        scale = "" if self.support_scale is None else f" support_scale={self.support_scale:g}"
        return f"{self.predictor} + {self.sequencer}{scale}"


# --------------------------------------------------------------------------- config groups
def group_options(group: str) -> dict[str, dict[str, Any]]:
    """Every option of config group ``group`` (``predictor``, ``sequencer``) composed with its
    defaults, by name, from the running Hydra app's search path (or ``conf/`` outside one).
    """
    from hydra import compose, initialize_config_dir
    from hydra.core.global_hydra import GlobalHydra

    def compose_all() -> dict[str, dict[str, Any]]:
        loader = GlobalHydra.instance().config_loader()
        names = loader.get_group_options(group)
        return {
            name: to_dict(compose(config_name="experiment", overrides=[f"{group}={name}"])[group])
            for name in names
        }

    if GlobalHydra.instance().is_initialized():
        return compose_all()
    with initialize_config_dir(config_dir=str(_CONF_DIR), version_base="1.3"):
        return compose_all()


def option_name(options: Mapping[str, Any], group: Mapping[str, Mapping[str, Any]]) -> str:
    """The name of the group option equal to ``options`` (``custom`` if none is)."""
    return next((name for name, value in group.items() if dict(value) == dict(options)), "custom")


def row_specs(cfg: Any, settings: ExperimentSettings, compare: CompareSettings) -> list[RowSpec]:
    """The compared configurations, in report order (checked now, before any long work)."""
    from cpmp.config.goal_nearest import KIND, goal_nearest_options
    from cpmp.experiment.config import predictor_options
    from cpmp.predictors import PREDICTORS

    predictors = group_options("predictor")
    sequencers = group_options("sequencer")
    sequencer_cfg = to_dict(cfg.get("sequencer"))
    if sequencer_cfg.get("kind") == KIND:
        raise ConfigError(
            "experiment=compare runs the predictors with the job's sequencer, which must be a "
            "learned one (e.g. sequencer=coupled); goal_nearest is listed in compare.baselines"
        )
    sequencer = option_name(sequencer_cfg, sequencers)
    sizes = tuple(settings.train_sizes)
    if compare.predictors == "all":
        names = sorted(predictors)
        kinds = {options.get("kind") for options in predictors.values()}
        chosen = {name: predictors[name] for name in names}
        chosen.update({kind: {"kind": kind} for kind in PREDICTORS if kind not in kinds})
    else:
        missing = [n for n in compare.predictors if n not in predictors]
        if missing:
            raise ConfigError(
                f"compare.predictors names unknown predictor option(s) {', '.join(missing)}; "
                f"choose from {', '.join(sorted(predictors))}"
            )
        chosen = {name: predictors[name] for name in compare.predictors}
    specs = []
    for name, options in chosen.items():
        predictor_options(options)
        specs.append(RowSpec("predictors", name, sequencer, options, sequencer_cfg, sizes))
    for name in compare.baselines:
        options = sequencers.get(name)
        if options is None or options.get("kind") != KIND:
            raise ConfigError(
                f"compare.baselines: {name!r} is not a sequencer option of kind {KIND!r}; "
                f"options of that kind: "
                f"{', '.join(n for n, o in sequencers.items() if o.get('kind') == KIND)}"
            )
        goal_nearest_options({k: v for k, v in options.items() if k != "kind"})
        specs.append(RowSpec("baselines", NO_PREDICTOR, name, {}, options, sizes))
    sweep = compare.sweep
    if sweep.support_scale:
        base = predictors.get(sweep.predictor)
        if base is None or "support_scale" not in base:
            raise ConfigError(
                f"compare.sweep.predictor must be a predictor option with support points "
                f"(support_scale), got {sweep.predictor!r}"
            )
        for scale in sweep.support_scale:
            options = {**base, "support_scale": float(scale)}
            predictor_options(options)
            specs.append(
                RowSpec(
                    "support_sweep",
                    sweep.predictor,
                    sequencer,
                    options,
                    sequencer_cfg,
                    tuple(sweep.train_sizes or ()),
                    float(scale),
                )
            )
    return specs


def run_compare(cfg: Any, run_dir: str | Path) -> Path:
    """Run the comparison (see the module doc); writes ``compare.json``, ``compare.md``,
    ``compare_c_vs_d.png``, ``compare_supports.png``, ``episodes.json`` and ``timings.json``
    into ``run_dir`` (plus ``seed_<s>/demos.h5``). Returns the path of ``compare.json``.
    """
    from omegaconf import DictConfig, ListConfig, OmegaConf

    from cpmp.compare.report import (
        aggregate_rows,
        job_episodes,
        job_timings,
        plot_c_vs_d,
        plot_supports,
        render_compare,
    )
    from cpmp.compare.runs import run_jobs
    from cpmp.config import TaskConfig
    from cpmp.experiment.report import write_json
    from cpmp.experiment.workers import default_workers
    from cpmp.io import atomic_write_text

    started = time.perf_counter()
    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    settings = ExperimentSettings.from_cfg(cfg.experiment)
    TaskConfig.from_dict(cfg.task)
    compare = CompareSettings.from_cfg(cfg.get("compare"), settings.train_sizes)
    specs = row_specs(cfg, settings, compare)
    plain = {
        key: OmegaConf.to_container(value, resolve=True)
        if isinstance(value, (DictConfig, ListConfig))
        else value
        for key, value in cfg.items()
        if key != "hydra"
    }
    jobs: dict[str, tuple[RowSpec, int, int]] = {}
    for spec in specs:
        for seed in settings.seeds:
            for d in spec.train_sizes:
                jobs.setdefault(spec.fit_key(seed, d), (spec, seed, d))
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
