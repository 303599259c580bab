"""The three jobs behind the scripts: the full experiment, training from a file, and offline
evaluation of a checkpoint. Each takes a composed config and a run directory."""

from __future__ import annotations

import logging
import time
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np

from cpmp.errors import ConfigError, CpmpFileError
from cpmp.experiment.config import predictor_options, to_dict
from cpmp.experiment.pipeline import (
    ExperimentSettings,
    balanced_subset,
    evaluate_offline,
    fit_sequencer,
    progress_bar,
    reproduce,
    split_by_strategy,
    stage,
    strategy_map,
    strategy_signatures,
    summarize_episodes,
)
from cpmp.experiment.report import PAPER_TABLE_I, jsonable, mean_std, write_json, write_report

log = logging.getLogger(__name__)


def validate_common(cfg: Any) -> tuple[str, dict[str, Any]]:
    """Check the predictor, sequencer and trainer groups before any long work starts."""
    from cpmp.sequencer import SequencerConfig
    from cpmp.training import TrainerConfig

    kind, options = predictor_options(cfg.predictor)
    try:
        SequencerConfig(**to_dict(cfg.get("sequencer")))
        TrainerConfig(**to_dict(cfg.get("trainer")))
    except TypeError as err:
        raise ConfigError(f"bad sequencer/trainer option: {err}") from err
    return kind, options


def run_experiment(cfg: Any, run_dir: str | Path) -> Path:
    """Collect demos in the simulator, train on D = train_sizes, evaluate progress prediction,
    reproduction (Table I) and the strategy map; write the report. Returns ``report.json``."""
    from cpmp.data import save_demonstrations
    from cpmp.experiment.plots import plot_progress_curves, plot_strategy_map, progress_curves
    from cpmp.sim import TaskConfig, record_demonstration, sample_box
    from cpmp.sim.collect import sample_boxes

    run_dir = Path(run_dir)
    settings = ExperimentSettings.from_cfg(cfg.experiment)
    task = TaskConfig.from_dict(cfg.task)
    kind, _ = validate_common(cfg)
    started = time.perf_counter()
    per_seed: list[dict[str, Any]] = []
    pairs_by_d: dict[int, list[tuple[np.ndarray, np.ndarray]]] = defaultdict(list)
    first_map: dict[str, Any] | None = None
    largest = max(settings.train_sizes)
    episodes_out: list[dict[str, Any]] = []
    for seed in settings.seeds:
        seed_dir = run_dir / f"seed_{seed}"
        seed_dir.mkdir(parents=True, exist_ok=True)
        with stage(f"seed {seed}: collect {3 * settings.demos_per_strategy} demonstrations"):
            rng = np.random.default_rng(seed)
            boxes = sample_boxes(rng, task, 3 * settings.demos_per_strategy, balanced=True)
            demos = [
                record_demonstration(b, task, name=f"demo_{i:03d}")
                for i, b in enumerate(progress_bar(boxes, f"seed {seed} demos"))
            ]
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
        with stage(f"seed {seed}: demonstrator on {settings.n_boxes} reproduction boxes"):
            box_rng = np.random.default_rng(seed + settings.box_seed_offset)
            repro_boxes = [sample_box(box_rng, task) for _ in range(settings.n_boxes)]
            expected = [
                record_demonstration(b, task) for b in progress_bar(repro_boxes, "expected")
            ]
        signatures = strategy_signatures(train)
        if settings.feature_noise > 0:
            from cpmp.augment import add_feature_noise

            train = add_feature_noise(train, settings.feature_noise, seed=seed)
        seed_row: dict[str, Any] = {"seed": seed, "by_train_size": {}}
        for d in settings.train_sizes:
            subset = balanced_subset(train, d)
            with stage(f"seed {seed}: train {kind} on {d} demos"):
                seq = fit_sequencer(
                    subset,
                    cfg.predictor,
                    cfg.get("sequencer"),
                    cfg.get("trainer"),
                    seed,
                    log_dir=seed_dir / "lightning",
                )
                seq.save(seed_dir / f"model_D{d}.pt")
            with stage(f"seed {seed}: evaluate progress (D={d})"):
                offline = evaluate_offline(seq, test)
                pairs_by_d[d] += offline["pairs"]
            with stage(f"seed {seed}: reproduce {settings.n_boxes} boxes (D={d})"):
                episodes = reproduce(
                    seq,
                    repro_boxes,
                    expected,
                    task,
                    signatures,
                    record_dir=seed_dir / "recordings",
                    record=settings.record,
                    max_time=settings.max_time,
                    label=f"D{d}_",
                )
            summary = summarize_episodes(episodes)
            episodes_out += [{"seed": seed, "D": d, **e.to_dict()} for e in episodes]
            row = {
                "progress": {k: offline["progress"][k] for k in ("mae", "mae_first", "mae_last")},
                "replay": {
                    k: offline["replay"][k]
                    for k in ("all_match", "sequence_match", "distance_mean", "distance_std")
                },
                "reproduction": summary,
                "fit": {
                    k: seq.fit_summary.get(k)
                    for k in ("loss", "seconds", "n_support_total", "warnings")
                },
            }
            if d == largest:
                with stage(f"seed {seed}: strategy map"):
                    smap = strategy_map(seq, task, signatures, settings.strategy_grid)
                row["strategy_map_accuracy"] = smap["accuracy"]
                if first_map is None:
                    first_map = {
                        **smap,
                        "train_boxes": [
                            (s.metadata["box_width"], s.metadata["box_depth"]) for s in subset
                        ],
                    }
            seed_row["by_train_size"][str(d)] = row
        per_seed.append(seed_row)

    files: dict[str, str] = {
        "report.json": "all numbers, per seed too",
        "episodes.json": "every reproduction episode: box, strategy, outcome, reason",
        "seed_<s>/demos.h5": "collected demonstrations with mask/train and mask/test",
        "seed_<s>/model_D<d>.pt": "trained sequencer checkpoints",
        "seed_<s>/recordings/*.rrd": "rerun recordings (open with `rerun FILE.rrd`)",
        "seed_<s>/lightning/": "Lightning CSV logs of the predictor fits",
    }
    with stage("plots"):
        curves = {f"D={d}": progress_curves(pairs_by_d[d]) for d in settings.train_sizes}
        plot_progress_curves(
            curves,
            run_dir / "fig6_progress.png",
            title="Predicted vs expected progress on held-out demos",
        )
        files["fig6_progress.png"] = "predicted vs expected progress (Fig. 6)"
        if first_map is not None:
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
    report = _aggregate(settings, kind, cfg, per_seed)
    report["files"] = files
    report["seconds"] = time.perf_counter() - started
    return write_report(report, run_dir)


