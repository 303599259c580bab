"""The main job's report: its seeds pooled (mean ± std), written as JSON, Markdown, figures.

``report.json`` (machine-readable), ``report.md``, the figures and ``timings.json``; the
helpers other reports share are in :mod:`~cpmp.experiment.output` (and importable from here).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
from typing_extensions import NotRequired, TypedDict  # NotRequired needs their TypedDict < 3.11

from cpmp.config.bc import KIND as BC
from cpmp.config.goal_nearest import KIND as GOAL_NEAREST
from cpmp.evaluation.offline import progress_curves
from cpmp.experiment.output import PAPER_TABLE_I, jsonable, mean_std, write_json
from cpmp.experiment.plots import plot_progress_curves, plot_strategy_map
from cpmp.experiment.reproduction import ReproductionSummary
from cpmp.experiment.settings import ExperimentJob
from cpmp.experiment.strategies import StrategyMap
from cpmp.io import atomic_write_text
from cpmp.records import JsonValue


def _fmt(mean: float | None, std: float | None = None, digits: int = 2) -> str:
    """``mean`` (``± std`` when given) with ``digits`` decimals, ``–`` for ``None``."""
    if mean is None:
        return "–"
    if std is None:
        return f"{mean:.{digits}f}"
    return f"{mean:.{digits}f} ± {std:.{digits}f}"


BASELINES = (GOAL_NEAREST, BC)
"""The ``sequencer`` kinds that train no progress predictor."""


def nearest_progress_note(kind: str = GOAL_NEAREST) -> str:
    """What the progress numbers of a run of the baseline ``kind`` are.

    Args:
        kind: one of :data:`BASELINES`.
    """
    return (
        f"sequencer={kind} trains no progress predictor (the predictor group is not used); "
        "its progress MAE is of a nearest-training-sample lookup of the expected progress "
        "(eq. 1), which it never uses to switch"
    )


NEAREST_PROGRESS_NOTE = nearest_progress_note()
"""What the progress numbers of a ``goal_nearest`` run are."""


def is_goal_nearest(sequencer: Mapping[str, object] | None) -> bool:
    """Whether a ``sequencer`` config (a mapping, maybe empty) selects the goal-nearest baseline."""
    return bool(sequencer) and sequencer.get("kind") == GOAL_NEAREST


def baseline_kind(sequencer: Mapping[str, object] | None) -> str | None:
    """The baseline (one of :data:`BASELINES`) a ``sequencer`` config selects, else ``None``."""
    kind = sequencer.get("kind") if sequencer else None
    return kind if isinstance(kind, str) and kind in BASELINES else None


def predictor_entry(
    kind: str, predictor: Mapping[str, object], sequencer: Mapping[str, object] | None
) -> dict[str, object]:
    """The report's ``predictor`` entry: ``kind`` and the options of the predictor that ran.

    For a baseline (``sequencer=goal_nearest`` or ``bc``, which run none) it is
    ``kind: "none"``, the progress estimate it reports instead (``nearest_sample``) and a note
    saying so.
    """
    baseline = baseline_kind(sequencer)
    if baseline is not None:
        return {
            "kind": "none",
            "progress_estimate": "nearest_sample",
            "used_to_switch": False,
            "note": nearest_progress_note(baseline),
        }
    return {"kind": kind, **predictor}


# ------------------------------------------------------------------------- seed pooling
class TrainSizeRow(TypedDict):
    """The report's numbers of one seed at one training size D.

    As :func:`cpmp.experiment.jobs.run_train_size` makes them.
    """

    progress: dict[str, float]
    """The offline progress MAE: ``mae``, ``mae_first``, ``mae_last``."""
    replay: dict[str, JsonValue]
    """The open-loop replay: ``all_match``, ``sequence_match`` (per variable),
    ``distance_mean``, ``distance_std``."""
    reproduction: ReproductionSummary
    """Table I of the seed's reproduction episodes."""
    fit: dict[str, JsonValue]
    """The fit report's ``loss``, ``seconds``, ``n_support_total`` and ``warnings``."""
    strategy_map_accuracy: NotRequired[float]
    """The strategy map's accuracy (at the largest D only)."""


