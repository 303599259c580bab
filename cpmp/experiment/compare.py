"""``experiment=compare``: every progress predictor and the ``goal_nearest`` baseline on the same
demonstrations, seeds and boxes, plus a support-density sweep of one predictor.

Rows (``compare.json``, one per predictor/sequencer/D, support scale for the sweep):

* ``predictors``: every option of the ``predictor`` config group (and any registered predictor
  kind no option uses, with its built-in defaults), each with its default options, run with the
  job's ``sequencer``;
* ``baselines``: each listed ``sequencer`` option that needs no predictor (``goal_nearest``);
* ``support_sweep``: ``compare.sweep.predictor`` at each ``compare.sweep.support_scale``, at the
  training sizes ``compare.sweep.train_sizes`` (default: the largest D).

Per seed the demonstrations and the demonstrator's runs on the reproduction boxes are collected
once (:func:`cpmp.experiment.jobs.collect_seed`) and every row uses them. Each (seed, row, D) is
one job: fit on the balanced subset of D training demos, progress MAE on the held-out demos,
mean ``step()`` time over one held-out demonstration replayed open loop, and the closed-loop
reproduction of every box (:func:`~cpmp.experiment.pipeline.reproduce`). Jobs run on
``experiment.workers`` spawned processes (``null``: one per core); every job seeds itself and
depends only on its own inputs, so the numbers do not depend on the worker count.
"""

from __future__ import annotations

import json
import logging
import math
import os
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from cpmp.errors import ConfigError, CpmpError
from cpmp.experiment.config import to_dict
from cpmp.experiment.pipeline import ExperimentSettings
from cpmp.experiment.report import PAPER_TABLE_I, jsonable, mean_std, write_json
from cpmp.io import atomic_path, atomic_write_text

if TYPE_CHECKING:
    from cpmp.experiment.jobs import SeedData

log = logging.getLogger(__name__)

ROW_FIELDS: tuple[str, ...] = (
    "predictor",
    "sequencer",
    "D",
    "mae",
    "W",
    "I",
    "C",
    "fit_s",
    "tick_ms",
    "supports",
)
"""Fields every row of ``compare.json`` has (``None`` where a number does not exist)."""

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


