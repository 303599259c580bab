"""The comparison's figures, drawn from ``compare.json``'s content (every bar an interval).

``compare_c_vs_d.png`` (complete episodes against D, one panel per world),
``compare_claims.png`` (each claim's paired differences in every world) and
``compare_supports.png`` (MAE, complete episodes and tick cost against the support points).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

from matplotlib import colormaps
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.ticker import NullFormatter, ScalarFormatter

from cpmp.compare.pooling import CompareResult, RowRecord
from cpmp.compare.stats import IntervalRecord
from cpmp.experiment.output import PAPER_TABLE_I
from cpmp.experiment.plots import new_figure, save_figure

_MARKERS = ("o", "s", "^", "v", "D", "P", "X", "<", ">", "*")


def _colours(n: int) -> list[tuple[float, float, float, float]]:
    """``n`` distinguishable colours (tab10, then tab20)."""
    cmap = colormaps["tab10" if n <= 10 else "tab20"]
    return [cmap(i % cmap.N) for i in range(n)]


def _bars(value: IntervalRecord | None, scale: float = 1.0) -> tuple[float, float, float]:
    """``(estimate, below, above)`` of an interval record times ``scale`` (nan for none)."""
    if value is None:
        return math.nan, math.nan, math.nan
    est = scale * value["estimate"]
    return est, est - scale * value["low"], scale * value["high"] - est


def _grid(n: int, width: float, height: float) -> tuple[Figure, list[Axes]]:
    """A figure with ``n`` panels in rows of at most three."""
    ncols = min(n, 3)
    nrows = math.ceil(n / ncols)
    figure = new_figure(width * ncols, height * nrows)
    axes = figure.subplots(nrows, ncols, squeeze=False).ravel().tolist()
    for ax in axes[n:]:
        ax.set_visible(False)
    return figure, axes[:n]


def plot_c_vs_d(result: CompareResult, path: Path) -> Path:
    """Complete episodes [%] against D, one line per row, one panel per world.

    Error bars are the 95 % intervals; the paper's Table I is dashed in the default simulated
    world.
    """
    worlds = [w for w in result["worlds"]]
    table = [r for r in result["rows"] if r["group"] != "support_sweep"]
    figure, axes = _grid(max(len(worlds), 1), 4.6, 3.6)
    for ax, world in zip(axes, worlds, strict=False):
        mine = [r for r in table if r["world"] == world["name"]]
        names = list(dict.fromkeys(r["name"] for r in mine))
        colours = _colours(len(names))
        for i, name in enumerate(names):
            rows = sorted((r for r in mine if r["name"] == name), key=lambda r: r["D"])
            shift = 0.08 * (i - (len(names) - 1) / 2)  # side by side: equal values stay visible
            bars = [_bars(r["C"], 100.0) for r in rows]
            ax.errorbar(
                [r["D"] + shift for r in rows],
                [b[0] for b in bars],
                yerr=[[b[1] for b in bars], [b[2] for b in bars]],
                marker=_MARKERS[i % len(_MARKERS)],
                color=colours[i],
                capsize=3,
                label=name,
            )
        sizes = sorted({r["D"] for r in mine})
        if world["kind"] == "sim" and not world["options"] and not world["feature_noise"]:
            paper = [(d, PAPER_TABLE_I[str(d)]["C"]) for d in sizes if str(d) in PAPER_TABLE_I]
            if paper:
                ax.plot(
                    [d for d, _ in paper],
                    [100.0 * c / 20 for _, c in paper],
                    "k--",
                    marker="s",
                    label="paper, Table I",
                )
        ax.set_xticks(sizes)
        ax.set_ylim(-5, 105)
        ax.set_xlabel("training demonstrations D")
        ax.set_ylabel("complete [% of episodes]")
        ax.set_title(world["name"], fontsize=9)
        ax.legend(fontsize=6, loc="lower right")
    return save_figure(figure, path)


def plot_claims(result: CompareResult, path: Path) -> Path:
    """Each claim's paired difference a − b in C [pp] and in MAE, per world and D.

    One row of points per (claim, world, D), its 95 % interval as a bar; a filled point is a
    significant difference (the interval excludes 0 and the sign-flip test agrees).
    """
    claims = result["claims"]
    figure = new_figure(10.0, 1.2 + 0.28 * max(len(claims), 1))
    left, right = figure.subplots(1, 2, sharey=True)
    names = list(dict.fromkeys(c["claim"] for c in claims))
    colours = _colours(max(len(names), 1))
    labels = []
    for y, c in enumerate(claims):
        colour = colours[names.index(c["claim"])]
        labels.append(f"{c['world']}, D = {c['D']}")
        for ax, key, scale in ((left, "C", 100.0), (right, "mae", 1.0)):
            est, below, above = _bars(c[key], scale)
            significant = bool(c[key] and c[key]["significant"])
            ax.errorbar(
                [est],
                [y],
                xerr=[[below], [above]],
                fmt="o",
                color=colour,
                mfc=colour if significant else "white",
                capsize=3,
                ms=5,
            )
    for ax in (left, right):
        ax.axvline(0.0, color="k", ls="--", lw=0.8)
    left.invert_yaxis()  # the axes share y: once inverts both
    left.set_yticks(range(len(labels)), labels, fontsize=7)
    left.set_xlabel("ΔC = C(a) − C(b) [percentage points]")
    right.set_xlabel("ΔMAE = MAE(a) − MAE(b)")
    for name, colour in zip(names, colours, strict=False):
        pair = next(c for c in claims if c["claim"] == name)
        left.plot([], [], "o", color=colour, label=f"{name}: {pair['a']} − {pair['b']}")
    if names:
        left.legend(fontsize=7, loc="lower left", bbox_to_anchor=(0.0, 1.0))
    return save_figure(figure, path)


def plot_supports(rows: Sequence[RowRecord], path: Path) -> Path:
    """The support-count axis: MAE, complete episodes and tick cost against support points.

    One line per world, D and predictor (its points sorted by supports; the predictor's own
    choice is a star), error bars the 95 % intervals; support points on a log scale.
    """
    figure = new_figure(13.0, 3.8)
    panels = figure.subplots(1, 3)
    sweep = [r for r in rows if r["group"] == "support_sweep" and r["supports"] is not None]
    series = list(dict.fromkeys((r["world"], r["D"], r["predictor"]) for r in sweep))
    colours = _colours(max(len(series), 1))
    for i, (world, d, predictor) in enumerate(series):
        mine = sorted(
            (r for r in sweep if (r["world"], r["D"], r["predictor"]) == (world, d, predictor)),
            key=lambda r: r["supports"]["estimate"],
        )
        x = [r["supports"]["estimate"] for r in mine]
        for ax, key, scale in zip(panels, ("mae", "C", "tick_ms"), (1.0, 100.0, 1.0), strict=True):
            bars = [_bars(r[key], scale) for r in mine]
            ax.errorbar(
                x,
                [b[0] for b in bars],
                yerr=[[b[1] for b in bars], [b[2] for b in bars]],
                marker=_MARKERS[i % len(_MARKERS)],
                color=colours[i],
                capsize=3,
                label=f"{predictor} ({world}, D = {d})",
            )
            own = [(xi, b[0]) for xi, b, r in zip(x, bars, mine, strict=True) if r["value"] is None]
            if own:
                ax.plot(*zip(*own, strict=True), "*", color=colours[i], ms=12)
    for ax, label in zip(
        panels,
        ("progress MAE (held-out)", "complete [% of episodes]", "tick [ms]"),
        strict=True,
    ):
        ax.set_xscale("log")
        ax.xaxis.set_major_formatter(ScalarFormatter())
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_xlabel("support points (all nodes)")
        ax.set_ylabel(label)
    panels[1].set_ylim(-5, 105)
    if series:
        panels[0].legend(fontsize=7)
    panels[0].set_title("star: the predictor's own choice", fontsize=8)
    return save_figure(figure, path)
