"""The results of the comparison (``cpmp-compare``).

The rows pooled over seeds (``compare.json``), the episodes and timings of every job, the
Markdown table (``compare.md``) and the two figures (``compare_c_vs_d.png``,
``compare_supports.png``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from matplotlib import colormaps
from matplotlib.ticker import NullFormatter, ScalarFormatter

from cpmp.compare.rows import FitJob, RowSpec
from cpmp.compare.runs import RowResult
from cpmp.experiment.collection import SeedData
from cpmp.experiment.output import PAPER_TABLE_I, jsonable, mean_std
from cpmp.experiment.plots import new_figure, save_figure
from cpmp.experiment.settings import ExperimentSettings

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


# ---------------------------------------------------------------------------- pooling
def aggregate_rows(
    specs: Sequence[RowSpec], settings: ExperimentSettings, results: Mapping[str, RowResult]
) -> list[dict[str, Any]]:
    """One row per spec and D: the :data:`ROW_FIELDS` as means over the seeds whose fit succeeded.

    The means (W/I/C: boxes of ``n_boxes``; mae in [0, 1]; fit_s [s]; tick_ms [ms]) come with
    their population std (``*_std``), the per-seed values and any refused fits (``errors``).
    """
    rows = []
    for spec in specs:
        for d in spec.train_sizes:
            per_seed = [results[spec.fit_key(seed, d)] for seed in settings.seeds]
            ok = [r for r in per_seed if not r.error]
            row: dict[str, Any] = {"predictor": spec.predictor, "sequencer": spec.sequencer, "D": d}
            for key in ("mae", "W", "I", "C", "fit_s", "tick_ms", "supports", "diverged"):
                row[key], std = mean_std([r.number(key) for r in ok])
                if key in ("mae", "W", "I", "C"):
                    row[f"{key}_std"] = std
            row.update(
                group=spec.group,
                support_scale=spec.support_scale,
                n_boxes=settings.n_boxes,
                seeds=list(settings.seeds),
                n_seeds=len(ok),
                per_seed={
                    key: [r.number(key) for r in per_seed]
                    for key in ("W", "I", "C", "mae", "supports")
                },
                errors=[
                    f"seed {seed}: {r.error}"
                    for seed, r in zip(settings.seeds, per_seed, strict=True)
                    if r.error
                ],
            )
            rows.append(jsonable(row))
    return rows


def job_episodes(
    results: Mapping[str, RowResult], jobs: Mapping[str, FitJob]
) -> list[dict[str, Any]]:
    """Every reproduction episode of every job, labelled with its row, seed and D.

    A fit shared by two rows is listed once, under the first.
    """
    out = []
    for key, (spec, seed, d) in jobs.items():
        label = {
            "predictor": spec.predictor,
            "sequencer": spec.sequencer,
            "support_scale": spec.support_scale,
            "seed": seed,
            "D": d,
        }
        out += [{**label, **episode} for episode in results[key].episodes]
    return out


def job_timings(
    collected: Mapping[int, SeedData],
    results: Mapping[str, RowResult],
    jobs: Mapping[str, FitJob],
    seconds: float,
    workers: int,
) -> dict[str, Any]:
    """Wall time of the run; wall and CPU seconds of every stage of every job.

    These scale the run's cost to other box or seed counts.
    """
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
                "seconds": r.seconds,
                "cpu_seconds": r.cpu_seconds,
                "boxes": len(r.episodes),
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
    """``value`` with ``digits`` decimals, ``–`` for ``None``."""
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
    """``compare.md``: the rows by predictor beside the paper's Table I, then the support sweep.

    Each row shows W / I / C per D, progress MAE, fit and tick time and support points.
    """
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
    """A new figure of ``width`` x ``height`` inches and its row of ``ncols`` axes."""
    figure = new_figure(width, height)
    return figure, figure.subplots(1, ncols, squeeze=False)[0]


_MARKERS = ("o", "s", "^", "v", "D", "P", "X", "<", ">", "*")


def _colours(n: int) -> list[Any]:
    """``n`` distinguishable colours (tab10, then tab20)."""
    cmap = colormaps["tab10" if n <= 10 else "tab20"]
    return [cmap(i % cmap.N) for i in range(n)]


def _percent(value: float | None, n: int) -> float:
    """``value`` as a percentage of ``n`` (nan for ``None``)."""
    return math.nan if value is None else 100.0 * value / n


def plot_c_vs_d(
    rows: Sequence[Mapping[str, Any]], settings: ExperimentSettings, path: Path
) -> Path:
    """Complete episodes [% of boxes] against D, one line per predictor/sequencer.

    Error bars are the std over seeds; the paper's Table I is dashed.
    """
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
    return save_figure(figure, path)


def plot_supports(
    rows: Sequence[Mapping[str, Any]], settings: ExperimentSettings, path: Path
) -> Path:
    """The support sweep: complete episodes and progress MAE against the support points.

    Complete episodes are in % of boxes, the support points on a log scale; one line per D.
    """
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
    return save_figure(figure, path)
