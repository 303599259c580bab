"""The three jobs behind the scripts: the full experiment, training from a file, and offline
evaluation of a checkpoint. Each takes a composed config and a run directory."""

from __future__ import annotations

import dataclasses
import logging
import logging.handlers
import os
import time
from collections import defaultdict
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from cpmp.errors import ConfigError, CpmpFileError
from cpmp.experiment.config import ExperimentJob, experiment_job, job_fit_settings
from cpmp.experiment.pipeline import (
    balanced_subset,
    evaluate_offline,
    progress_bar,
    reproduce,
    split_by_strategy,
    stage,
    strategy_map,
    strategy_signatures,
    summarize_episodes,
    train_sequencer,
)
from cpmp.experiment.report import (
    PAPER_TABLE_I,
    jsonable,
    mean_std,
    predictor_entry,
    write_json,
    write_report,
)

log = logging.getLogger(__name__)


def validate_common(cfg: Any) -> tuple[str, dict[str, Any]]:
    """Check the predictor, sequencer and trainer groups of a composed config
    (:func:`~cpmp.experiment.config.job_fit_settings`); returns the predictor's kind and all
    its options."""
    settings = job_fit_settings(cfg)
    return settings.predictor, dataclasses.asdict(settings.fit.predictor_config)


@dataclass
class SeedData:
    """One seed's collected data, handed to each of its training sizes.

    Attributes:
        seed: the seed.
        train: training demonstrations (with feature noise when ``feature_noise > 0``).
        test: held-out demonstrations.
        boxes: the reproduction boxes.
        expected: the demonstrator's recording of each reproduction box.
        signatures: initial MP per variable of each demonstrated strategy.
        seconds: wall time [s] per stage (``kinematics``: building the arm kinematics, once
            per process; ``collect``; ``expected``).
    """

    seed: int
    train: list[Any]
    test: list[Any]
    boxes: list[Any]
    expected: list[Any]
    signatures: dict[str, dict[str, str]]
    seconds: dict[str, float] = field(default_factory=dict)


@contextmanager
def _timed(seconds: dict[str, float], key: str, name: str) -> Iterator[None]:
    """A logged :func:`stage` whose wall time [s] is added to ``seconds[key]``."""
    start = time.perf_counter()
    with stage(name):
        yield
    seconds[key] = seconds.get(key, 0.0) + time.perf_counter() - start


def collect_seed(job: ExperimentJob | Any, run_dir: str | Path, seed: int) -> SeedData:
    """Stage 1 of one seed: record its demonstrations (saved as ``seed_<s>/demos.h5`` with the
    train/test split) and the demonstrator's run on every reproduction box. ``job``: the
    typed job (or its composed config, converted here)."""
    from cpmp.data import save_demonstrations
    from cpmp.sim import sample_box
    from cpmp.sim.collect import sample_boxes
    from cpmp.sim.simulation import shared_kinematics

    job = experiment_job(job)
    settings, task = job.settings, job.task
    seed_dir = Path(run_dir) / f"seed_{seed}"
    seed_dir.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    shared_kinematics(task.compile_kinematics)  # built (compiled) once per process
    seconds: dict[str, float] = {"kinematics": time.perf_counter() - start}
    n_demos = 3 * settings.demos_per_strategy
    with _timed(seconds, "collect", f"seed {seed}: collect {n_demos} demonstrations"):
        rng = np.random.default_rng(seed)
        boxes = sample_boxes(rng, task, n_demos, balanced=True)
        names = [f"demo_{i:03d}" for i in range(n_demos)]
        demos = _record_together(boxes, task, names, f"seed {seed} demos")
        failed = [d.name for d in demos if not d.metadata.get("success")]
        if failed:
            raise RuntimeError(f"the scripted demonstrator failed on {failed}")
        if settings.record_demos:
            from cpmp.experiment.demo_recording import record_demo_rrd

            (seed_dir / "recordings").mkdir(exist_ok=True)
            for demo, box in zip(demos, boxes, strict=True):
                record_demo_rrd(demo, box, task, seed_dir / "recordings" / f"{demo.name}.rrd")
        train, test = split_by_strategy(demos, settings.train_per_strategy)
        save_demonstrations(
            seed_dir / "demos.h5",
            demos,
            splits={"train": [d.name for d in train], "test": [d.name for d in test]},
        )
    name = f"seed {seed}: demonstrator on {settings.n_boxes} reproduction boxes"
    with _timed(seconds, "expected", name):
        box_rng = np.random.default_rng(seed + settings.box_seed_offset)
        repro_boxes = [sample_box(box_rng, task) for _ in range(settings.n_boxes)]
        expected = _record_together(repro_boxes, task, None, "expected")
    signatures = strategy_signatures(train)
    if settings.feature_noise > 0:
        from cpmp.augment import add_feature_noise

        train = add_feature_noise(train, settings.feature_noise, seed=seed)
    return SeedData(seed, train, test, repro_boxes, expected, signatures, seconds)


