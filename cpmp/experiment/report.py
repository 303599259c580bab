"""Report files of the main job: ``report.json`` (machine-readable) and ``report.md``."""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from cpmp.io import atomic_write_text, to_builtin

PAPER_TABLE_I: dict[str, dict[str, float]] = {
    "3": {"W": 3, "I": 4, "C": 13, "distance_mean": 0.13, "distance_std": 0.08},
    "6": {"W": 3, "I": 2, "C": 15, "distance_mean": 0.07, "distance_std": 0.04},
    "9": {"W": 2, "I": 2, "C": 16, "distance_mean": 0.06, "distance_std": 0.03},
}
"""The paper's Table I (20 random boxes per D)."""


jsonable = to_builtin
"""Recursively convert numpy values and tuples to JSON types (NaN -> None)."""


def write_json(path: str | Path, obj: Any) -> Path:
    """Write ``obj`` as indented JSON, atomically."""
    atomic_write_text(path, json.dumps(jsonable(obj), indent=2) + "\n")
    return Path(path)


def mean_std(values: list[float | None]) -> tuple[float | None, float | None]:
    """Mean and (population) std of the non-missing values."""
    xs = [v for v in values if v is not None]
    if not xs:
        return None, None
    return float(np.mean(xs)), float(np.std(xs))


def _fmt(mean: float | None, std: float | None = None, digits: int = 2) -> str:
    if mean is None:
        return "–"
    if std is None:
        return f"{mean:.{digits}f}"
    return f"{mean:.{digits}f} ± {std:.{digits}f}"


GOAL_NEAREST = "goal_nearest"
"""The ``sequencer.kind`` of the baseline without a progress predictor (:mod:`cpmp.goal_nearest`;
kept as a string here so that writing a report imports no model code)."""

NEAREST_PROGRESS_NOTE = (
    "sequencer=goal_nearest trains no progress predictor (the predictor group is not used); "
    "its progress MAE is of a nearest-training-sample lookup of the expected progress (eq. 1), "
    "which it never uses to switch"
)
"""What the progress numbers of a ``goal_nearest`` run are."""


def is_goal_nearest(sequencer: Mapping[str, Any] | None) -> bool:
    """Whether a ``sequencer`` config (a mapping, possibly empty) selects the goal-nearest
    baseline."""
    return bool(sequencer) and sequencer.get("kind") == GOAL_NEAREST


def predictor_entry(
    kind: str, predictor: Mapping[str, Any], sequencer: Mapping[str, Any] | None
) -> dict[str, Any]:
    """The report's ``predictor`` entry: ``kind`` and the options of the predictor that ran, or
    for ``sequencer=goal_nearest`` (which runs none) ``kind: "none"``, the progress estimate it
    reports instead (``nearest_sample``) and a note saying so."""
    if is_goal_nearest(sequencer):
        return {
            "kind": "none",
            "progress_estimate": "nearest_sample",
            "used_to_switch": False,
            "note": NEAREST_PROGRESS_NOTE,
        }
    return {"kind": kind, **predictor}


def _method_line(report: Mapping[str, Any]) -> str:
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
    pred = report["predictor"]
    return (
        f"Predictor `{pred['kind']}` (feature weighting `{pred.get('feature_weighting', '–')}`, "
        f"scaling `{pred.get('feature_scaling', '–')}`), start rule "
        f"`{seq.get('start_rule', 'independent')}`, switching rule "
        f"`{seq.get('switch_rule', 'plateau')}`, coupling `{seq.get('coupling', 'none')}`, "
        f"recovery `{seq.get('recovery', False)}`"
    )


def render_markdown(report: Mapping[str, Any]) -> str:
    """The human-readable report: Table I beside the paper's, progress errors, strategy map.
    The header names what ran: the predictor and the learned sequencer's rules, or the
    ``goal_nearest`` baseline's options (whose progress numbers are labelled as a
    nearest-sample lookup it does not switch on)."""
    exp = report["experiment"]
    goal_nearest = is_goal_nearest(report.get("sequencer"))
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
            f"{paper_dist} | {'–' if goal_nearest else _fmt(row.get('recoveries'), None, 1)} |"
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
    if goal_nearest:
        lines += [
            "## Progress estimate (nearest-sample lookup, not used to switch)",
            "",
            f"Not a learned prediction: {NEAREST_PROGRESS_NOTE}. Held-out demonstrations.",
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


def write_report(report: Mapping[str, Any], run_dir: str | Path) -> Path:
    """Write ``report.json`` and ``report.md`` into ``run_dir``; returns the JSON path."""
    run_dir = Path(run_dir)
    write_json(run_dir / "report.json", report)
    atomic_write_text(run_dir / "report.md", render_markdown(jsonable(report)))
    return run_dir / "report.json"