class SeedRow(TypedDict):
    """One seed's rows of the report (``per_seed``)."""

    seed: int
    """The seed."""
    by_train_size: dict[str, TrainSizeRow]
    """Its numbers by ``str(D)``."""


def pool_seeds(job: ExperimentJob, per_seed: list[SeedRow]) -> dict[str, JsonValue]:
    """The report of the main job from its per-seed rows.

    Every number is the mean ± std over seeds; distances are pooled over all complete
    episodes; the configs that ran are listed.

    Args:
        job: the typed job.
        per_seed: ``{"seed", "by_train_size": {str(d): row}}`` per seed, each row as
            :func:`cpmp.experiment.jobs.run_train_size` returns it.
    """
    settings = job.settings
    reproduction: dict[str, dict[str, JsonValue]] = {}
    progress_by_d: dict[str, dict[str, float | None]] = {}
    for d in map(str, settings.train_sizes):
        rows = [s["by_train_size"][d] for s in per_seed]
        rep: dict[str, JsonValue] = {}
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
        for key in (
            "recoveries",
            "recovered_episodes",
            "recovered_complete",
            "recoveries_right",
            "recoveries_wrong",
            "give_ups",
            "holds",
        ):
            rep[key], _ = mean_std([r["reproduction"].get(key) for r in rows])
        causes: dict[str, int] = {}
        for r in rows:
            for reason, count in (r["reproduction"].get("causes") or {}).items():
                causes[reason] = causes.get(reason, 0) + count
        rep["causes"] = dict(sorted(causes.items(), key=lambda kv: (-kv[1], kv[0])))
        rep["n_boxes"] = settings.n_boxes
        rep["paper"] = PAPER_TABLE_I.get(d)
        reproduction[d] = rep
        prog: dict[str, float | None] = {}
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
            "experiment": {
                k: v for k, v in settings.__dict__.items() if k not in ("workers", "executor")
            },
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


def _configs(job: ExperimentJob) -> dict[str, object]:
    """The report's ``predictor``, ``sequencer`` and ``task`` sections: every option used."""
    fit = job.fit
    if fit.baseline is not None:
        sequencer = fit.baseline_options()
    else:
        sequencer = dataclasses.asdict(fit.fit.sequencer)
    return {
        "predictor": predictor_entry(
            fit.predictor, dataclasses.asdict(fit.fit.predictor_config), sequencer
        ),
        "sequencer": sequencer,
        "task": job.task.to_dict(),
    }


def experiment_files(job: ExperimentJob) -> dict[str, str]:
    """What the main job writes besides its figures: file (pattern) -> what it holds."""
    files: dict[str, str] = {
        "report.json": "all numbers, per seed too",
        "episodes.json": "per episode: box_size_m [m], strategy, outcome, reason, cause",
        "timings.json": "wall time of the run and of every stage, summed over seeds",
        "seed_<s>/demos.h5": "collected demonstrations with mask/train and mask/test",
        "seed_<s>/model_D<d>.pt": "trained sequencer checkpoints",
        "seed_<s>/recordings/*.rrd": "rerun recordings (open with `rerun FILE.rrd`)",
        "seed_<s>/lightning/D<d>/": "Lightning CSV logs of the predictor fits",
    }
    if job.fit.baseline is not None:  # no predictor: nothing for Lightning to fit
        del files["seed_<s>/lightning/D<d>/"]
        files["seed_<s>/model_D<d>.pt"] = (
            f"{job.fit.baseline} checkpoints (cpmp.evaluation.checkpoints.load_sequencer)"
        )
    return files


def write_figures(
    job: ExperimentJob,
    run_dir: Path,
    pairs_by_d: Mapping[int, list[tuple[np.ndarray, np.ndarray]]],
    strategy_map: StrategyMap,
    train_boxes: Sequence[tuple[float, float]],
) -> dict[str, str]:
    """Fig. 6 (progress curves per D) and Fig. 7 (the strategy map) into ``run_dir``.

    Args:
        job: the typed job.
        run_dir: the run directory.
        pairs_by_d: ``(expected (n,), predicted (n,))`` per held-out activation, by D.
        strategy_map: the first seed's strategy map at the largest D.
        train_boxes: (width, depth) [m] of its training demonstrations.

    Returns:
        The figures' entries of the report's files.
    """
    settings = job.settings
    curves = {f"D={d}": progress_curves(pairs_by_d[d]) for d in settings.train_sizes}
    plot_progress_curves(
        curves,
        run_dir / "fig6_progress.png",
        title="Predicted vs expected progress on held-out demos",
    )
    plot_strategy_map(
        strategy_map.widths,
        strategy_map.depths,
        strategy_map.chosen,
        strategy_map.correct,
        run_dir / "fig7_strategy_map.png",
        training_boxes=list(train_boxes),
        title=f"Initial strategy, D={max(settings.train_sizes)}, seed {settings.seeds[0]}",
    )
    return {
        "fig6_progress.png": "predicted vs expected progress (Fig. 6)",
        "fig7_strategy_map.png": "chosen vs correct initial strategy (Fig. 7)",
    }