def _aggregate(
    settings: ExperimentSettings, kind: str, cfg: Any, per_seed: list[dict[str, Any]]
) -> dict[str, Any]:
    """Mean ± std over seeds of every number; distances pooled over all complete episodes."""
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
            "experiment": settings.__dict__,
            "predictor": {"kind": kind, **to_dict(cfg.predictor)},
            "sequencer": to_dict(cfg.get("sequencer")),
            "task": to_dict(cfg.task),
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
    validate_common(cfg)
    from cpmp.data import load_demonstrations

    path, split = _demo_file(cfg, "train")
    demos = load_demonstrations(path, split=split)
    run_dir = Path(run_dir)
    with stage(f"train on {len(demos)} demos from {path} (split {split or 'all'})"):
        seq = fit_sequencer(
            demos,
            cfg.predictor,
            cfg.get("sequencer"),
            cfg.get("trainer"),
            int(cfg.seed),
            log_dir=run_dir / "lightning",
        )
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
    from cpmp.sequencer import ConcurrentSequencer

    if not cfg.get("checkpoint"):
        raise ConfigError("checkpoint is required: checkpoint=path/to/model.pt")
    checkpoint = Path(str(cfg.checkpoint))
    if not checkpoint.is_file():
        raise CpmpFileError(f"checkpoint {checkpoint} does not exist; train one with train.py")
    path, split = _demo_file(cfg, "test")
    seq = ConcurrentSequencer.load(checkpoint)
    demos = load_demonstrations(path, split=split)
    run_dir = Path(run_dir)
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
        "progress": result["progress"],
        "replay": result["replay"],
    }
    json_path = write_json(run_dir / "evaluation.json", out)
    from cpmp.io import atomic_write_text

    atomic_write_text(run_dir / "evaluation.md", _evaluation_markdown(out))
    return json_path


def _evaluation_markdown(out: dict[str, Any]) -> str:
    p, r = out["progress"], out["replay"]
    lines = [
        f"# Offline evaluation of `{out['checkpoint']}`",
        "",
        f"{out['n_demos']} demos from `{out['data']}` (split {out['split'] or 'all'}).",
        "",
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