def _record_together(boxes: list[Any], task: Any, names: list[str] | None, desc: str) -> list[Any]:
    """The scripted demonstrations of ``boxes``, all boxes run together
    (:func:`cpmp.sim.record_demonstrations`, the same data as one at a time), with a progress
    bar."""
    from cpmp.sim import record_demonstrations

    bar = progress_bar(boxes, desc)
    try:
        return record_demonstrations(boxes, task, names, on_result=lambda i, demo: bar.update(1))
    finally:
        bar.close()


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
    with _timed(seconds, "train", f"seed {seed}: train {kind} on {d} demos"):
        seq = train_sequencer(subset, job.fit, seed, log_dir=seed_dir / "lightning" / f"D{d}")
        seq.save(seed_dir / f"model_D{d}.pt")
    with _timed(seconds, "evaluate", f"seed {seed}: evaluate progress (D={d})"):
        offline = evaluate_offline(seq, data.test)
    with _timed(seconds, "reproduce", f"seed {seed}: reproduce {settings.n_boxes} boxes (D={d})"):
        episodes = reproduce(
            seq,
            data.boxes,
            data.expected,
            task,
            data.signatures,
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
        with _timed(seconds, "strategy_map", f"seed {seed}: strategy map"):
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


def default_workers(n_seeds: int) -> int:
    """``min(cores, n_seeds)``: the worker count of ``experiment.workers: null``."""
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        cores = os.cpu_count() or 1
    return max(1, min(cores, n_seeds))


def run_experiment(cfg: Any, run_dir: str | Path) -> Path:
    """Collect demos in the simulator, train on D = train_sizes, evaluate progress prediction,
    reproduction (Table I) and the strategy map; write the report. Returns ``report.json``.

    Each seed's collection and each (seed, D) training size is a job; with
    ``experiment.workers > 1`` they run in that many worker processes (one torch thread
    each, logs prefixed with their seed and D), and every number in the report is the same as
    in a serial run. ``timings.json`` holds the wall time of every stage.

    A config with a ``compare`` node (``experiment=compare``) runs
    :func:`cpmp.experiment.compare.run_compare` instead and returns ``compare.json``.
    """
    from cpmp.experiment.plots import plot_progress_curves, plot_strategy_map, progress_curves

    if cfg.get("compare") is not None:
        from cpmp.experiment.compare import run_compare

        return run_compare(cfg, run_dir)
    run_dir = Path(run_dir)
    job = experiment_job(cfg)
    settings = job.settings
    started = time.perf_counter()
    workers = settings.workers or default_workers(len(settings.seeds))
    workers = min(workers, len(settings.seeds) * len(settings.train_sizes))
    if workers > 1:
        log.info("running seeds %s on %d worker processes", settings.seeds, workers)
        collected, results = _run_parallel(job, run_dir, workers)
    else:
        collected, results = {}, {}
        for seed in settings.seeds:
            collected[seed] = collect_seed(job, run_dir, seed)
            for d in settings.train_sizes:
                results[seed, d] = run_train_size(job, run_dir, collected[seed], d)

    largest = max(settings.train_sizes)
    per_seed: list[dict[str, Any]] = []
    pairs_by_d: dict[int, list[tuple[np.ndarray, np.ndarray]]] = defaultdict(list)
    episodes_out: list[dict[str, Any]] = []
    stage_seconds: dict[str, float] = defaultdict(float)
    for seed in settings.seeds:
        for key, value in collected[seed].seconds.items():
            stage_seconds[key] += value
        seed_row: dict[str, Any] = {"seed": seed, "by_train_size": {}}
        for d in settings.train_sizes:
            result = results[seed, d]
            pairs_by_d[d] += result["pairs"]
            episodes_out += result["episodes"]
            seed_row["by_train_size"][str(d)] = result["row"]
            for key, value in result["seconds"].items():
                stage_seconds[key] += value
        per_seed.append(seed_row)
    first = results[settings.seeds[0], largest]
    first_map = {**first["strategy_map"], "train_boxes": first["train_boxes"]}

    files: dict[str, str] = {
        "report.json": "all numbers, per seed too",
        "episodes.json": "every reproduction episode: box, strategy, outcome, reason",
        "timings.json": "wall time of the run and of every stage, summed over seeds",
        "seed_<s>/demos.h5": "collected demonstrations with mask/train and mask/test",
        "seed_<s>/model_D<d>.pt": "trained sequencer checkpoints",
        "seed_<s>/recordings/*.rrd": "rerun recordings (open with `rerun FILE.rrd`)",
        "seed_<s>/lightning/D<d>/": "Lightning CSV logs of the predictor fits",
    }
    if job.fit.goal_nearest is not None:  # no predictor: nothing for Lightning to fit
        del files["seed_<s>/lightning/D<d>/"]
        files["seed_<s>/model_D<d>.pt"] = (
            "goal_nearest checkpoints (cpmp.goal_nearest.load_sequencer)"
        )
    with _timed(stage_seconds, "plots", "plots"):
        curves = {f"D={d}": progress_curves(pairs_by_d[d]) for d in settings.train_sizes}
        plot_progress_curves(
            curves,
            run_dir / "fig6_progress.png",
            title="Predicted vs expected progress on held-out demos",
        )
        files["fig6_progress.png"] = "predicted vs expected progress (Fig. 6)"
        plot_strategy_map(
            first_map["widths"],
            first_map["depths"],
            first_map["chosen"],
            first_map["correct"],
            run_dir / "fig7_strategy_map.png",
            training_boxes=first_map["train_boxes"],
            title=f"Initial strategy, D={largest}, seed {settings.seeds[0]}",
        )
        files["fig7_strategy_map.png"] = "chosen vs correct initial strategy (Fig. 7)"
    write_json(run_dir / "episodes.json", episodes_out)
    report = _aggregate(job, per_seed)
    report["files"] = files
    report["seconds"] = time.perf_counter() - started
    write_json(
        run_dir / "timings.json",
        {
            "seconds": report["seconds"],
            "workers": workers,
            "stages": dict(stage_seconds),
            "note": "stage times are wall seconds summed over seeds and training sizes; with "
            "workers > 1 they add up to more than the run's wall time",
        },
    )
    return write_report(report, run_dir)


# ------------------------------------------------------------------- parallel worker jobs
_JOB_LABEL = ""
"""In a worker process: the prefix of its log lines (the job's seed and D)."""


class _JobPrefix(logging.Filter):
    """Prefix every record a worker sends to the main process with its job's label."""

    def filter(self, record: logging.LogRecord) -> bool:
        if _JOB_LABEL:
            record.msg = f"[{_JOB_LABEL}] {record.getMessage()}"
            record.args = None
        return True


class _Dispatch(logging.Handler):
    """Hands a worker's record to the main process's logger of the same name (and so to the
    handlers Hydra configured: console and job log)."""

    def emit(self, record: logging.LogRecord) -> None:
        logger = logging.getLogger(record.name)
        if logger.isEnabledFor(record.levelno):
            logger.handle(record)


def _init_worker(queue: Any, level: int) -> None:
    """Worker start-up: one torch thread, every log record sent to the main process."""
    import torch

    torch.set_num_threads(1)
    handler = logging.handlers.QueueHandler(queue)
    handler.addFilter(_JobPrefix())
    root = logging.getLogger()
    root.handlers = [handler]
    root.setLevel(level)


def _collect_job(job: ExperimentJob, run_dir: Path, seed: int) -> SeedData:
    global _JOB_LABEL
    _JOB_LABEL = f"seed {seed}"
    return collect_seed(job, run_dir, seed)


def _train_size_job(job: ExperimentJob, run_dir: Path, data: SeedData, d: int) -> dict[str, Any]:
    global _JOB_LABEL
    _JOB_LABEL = f"seed {data.seed} D={d}"
    return run_train_size(job, run_dir, data, d)


def _run_parallel(
    job: ExperimentJob, run_dir: Path, workers: int
) -> tuple[dict[int, SeedData], dict[tuple[int, int], dict[str, Any]]]:
    """Every seed's collection, then each of its training sizes (largest first), as jobs on
    ``workers`` spawned processes. Returns the collections by seed and results by (seed, D)."""
    import multiprocessing
    from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait

    settings = job.settings
    context = multiprocessing.get_context("spawn")
    queue = context.Queue()
    listener = logging.handlers.QueueListener(queue, _Dispatch())
    level = logging.getLogger("cpmp").getEffectiveLevel()
    collected: dict[int, SeedData] = {}
    results: dict[tuple[int, int], dict[str, Any]] = {}
    listener.start()
    pool = ProcessPoolExecutor(workers, context, initializer=_init_worker, initargs=(queue, level))
    # Workers show no progress bars (two would overwrite each other; their prefixed log lines
    # show the progress): tqdm reads TQDM_DISABLE when imported, so a worker must inherit it.
    bars = os.environ.get("TQDM_DISABLE")
    os.environ["TQDM_DISABLE"] = "1"
    try:
        pending: dict[Future, tuple[int, int | None]] = {
            pool.submit(_collect_job, job, run_dir, seed): (seed, None) for seed in settings.seeds
        }
        while pending:
            done, _ = wait(pending, return_when=FIRST_COMPLETED)
            for future in done:
                seed, d = pending.pop(future)
                if d is not None:
                    results[seed, d] = future.result()
                    continue
                collected[seed] = data = future.result()
                for size in sorted(settings.train_sizes, reverse=True):
                    training = pool.submit(_train_size_job, job, run_dir, data, size)
                    pending[training] = (seed, size)
    finally:
        if bars is None:
            del os.environ["TQDM_DISABLE"]
        else:
            os.environ["TQDM_DISABLE"] = bars
        pool.shutdown(wait=True, cancel_futures=True)
        listener.stop()
    return collected, results


def _aggregate(job: ExperimentJob, per_seed: list[dict[str, Any]]) -> dict[str, Any]:
    """Mean ± std over seeds of every number; distances pooled over all complete episodes."""
    settings = job.settings
    reproduction: dict[str, Any] = {}
    progress_by_d: dict[str, Any] = {}
    for d in map(str, settings.train_sizes):
        rows = [s["by_train_size"][d] for s in per_seed]
        rep: dict[str, Any] = {}
        for key in ("W", "I", "C", "diverged"):
            rep[key], rep[f"{key}_std"] = mean_std([r["reproduction"][key] for r in rows])
        rep["per_seed"] = {key: [r["reproduction"][key] for r in rows] for key in ("W", "I", "C")}
        for prefix in ("distance", "distance_continuous"):
            pooled_mean, pooled_sq, n = 0.0, 0.0, 0
            for r in rows:
                rr = r["reproduction"]
                if rr["n_distances"] and rr.get(f"{prefix}_mean") is not None:
                    k = rr["n_distances"]
                    pooled_mean += rr[f"{prefix}_mean"] * k
                    pooled_sq += (rr[f"{prefix}_std"] ** 2 + rr[f"{prefix}_mean"] ** 2) * k
                    n += k
            mean = pooled_mean / n if n else None
            rep[f"{prefix}_mean"] = mean
            rep[f"{prefix}_std"] = float(np.sqrt(max(pooled_sq / n - mean**2, 0))) if n else None
        for key in ("recoveries", "recovered_episodes", "recovered_complete", "holds"):
            rep[key], _ = mean_std([r["reproduction"].get(key) for r in rows])
        rep["n_boxes"] = settings.n_boxes
        rep["paper"] = PAPER_TABLE_I.get(d)
        reproduction[d] = rep
        prog: dict[str, Any] = {}
        for key in ("mae", "mae_first", "mae_last"):
            prog[key], prog[f"{key}_std"] = mean_std([r["progress"][key] for r in rows])
        prog["replay_all_match"], _ = mean_std([r["replay"]["all_match"] for r in rows])
        progress_by_d[d] = prog
    largest = str(max(settings.train_sizes))
    accuracy = [s["by_train_size"][largest].get("strategy_map_accuracy") for s in per_seed]
    acc_mean, acc_std = mean_std(accuracy)
    warnings = [
        f"seed {s['seed']}, D = {d}: {text}"
        for s in per_seed
        for d, row in s["by_train_size"].items()
        for text in row["fit"].get("warnings") or []
    ]
    return jsonable(
        {
            "experiment": {k: v for k, v in settings.__dict__.items() if k != "workers"},
            **_configs(job),
            "progress": {
                "mae": progress_by_d[largest]["mae"],
                "mae_first": progress_by_d[largest]["mae_first"],
                "mae_last": progress_by_d[largest]["mae_last"],
                "train_size": int(largest),
                "by_train_size": progress_by_d,
            },
            "reproduction": reproduction,
            "strategy_map": {
                "accuracy": acc_mean,
                "accuracy_std": acc_std,
                "grid": settings.strategy_grid,
                "train_size": int(largest),
            },
            "fit_warnings": warnings,
            "per_seed": per_seed,
        }
    )


def _configs(job: ExperimentJob) -> dict[str, Any]:
    """The report's ``predictor``, ``sequencer`` and ``task`` sections: every option used."""
    fit = job.fit
    if fit.goal_nearest is not None:
        from cpmp.goal_nearest import KIND

        sequencer = {"kind": KIND, **dataclasses.asdict(fit.goal_nearest)}
    else:
        sequencer = dataclasses.asdict(fit.fit.sequencer)
    return {
        "predictor": predictor_entry(
            fit.predictor, dataclasses.asdict(fit.fit.predictor_config), sequencer
        ),
        "sequencer": sequencer,
        "task": job.task.to_dict(),
    }


def _demo_file(cfg: Any, auto_split: str) -> tuple[Path, str | None]:
    """The ``data`` group's file (checked to exist) and split; ``split: auto`` means
    ``auto_split`` when the file has that mask, else every demonstration."""
    from cpmp.data import list_splits

    if not cfg.data.get("path"):
        raise ConfigError("data.path is required: give an HDF5 file of demonstrations")
    path = Path(str(cfg.data.path))
    if not path.is_file():
        raise CpmpFileError(f"demonstration file {path} does not exist (set data.path)")
    split = cfg.data.get("split", "auto")
    if split == "auto":
        split = auto_split if auto_split in list_splits(path) else None
    return path, split


def train_from_file(cfg: Any, run_dir: str | Path) -> Path:
    """Train a sequencer from a demonstration file (its ``mask/train`` split when present) and
    save ``model.pt`` into ``run_dir``; returns the checkpoint path."""
    settings = job_fit_settings(cfg)
    from cpmp.data import load_demonstrations

    path, split = _demo_file(cfg, "train")
    demos = load_demonstrations(path, split=split)
    run_dir = Path(run_dir)
    with stage(f"train on {len(demos)} demos from {path} (split {split or 'all'})"):
        seq = train_sequencer(demos, settings, int(cfg.seed), log_dir=run_dir / "lightning")
    out = seq.save(run_dir / "model.pt")
    write_json(
        run_dir / "train_summary.json",
        {"data": str(path), "split": split, "n_demos": len(demos), **seq.fit_summary},
    )
    log.info("graphs:\n%s", seq.describe())
    return out


def evaluate_checkpoint(cfg: Any, run_dir: str | Path) -> Path:
    """Evaluate a checkpoint offline on a file's test split: progress MAE per node, replay of the
    recorded feature streams, Fig. 6 plot. Writes ``evaluation.json``/``.md``; returns the JSON."""
    from cpmp.data import load_demonstrations
    from cpmp.experiment.plots import plot_progress_curves
    from cpmp.goal_nearest import load_sequencer

    if not cfg.get("checkpoint"):
        raise ConfigError("checkpoint is required: checkpoint=path/to/model.pt")
    checkpoint = Path(str(cfg.checkpoint))
    if not checkpoint.is_file():
        raise CpmpFileError(f"checkpoint {checkpoint} does not exist; train one with train.py")
    path, split = _demo_file(cfg, "test")
    seq = load_sequencer(checkpoint)  # any kind the main job or train.py writes
    demos = load_demonstrations(path, split=split)
    run_dir = Path(run_dir)
    unknown = _unknown_mps(seq, demos)
    if unknown:
        log.warning(
            "%s has MPs the model does not know, left out of the progress MAE (renamed? "
            "rename them back or retrain): %s",
            path,
            ", ".join(f"{u['variable']}/{u['mp']} ({u['activations']}x)" for u in unknown),
        )
    with stage(f"evaluate on {len(demos)} demos"):
        result = evaluate_offline(seq, demos)
    plot_progress_curves(
        {"held-out": result["curves"]},
        run_dir / "fig6_progress.png",
        title="Predicted vs expected progress",
    )
    out = {
        "checkpoint": str(cfg.checkpoint),
        "data": str(path),
        "split": split,
        "n_demos": len(demos),
        "model": _model_entry(seq),
        "unknown_mps": unknown,
        "progress": result["progress"],
        "replay": result["replay"],
    }
    json_path = write_json(run_dir / "evaluation.json", out)
    from cpmp.io import atomic_write_text

    atomic_write_text(run_dir / "evaluation.md", _evaluation_markdown(out))
    return json_path


def _model_entry(seq: Any) -> dict[str, Any]:
    """What an evaluated checkpoint is: ``sequencer`` (``learned`` or ``goal_nearest``) and
    ``predictor`` (its kind, ``none`` for goal_nearest, with a note on what its progress is)."""
    from cpmp.goal_nearest import KIND, GoalNearestSequencer

    if isinstance(seq, GoalNearestSequencer):
        entry = predictor_entry("none", {}, {"kind": KIND})
        return {"sequencer": KIND, "predictor": entry.pop("kind"), **entry}
    return {"sequencer": "learned", "predictor": seq.predictor.kind}


def _unknown_mps(seq: Any, demos: list[Any]) -> list[dict[str, Any]]:
    """MPs labelled in ``demos`` (demonstrations) that ``seq`` (a sequencer) has no node for:
    a renamed MP, or every MP of a variable the model was not trained on. Returns
    ``[{"variable", "mp", "known_variable", "activations", "demos"}]`` sorted by variable, MP."""
    found: dict[tuple[str, str], dict[str, Any]] = {}
    for m, demo in enumerate(demos):
        for v in demo.variables:
            graph = seq.graphs.get(v)
            for seg in demo.segments(v):
                if graph is not None and seg.mp in graph.nodes:
                    continue
                row = found.setdefault(
                    (v, seg.mp),
                    {
                        "variable": v,
                        "mp": seg.mp,
                        "known_variable": graph is not None,
                        "activations": 0,
                        "demos": [],
                    },
                )
                row["activations"] += 1
                name = demo.name or f"demo_{m}"
                if name not in row["demos"]:
                    row["demos"].append(name)
    return [found[k] for k in sorted(found)]


def _evaluation_markdown(out: dict[str, Any]) -> str:
    p, r = out["progress"], out["replay"]
    lines = [
        f"# Offline evaluation of `{out['checkpoint']}`",
        "",
        f"{out['n_demos']} demos from `{out['data']}` (split {out['split'] or 'all'}).",
        "",
    ]
    model = out["model"]
    if model["sequencer"] == "learned":
        lines += [f"Learned sequencer, predictor `{model['predictor']}`.", ""]
    else:
        lines += [f"Sequencer `{model['sequencer']}`: {model['note']}.", ""]
    if out.get("unknown_mps"):
        lines += [
            "**MPs the model does not know** (renamed, or of a variable the model was not "
            "trained on): left out of the progress MAE; a variable with one cannot match in "
            "the replay, a variable the model lacks is not replayed.",
            "",
            "| variable | MP | activations | demos |",
            "| --- | --- | --- | --- |",
        ]
        lines += [
            f"| {u['variable']}{'' if u['known_variable'] else ' (unknown)'} | {u['mp']} | "
            f"{u['activations']} | {', '.join(u['demos'])} |"
            for u in out["unknown_mps"]
        ]
        lines.append("")
    lines += [
        f"Progress MAE {p['mae']:.3f} (first 10 %: {p['mae_first']:.3f}, last 10 %: "
        f"{p['mae_last']:.3f}).",
        "",
        "| node | MAE |",
        "| --- | --- |",
    ]
    lines += [f"| {k} | {v:.3f} |" for k, v in p["per_node"].items()]
    dist = (
        "–" if r["distance_mean"] is None else f"{r['distance_mean']:.3f} ± {r['distance_std']:.3f}"
    )
    lines += [
        "",
        f"Replay: all variables reproduced in {100 * r['all_match']:.0f} % of the demos; "
        f"switch-state distance {dist}.",
        "",
        "| variable | sequence match |",
        "| --- | --- |",
    ]
    lines += [f"| {v} | {100 * m:.0f} % |" for v, m in r["sequence_match"].items()]
    return "\n".join(lines) + "\n"