@dataclass
class CompareSettings:
    """The ``compare`` config node.

    Attributes:
        predictors: ``all`` (every ``predictor`` group option and every registered kind) or
            a list of ``predictor`` group option names.
        baselines: ``sequencer`` group options run without a predictor (``goal_nearest``).
        sweep_predictor: the ``predictor`` option whose ``support_scale`` is swept.
        support_scale: the swept values (support points per unit of L1 path length).
        sweep_train_sizes: the training sizes of the sweep (``None``: the largest D).
    """

    predictors: str | list[str] = "all"
    baselines: list[str] = field(default_factory=lambda: ["goal_nearest"])
    sweep_predictor: str = "klr"
    support_scale: list[float] = field(default_factory=list)
    sweep_train_sizes: list[int] | None = None

    @classmethod
    def from_cfg(cls, cfg: Any, train_sizes: Sequence[int]) -> CompareSettings:
        options = to_dict(cfg)
        sweep = to_dict(options.pop("sweep", None))
        known = {"predictors", "baselines"}
        unknown = sorted(set(options) - known) + [
            f"sweep.{k}" for k in sorted(set(sweep) - {"predictor", "support_scale", "train_sizes"})
        ]
        if unknown:
            raise ConfigError(
                f"unknown compare option(s) {', '.join(unknown)}; valid: predictors, baselines, "
                "sweep.predictor, sweep.support_scale, sweep.train_sizes"
            )
        out = cls(
            predictors=options.get("predictors", "all"),
            baselines=list(options.get("baselines") or []),
            sweep_predictor=str(sweep.get("predictor", "klr")),
            support_scale=list(sweep.get("support_scale") or []),
            sweep_train_sizes=sweep.get("train_sizes"),
        )
        if out.predictors != "all" and (not isinstance(out.predictors, list) or not out.predictors):
            raise ConfigError(
                f"compare.predictors must be 'all' or a non-empty list, got {out.predictors!r}"
            )
        for value in out.support_scale:
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not value > 0:
                raise ConfigError(
                    f"compare.sweep.support_scale must be numbers > 0, got {out.support_scale}"
                )
        if len(set(out.support_scale)) != len(out.support_scale):
            raise ConfigError(f"compare.sweep.support_scale has duplicates: {out.support_scale}")
        sizes = out.sweep_train_sizes
        if sizes is None:
            out.sweep_train_sizes = [max(train_sizes)]
        elif not isinstance(sizes, list) or any(d not in train_sizes for d in sizes):
            raise ConfigError(
                f"compare.sweep.train_sizes must be a list of experiment.train_sizes "
                f"{list(train_sizes)}, got {sizes!r}"
            )
        return out


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
        keys (the sweep's point at the default scale) share one job."""
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
    defaults, by name, from the running Hydra app's search path (or ``conf/`` outside one)."""
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
    from cpmp.experiment.config import predictor_options
    from cpmp.goal_nearest import KIND, goal_nearest_options
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
    if compare.support_scale:
        base = predictors.get(compare.sweep_predictor)
        if base is None or "support_scale" not in base:
            raise ConfigError(
                f"compare.sweep.predictor must be a predictor option with support points "
                f"(support_scale), got {compare.sweep_predictor!r}"
            )
        for scale in compare.support_scale:
            options = {**base, "support_scale": float(scale)}
            predictor_options(options)
            specs.append(
                RowSpec(
                    "support_sweep",
                    compare.sweep_predictor,
                    sequencer,
                    options,
                    sequencer_cfg,
                    tuple(compare.sweep_train_sizes or ()),
                    float(scale),
                )
            )
    return specs


# ---------------------------------------------------------------------------- worker jobs
def _init_worker() -> None:
    """Worker start-up: one torch thread (a second busy thread per process on a machine of
    few cores slows every process down)."""
    import torch

    torch.set_num_threads(1)


def _collect(cfg: dict[str, Any], run_dir: Path, seed: int) -> SeedData:
    from omegaconf import OmegaConf

    from cpmp.experiment.jobs import collect_seed

    return collect_seed(OmegaConf.create(cfg), run_dir, seed)


def tick_ms(seq: Any, demo: Any) -> float:
    """Mean wall time [ms] of one ``step()`` over ``demo``'s feature stream replayed open
    loop (after a ``reset`` on its first sample)."""
    seq.reset(float(demo.time[0]), demo.features[0])
    elapsed = 0.0
    for t, x in zip(demo.time[1:], demo.features[1:], strict=True):
        start = time.perf_counter()
        seq.step(float(t), x)
        elapsed += time.perf_counter() - start
    return 1e3 * elapsed / max(len(demo.time) - 1, 1)


def run_row(cfg: Mapping[str, Any], spec: RowSpec, data: SeedData, d: int) -> dict[str, Any]:
    """One (seed, row, D) job: fit, progress MAE, tick time and closed-loop reproduction.

    Returns the row's numbers for this seed (``W``, ``I``, ``C``, ``diverged``, ``mae``,
    ``fit_s``, ``tick_ms``, ``supports``), ``error`` (a refused fit: the numbers are
    ``None``), ``episodes`` (one summary dict per box: outcome, reason, chosen strategy, ...)
    and ``seconds`` / ``cpu_seconds`` per stage.
    """
    import torch

    from cpmp.evaluation import activation_progress, progress_errors
    from cpmp.experiment.pipeline import (
        balanced_subset,
        fit_sequencer,
        reproduce,
        summarize_episodes,
    )
    from cpmp.sim import TaskConfig

    torch.manual_seed(data.seed)  # fits draw from their own generators; this is a safety net
    settings = ExperimentSettings.from_cfg(cfg["experiment"])
    task = TaskConfig.from_dict(cfg["task"])
    trainer = {**to_dict(cfg.get("trainer")), "logger": None, "progress_bar": False}
    seconds: dict[str, float] = {}
    cpu: dict[str, float] = {}
    out: dict[str, Any] = {key: None for key in ("W", "I", "C", "diverged", "mae", "tick_ms")}
    out.update(error=None, episodes=[], seconds=seconds, cpu_seconds=cpu)

    def timed(key: str, start: float, start_cpu: float) -> None:
        seconds[key] = time.perf_counter() - start
        cpu[key] = time.process_time() - start_cpu

    subset = balanced_subset(data.train, d)
    start, start_cpu = time.perf_counter(), time.process_time()
    try:
        seq = fit_sequencer(subset, spec.predictor_cfg, spec.sequencer_cfg, trainer, data.seed)
    except CpmpError as err:
        timed("fit", start, start_cpu)
        out.update(error=f"{type(err).__name__}: {err}", fit_s=None, supports=None)
        return out
    timed("fit", start, start_cpu)
    out["fit_s"] = seconds["fit"]
    out["supports"] = seq.fit_summary.get("n_support_total")
    start, start_cpu = time.perf_counter(), time.process_time()
    out["mae"] = progress_errors(activation_progress(seq, data.test))["mae"]
    out["tick_ms"] = tick_ms(seq, data.test[0])
    timed("evaluate", start, start_cpu)
    start, start_cpu = time.perf_counter(), time.process_time()
    episodes = reproduce(
        seq,
        data.boxes,
        data.expected,
        task,
        data.signatures,
        record_dir=None,
        record="none",
        max_time=settings.max_time,
        label=f"seed {data.seed} D{d} {spec.label()}: ",
    )
    timed("reproduce", start, start_cpu)
    summary = summarize_episodes(episodes)
    out.update({k: summary[k] for k in ("W", "I", "C", "diverged")})
    out["episodes"] = [e.to_dict() for e in episodes]
    return out


# ----------------------------------------------------------------------------------- run
def _workers(settings: ExperimentSettings) -> int:
    if settings.workers:
        return int(settings.workers)
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def _say(text: str) -> None:
    """A progress line (the Hydra entry points show the ``cpmp`` log on the console)."""
    log.info("%s", text)


def run_compare(cfg: Any, run_dir: str | Path) -> Path:
    """Run the comparison (see the module doc); writes ``compare.json``, ``compare.md``,
    ``compare_c_vs_d.png``, ``compare_supports.png``, ``episodes.json`` and ``timings.json``
    into ``run_dir``
    (plus ``seed_<s>/demos.h5``). Returns the path of ``compare.json``."""
    from omegaconf import DictConfig, ListConfig, OmegaConf

    from cpmp.sim import TaskConfig

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
    workers = min(_workers(settings), len(jobs) + len(settings.seeds))
    _say(
        f"compare: {len(specs)} rows, {len(jobs)} fits over seeds {settings.seeds} and "
        f"D = {settings.train_sizes}, {settings.n_boxes} boxes each, {workers} worker(s)"
    )
    collected, results = _run_jobs(plain, run_dir, settings, jobs, workers, started)
    rows = aggregate_rows(specs, settings, results)
    seconds = time.perf_counter() - started
    timings = _timings(collected, results, jobs, seconds, workers)
    write_json(run_dir / "timings.json", timings)
    write_json(run_dir / "episodes.json", _episodes(results, jobs))
    path = write_json(run_dir / "compare.json", rows)
    plot_c_vs_d(rows, settings, run_dir / "compare_c_vs_d.png")
    plot_supports(rows, settings, run_dir / "compare_supports.png")
    atomic_write_text(run_dir / "compare.md", render_compare(rows, settings, seconds, workers))
    _say(f"compare: done in {seconds / 60:.1f} min")
    return path


def _run_jobs(
    plain: dict[str, Any],
    run_dir: Path,
    settings: ExperimentSettings,
    jobs: Mapping[str, tuple[RowSpec, int, int]],
    workers: int,
    started: float,
) -> tuple[dict[int, SeedData], dict[str, dict[str, Any]]]:
    """Collect every seed, then run its jobs; serially in this process with one worker, else
    on ``workers`` spawned processes, each given the next job as it frees up: collections
    first, then the job expected to take longest (the same row and D of an earlier seed tells;
    rows not yet measured go first, largest D first). The order changes no number."""
    collected: dict[int, SeedData] = {}
    results: dict[str, dict[str, Any]] = {}
    order = {key: i for i, key in enumerate(sorted(jobs, key=lambda k: -jobs[k][2]))}
    done = 0

    def report(key: str, result: dict[str, Any]) -> None:
        nonlocal done
        done += 1
        spec, seed, d = jobs[key]
        if result["error"]:
            what = f"refused: {result['error']}"
        else:
            what = (
                f"W/I/C {result['W']}/{result['I']}/{result['C']} of {settings.n_boxes}, "
                f"MAE {result['mae']:.3f}, fit {result['fit_s']:.1f} s, "
                f"tick {result['tick_ms']:.2f} ms"
            )
        elapsed = time.perf_counter() - started
        _say(f"[{done}/{len(jobs)}] seed {seed} D={d} {spec.label()}: {what} ({elapsed:.0f} s)")

    def collected_now(seed: int) -> None:
        _say(f"seed {seed}: demonstrations collected ({time.perf_counter() - started:.0f} s)")

    if workers <= 1:
        for seed in settings.seeds:
            collected[seed] = _collect(plain, run_dir, seed)
            collected_now(seed)
            for key in sorted((k for k in jobs if jobs[k][1] == seed), key=order.__getitem__):
                spec, _, d = jobs[key]
                results[key] = run_row(plain, spec, collected[seed], d)
                report(key, results[key])
        return collected, results

    import multiprocessing
    from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait

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

    context = multiprocessing.get_context("spawn")
    saved = os.environ.get("TQDM_DISABLE")
    os.environ["TQDM_DISABLE"] = "1"  # inherited by the workers: their progress is reported here
    pool = ProcessPoolExecutor(workers, context, initializer=_init_worker)
    pending: dict[Future, tuple[str, Any]] = {}

    def fill() -> None:
        while len(pending) < workers and (job := next_job()) is not None:
            what, key = job
            if what == "collect":
                future = pool.submit(_collect, plain, run_dir, key)
            else:
                spec, seed, d = jobs[key]
                future = pool.submit(run_row, plain, spec, collected[seed], d)
            pending[future] = job

    try:
        fill()
        while pending:
            finished, _ = wait(pending, return_when=FIRST_COMPLETED)
            for future in sorted(finished, key=lambda f: str(pending[f])):
                what, key = pending.pop(future)
                if what == "row":
                    results[key] = future.result()
                    measured.setdefault(identity(key), sum(results[key]["seconds"].values()))
                    report(key, results[key])
                    continue
                collected[key] = future.result()
                collected_now(key)
                ready.extend(k for k in jobs if jobs[k][1] == key)
            fill()
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
        if saved is None:
            os.environ.pop("TQDM_DISABLE", None)
        else:
            os.environ["TQDM_DISABLE"] = saved
    return collected, results


# ---------------------------------------------------------------------------- aggregation
def aggregate_rows(
    specs: Sequence[RowSpec], settings: ExperimentSettings, results: Mapping[str, dict[str, Any]]
) -> list[dict[str, Any]]:
    """One row per spec and D: the :data:`ROW_FIELDS` as means over the seeds whose fit
    succeeded (W/I/C: boxes of ``n_boxes``; mae in [0, 1]; fit_s [s]; tick_ms [ms]), their
    population std (``*_std``), the per-seed values and any refused fits (``errors``)."""
    rows = []
    for spec in specs:
        for d in spec.train_sizes:
            per_seed = [results[spec.fit_key(seed, d)] for seed in settings.seeds]
            ok = [r for r in per_seed if not r["error"]]
            row: dict[str, Any] = {"predictor": spec.predictor, "sequencer": spec.sequencer, "D": d}
            for key in ("mae", "W", "I", "C", "fit_s", "tick_ms", "supports", "diverged"):
                row[key], std = mean_std([r.get(key) for r in ok])
                if key in ("mae", "W", "I", "C"):
                    row[f"{key}_std"] = std
            row.update(
                group=spec.group,
                support_scale=spec.support_scale,
                n_boxes=settings.n_boxes,
                seeds=list(settings.seeds),
                n_seeds=len(ok),
                per_seed={
                    key: [r.get(key) for r in per_seed]
                    for key in ("W", "I", "C", "mae", "supports")
                },
                errors=[
                    f"seed {seed}: {r['error']}"
                    for seed, r in zip(settings.seeds, per_seed, strict=True)
                    if r["error"]
                ],
            )
            rows.append(jsonable(row))
    return rows


def _episodes(
    results: Mapping[str, dict[str, Any]], jobs: Mapping[str, tuple[RowSpec, int, int]]
) -> list[dict[str, Any]]:
    """Every reproduction episode of every job, labelled with its row, seed and D (a fit
    shared by two rows is listed once, under the first)."""
    out = []
    for key, (spec, seed, d) in jobs.items():
        label = {
            "predictor": spec.predictor,
            "sequencer": spec.sequencer,
            "support_scale": spec.support_scale,
            "seed": seed,
            "D": d,
        }
        out += [{**label, **episode} for episode in results[key]["episodes"]]
    return out


def _timings(
    collected: Mapping[int, SeedData],
    results: Mapping[str, dict[str, Any]],
    jobs: Mapping[str, tuple[RowSpec, int, int]],
    seconds: float,
    workers: int,
) -> dict[str, Any]:
    """Wall time of the run; wall and CPU seconds of every stage of every job (to scale the
    run's cost to other box or seed counts)."""
    tasks = []
    for key, (spec, seed, d) in jobs.items():
        r = results[key]
        tasks.append(
            {
                "group": spec.group,
                "predictor": spec.predictor,
                "sequencer": spec.sequencer,
                "support_scale": spec.support_scale,
                "seed": seed,
                "D": d,
                "seconds": r["seconds"],
                "cpu_seconds": r["cpu_seconds"],
                "boxes": len(r["episodes"]),
            }
        )
    return {
        "seconds": seconds,
        "workers": workers,
        "collect_seconds": {str(s): data.seconds for s, data in collected.items()},
        "jobs": tasks,
        "note": "per-job seconds are wall time inside a worker; cpu_seconds its process time",
    }


# ------------------------------------------------------------------------------ reporting
def _fmt(value: float | None, digits: int = 1) -> str:
    return "–" if value is None else f"{value:.{digits}f}"


def _wic(row: Mapping[str, Any] | None) -> str:
    """``W / I / C`` means (``± std`` of C over more than one seed)."""
    if row is None or row.get("C") is None:
        return "–"
    spread = f" ± {_fmt(row['C_std'])}" if row.get("n_seeds", 1) > 1 else ""
    return f"{_fmt(row['W'])} / {_fmt(row['I'])} / {_fmt(row['C'])}{spread}"


def render_compare(
    rows: Sequence[Mapping[str, Any]], settings: ExperimentSettings, seconds: float, workers: int
) -> str:
    """``compare.md``: the rows by predictor with W / I / C per D beside the paper's Table I,
    progress MAE, fit and tick time, support points; then the support sweep."""
    sizes = list(settings.train_sizes)
    largest = max(sizes)
    lines = [
        f"# cpmp comparison `{settings.name}`",
        "",
        f"Seeds {settings.seeds}; {settings.n_boxes} random boxes per D and seed (the same "
        f"boxes for every row); {3 * settings.demos_per_strategy} demonstrations per seed "
        f"({3 * settings.train_per_strategy} train). W / I / C = wrong start / incomplete / "
        "complete, mean over seeds; MAE = progress error on the held-out demonstrations "
        "(goal_nearest: its nearest-neighbour estimate, which it does not use to switch); "
        f"fit [s], tick [ms] (mean `step()` over a held-out demonstration) and support points "
        f"at D = {largest}. Wall time {seconds / 60:.1f} min on {workers} worker(s).",
        "",
        "| predictor | sequencer | "
        + " | ".join(f"D = {d}: W / I / C" for d in sizes)
        + " | MAE ("
        + " / ".join(map(str, sizes))
        + ") | fit [s] | tick [ms] | supports |",
        "| --- | --- | " + " | ".join("---" for _ in sizes) + " | --- | --- | --- | --- |",
    ]
    paper = [PAPER_TABLE_I.get(str(d)) for d in sizes]
    if any(paper):
        cells = [f"{p['W']} / {p['I']} / {p['C']} (of 20)" if p else "–" for p in paper]
        lines.append("| paper, Table I | paper | " + " | ".join(cells) + " | – | – | – | – |")
    table = [r for r in rows if r["group"] != "support_sweep"]
    keys = list(dict.fromkeys((r["predictor"], r["sequencer"]) for r in table))
    for predictor, sequencer in keys:
        by_d = {
            r["D"]: r for r in table if (r["predictor"], r["sequencer"]) == (predictor, sequencer)
        }
        last = by_d.get(largest, {})
        maes = " / ".join(_fmt(by_d.get(d, {}).get("mae"), 3) for d in sizes)
        supports = last.get("supports")
        lines.append(
            f"| `{predictor}` | `{sequencer}` | "
            + " | ".join(_wic(by_d.get(d)) for d in sizes)
            + f" | {maes} | {_fmt(last.get('fit_s'))} | {_fmt(last.get('tick_ms'), 2)} | "
            f"{'–' if supports is None else f'{supports:.0f}'} |"
        )
    sweep = [r for r in rows if r["group"] == "support_sweep"]
    if sweep:
        lines += [
            "",
            f"## Support-density sweep (`{sweep[0]['predictor']}`)",
            "",
            "| D | support_scale | supports | W / I / C | MAE | fit [s] | tick [ms] |",
            "| --- | --- | --- | --- | --- | --- | --- |",
        ]
        for r in sorted(sweep, key=lambda r: (r["D"], r["support_scale"])):
            supports = "–" if r["supports"] is None else f"{r['supports']:.0f}"
            lines.append(
                f"| {r['D']} | {r['support_scale']:g} | {supports} | {_wic(r)} | "
                f"{_fmt(r['mae'], 3)} | {_fmt(r['fit_s'])} | {_fmt(r['tick_ms'], 2)} |"
            )
    errors = [(r, e) for r in rows for e in r["errors"]]
    if errors:
        lines += ["", "## Refused fits", ""]
        lines += [
            f"- `{r['predictor']}` + `{r['sequencer']}`, D = {r['D']}, {e}" for r, e in errors
        ]
    lines += ["", "## Files", ""]
    lines += [
        "- `compare.json`: every row (means, stds, per-seed values, refused fits)",
        "- `compare_c_vs_d.png`: complete episodes against D per predictor",
        "- `compare_supports.png`: complete episodes and MAE against the support-point count",
        "- `episodes.json`: every reproduction episode: row, seed, D, box, outcome, reason",
        "- `timings.json`: wall and CPU seconds of every job",
        "- `seed_<s>/demos.h5`: the demonstrations of each seed (mask/train, mask/test)",
    ]
    return "\n".join(lines) + "\n"


def _figure(width: float, height: float, ncols: int = 1) -> tuple[Any, Any]:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    figure = Figure(figsize=(width, height), dpi=120, layout="constrained")
    FigureCanvasAgg(figure)
    return figure, figure.subplots(1, ncols, squeeze=False)[0]


def _save(figure: Any, path: Path) -> Path:
    with atomic_path(path) as tmp:
        figure.savefig(tmp, format="png")
    figure.clear()
    return path


_MARKERS = ("o", "s", "^", "v", "D", "P", "X", "<", ">", "*")


def _colours(n: int) -> list[Any]:
    """``n`` distinguishable colours (tab10, then tab20)."""
    from matplotlib import colormaps

    cmap = colormaps["tab10" if n <= 10 else "tab20"]
    return [cmap(i % cmap.N) for i in range(n)]


def _percent(value: float | None, n: int) -> float:
    return math.nan if value is None else 100.0 * value / n


def plot_c_vs_d(
    rows: Sequence[Mapping[str, Any]], settings: ExperimentSettings, path: Path
) -> Path:
    """Complete episodes [% of boxes] against D, one line per predictor/sequencer (error bars:
    std over seeds), the paper's Table I dashed."""
    figure, (ax,) = _figure(8.5, 4.5)
    table = [r for r in rows if r["group"] != "support_sweep"]
    keys = list(dict.fromkeys((r["predictor"], r["sequencer"]) for r in table))
    colours = _colours(len(keys))
    for i, (predictor, sequencer) in enumerate(keys):
        mine = sorted(
            (r for r in table if (r["predictor"], r["sequencer"]) == (predictor, sequencer)),
            key=lambda r: r["D"],
        )
        label = predictor if mine[0]["group"] == "predictors" else f"{sequencer} (no predictor)"
        shift = 0.06 * (i - (len(keys) - 1) / 2)  # side by side: equal counts stay visible
        ax.errorbar(
            [r["D"] + shift for r in mine],
            [_percent(r["C"], r["n_boxes"]) for r in mine],
            yerr=[_percent(r["C_std"], r["n_boxes"]) for r in mine],
            marker=_MARKERS[i % len(_MARKERS)],
            color=colours[i],
            capsize=3,
            label=label,
        )
    paper = [
        (d, PAPER_TABLE_I[str(d)]["C"]) for d in settings.train_sizes if str(d) in PAPER_TABLE_I
    ]
    if paper:
        ax.plot(
            [d for d, _ in paper],
            [100.0 * c / 20 for _, c in paper],
            "k--",
            marker="s",
            label="paper, Table I",
        )
    ax.set_xlabel("training demonstrations D")
    ax.set_ylabel("complete [% of boxes]")
    ax.set_xticks(list(settings.train_sizes))
    ax.set_ylim(-5, 105)
    ax.set_title(f"Closed-loop reproduction, seeds {settings.seeds}, {settings.n_boxes} boxes")
    ax.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5))
    return _save(figure, path)