def write_timings(
    run_dir: Path,
    seconds: float,
    workers: int,
    stage_seconds: Mapping[str, float],
    executor: str = "local",
) -> Path:
    """``timings.json``: the run's wall time [s], executor, jobs at once, seconds per stage.

    The stage seconds are wall seconds summed over seeds and training sizes.
    """
    return write_json(
        run_dir / "timings.json",
        {
            "seconds": seconds,
            "executor": executor,
            "workers": workers,
            "stages": dict(stage_seconds),
            "note": "stage times are wall seconds summed over seeds and training sizes; with "
            "workers > 1 they add up to more than the run's wall time",
        },
    )


# ----------------------------------------------------------------------------- markdown
def _method_line(report: Mapping[str, JsonValue]) -> str:
    """The sentence saying which predictor and sequencer ran, with their options."""
    seq = report.get("sequencer") or {}
    if is_goal_nearest(seq):
        return (
            f"Sequencer `{GOAL_NEAREST}` (the baseline without learned progress): a variable "
            f"switches once every feature its active MP moves (L1 path share >= "
            f"{seq.get('motion_share', '–')}) has stayed slower than "
            f"{seq.get('speed_threshold', '–')} scaled units/s for {seq.get('hold_time', '–')} s, "
            "to the successor whose demonstrated entry states are nearest; each variable starts "
            "at the initial MP with the nearest demonstrated entry state (feature scaling "
            f"`{seq.get('feature_scaling', '–')}`). No progress predictor is trained or used "
            "(the `predictor` group is ignored), so there is no coupling and no stall recovery"
        )
    if baseline_kind(seq) == BC:
        return (
            f"Sequencer `{BC}` (behaviour cloning, the baseline without learned progress): per "
            "variable and MP a kernel logistic regression of stay / successor trained on every "
            f"demonstrated tick (RBF γ {seq.get('gamma', '–')} on `"
            f"{seq.get('feature_scaling', '–')}`-scaled features, at most "
            f"{seq.get('max_supports', '–')} support points per node plus every switch tick, l2 "
            f"{seq.get('l2', '–')}, class weight `{seq.get('class_weight', '–')}`); a variable "
            f"switches when a successor's probability exceeds {seq.get('threshold', '–')}; each "
            "variable starts at the initial MP with the nearest demonstrated first sample. No "
            "progress predictor is trained or used (the `predictor` group is ignored), so there "
            "is no coupling and no stall recovery"
        )
    pred = report["predictor"]
    return (
        f"Predictor `{pred['kind']}` (feature weighting `{pred.get('feature_weighting', '–')}`, "
        f"scaling `{pred.get('feature_scaling', '–')}`), start rule "
        f"`{seq.get('start_rule', 'independent')}`, switching rule "
        f"`{seq.get('switch_rule', 'plateau')}`, coupling `{seq.get('coupling', 'none')}`, "
        f"recovery `{seq.get('recovery', False)}`"
    )


def render_markdown(report: Mapping[str, JsonValue]) -> str:
    """The human-readable report: Table I beside the paper's, progress errors, strategy map.

    The header names what ran: the predictor and the learned sequencer's rules, or the
    options of a baseline, ``goal_nearest`` or ``bc`` (whose progress numbers are labelled as
    a nearest-sample lookup it does not switch on).
    """
    exp = report["experiment"]
    baseline = baseline_kind(report.get("sequencer"))
    lines = [
        f"# cpmp experiment `{exp['name']}`",
        "",
        f"{_method_line(report)}; task settle time "
        f"{report.get('task', {}).get('settle_time', '–')} s, demonstration feature noise "
        f"{exp.get('feature_noise', 0.0)}; seeds {exp['seeds']}, {exp['n_boxes']} random boxes "
        "per training size and seed; counts are mean ± std over seeds.",
        "",
        "## Reproduction (Table I)",
        "",
        "| D | W | I | C | W / I / C (paper) | distance | distance, continuous features "
        "| distance (paper) | recoveries |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for d, row in report["reproduction"].items():
        paper = PAPER_TABLE_I.get(d)
        paper_counts = f"{paper['W']} / {paper['I']} / {paper['C']}" if paper else "–"
        paper_dist = _fmt(paper["distance_mean"], paper["distance_std"]) if paper else "–"
        lines.append(
            f"| {d} | {_fmt(row['W'], row['W_std'], 1)} | {_fmt(row['I'], row['I_std'], 1)} | "
            f"{_fmt(row['C'], row['C_std'], 1)} | {paper_counts} | "
            f"{_fmt(row['distance_mean'], row['distance_std'])} | "
            f"{_fmt(row.get('distance_continuous_mean'), row.get('distance_continuous_std'))} | "
            f"{paper_dist} | {'–' if baseline else _fmt(row.get('recoveries'), None, 1)} |"
        )
    lines += [
        "",
        f"Of {exp['n_boxes']} boxes: W = wrong start, I = incomplete (wrong transition, deadlock, "
        "time-out or diverged physics), C = complete. The paper's counts are of 20 boxes.",
        "Distance: Euclidean feature-space distance between the state at which the sequencer "
        "triggered a transition and the state at which the scripted demonstrator switched on "
        "the same box (k-th switch of each variable paired with the k-th), pooled over all "
        "complete episodes; the continuous column leaves out binary features (touch signals), "
        "which flip by 1 when a switch comes a tick early or late. Recoveries: stalls resolved "
        "per seed (mean).",
        "",
    ]
    causes = [
        f"D = {d}: " + ", ".join(f"{reason} {n}" for reason, n in row["causes"].items())
        for d, row in report["reproduction"].items()
        if row.get("causes")
    ]
    if causes:
        lines += [
            "Causes of the incomplete episodes, all seeds (the switch that never came and why; "
            "each episode's in `episodes.json`): " + "; ".join(causes) + ".",
            "",
        ]
    if baseline:
        lines += [
            "## Progress estimate (nearest-sample lookup, not used to switch)",
            "",
            f"Not a learned prediction: {nearest_progress_note(baseline)}. Held-out "
            "demonstrations.",
            "",
        ]
    else:
        lines += ["## Progress prediction (Fig. 6)", ""]
    lines += ["| D | MAE | MAE first 10 % | MAE last 10 % |", "| --- | --- | --- | --- |"]
    for d, row in report["progress"]["by_train_size"].items():
        lines.append(
            f"| {d} | {_fmt(row['mae'], row['mae_std'], 3)} | {_fmt(row['mae_first'], None, 3)} "
            f"| {_fmt(row['mae_last'], None, 3)} |"
        )
    smap = report.get("strategy_map")
    if smap:
        lines += [
            "",
            "## Strategy map (Fig. 7)",
            "",
            f"Initial strategy correct on {_fmt(100 * smap['accuracy'], None, 1)} % of a "
            f"{smap['grid'][0]} x {smap['grid'][1]} width x depth grid (D = {smap['train_size']},"
            f" mean over seeds).",
        ]
    warnings = report.get("fit_warnings") or []
    if warnings:
        lines += ["", "## Fit warnings", ""]
        lines += [f"- {text}" for text in warnings]
    lines += ["", "## Files", ""]
    lines += [f"- `{name}`: {what}" for name, what in report.get("files", {}).items()]
    return "\n".join(lines) + "\n"


def write_report(report: Mapping[str, JsonValue], run_dir: str | Path) -> Path:
    """Write ``report.json`` and ``report.md`` into ``run_dir``; returns the JSON path."""
    run_dir = Path(run_dir)
    write_json(run_dir / "report.json", report)
    atomic_write_text(run_dir / "report.md", render_markdown(jsonable(report)))
    return run_dir / "report.json"