def plot_supports(
    rows: Sequence[Mapping[str, Any]], settings: ExperimentSettings, path: Path
) -> Path:
    """The support sweep: complete episodes [% of boxes] and progress MAE against the number
    of support points (log scale), one line per D."""
    figure, (left, right) = _figure(9.0, 3.8, ncols=2)
    sweep = [r for r in rows if r["group"] == "support_sweep" and r["supports"] is not None]
    for d in sorted({r["D"] for r in sweep}):
        mine = sorted((r for r in sweep if r["D"] == d), key=lambda r: r["supports"])
        x = [r["supports"] for r in mine]
        left.errorbar(
            x,
            [_percent(r["C"], r["n_boxes"]) for r in mine],
            yerr=[_percent(r["C_std"], r["n_boxes"]) for r in mine],
            marker="o",
            capsize=3,
            label=f"D = {d}",
        )
        right.errorbar(
            x, [r["mae"] for r in mine], yerr=[r["mae_std"] for r in mine], marker="o", capsize=3
        )
        for r in mine:
            right.annotate(
                f"{r['support_scale']:g}",
                (r["supports"], r["mae"]),
                fontsize=7,
                xytext=(3, 3),
                textcoords="offset points",
            )
    name = sweep[0]["predictor"] if sweep else "–"
    from matplotlib.ticker import NullFormatter, ScalarFormatter

    for ax in (left, right):
        ax.set_xscale("log")
        ax.xaxis.set_major_formatter(ScalarFormatter())
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_xlabel("support points (all nodes)")
    left.set_ylabel("complete [% of boxes]")
    left.set_ylim(-5, 105)
    right.set_ylabel("progress MAE (held-out)")
    left.set_title(f"{name}: reproduction")
    right.set_title(f"{name}: progress error (labels: support_scale)")
    if sweep:
        left.legend(fontsize=8)
    return _save(figure, path)
