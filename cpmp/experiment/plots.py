"""The paper's figures as PNG files, and a plot of aggregated sweep results.

The progress field (Fig. 3), progress curves (Fig. 6) and strategy map (Fig. 7).

Figures are built as :class:`matplotlib.figure.Figure` objects rendered by the Agg canvas, not
through ``pyplot``: no global backend is switched, no figure is left registered (nothing to
close), and each PNG is written atomically (a failed plot leaves no partial file).
"""

from __future__ import annotations

import math
import numbers
import os
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TypeAlias

import numpy as np
import numpy.typing as npt
from matplotlib.artist import Artist
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import LineCollection
from matplotlib.colors import BoundaryNorm, ListedColormap
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch, Rectangle

from cpmp.errors import ConfigError, DataError
from cpmp.io import atomic_path

Cell: TypeAlias = "str | int | float | bool | None"
"""A value of a table cell (:func:`plot_sweep`): a number, a text, a flag or missing."""

CURVE_KEYS = ("time", "predicted_mean", "predicted_std", "expected_mean")
"""Keys :func:`plot_progress_curves` needs in each curves dict (see
:func:`cpmp.evaluation.offline.progress_curves`)."""

_STRATEGY_COLOURS = ("#4daf4a", "#ffd92f", "#377eb8")  # green, yellow, blue as in the paper
_OTHER_COLOUR = "#e41a1c"  # red: a strategy that was never demonstrated
_DPI = 120


def new_figure(width: float, height: float) -> Figure:
    """An empty figure of ``width`` x ``height`` inches on the Agg canvas (no pyplot)."""
    figure = Figure(figsize=(width, height), dpi=_DPI, layout="constrained")
    FigureCanvasAgg(figure)
    return figure


def save_figure(figure: Figure, path: str | os.PathLike[str]) -> Path:
    """Write ``figure`` as a PNG to ``path`` atomically and free it; returns the path."""
    with atomic_path(path) as tmp:
        figure.savefig(tmp, format="png")
    figure.clear()
    return Path(path)


def _points(value: npt.ArrayLike, name: str) -> np.ndarray:
    """``value`` as (n, 2) float array; a single (2,) point becomes (1, 2)."""
    array = np.asarray(value, dtype=float)
    if array.ndim == 1 and array.size == 2:
        array = array[None, :]
    if array.size == 0:
        return np.zeros((0, 2))
    if array.ndim != 2 or array.shape[1] != 2:
        raise DataError(f"{name} must have shape (n, 2), got {array.shape}")
    if not np.all(np.isfinite(array)):
        raise DataError(f"{name} contains NaN or inf")
    return array


def plot_progress_field(
    predict: Callable[[np.ndarray], np.ndarray],
    trajectories: Sequence[np.ndarray],
    support_points: np.ndarray | Sequence[np.ndarray],
    path: str | os.PathLike[str],
    *,
    bounds: tuple[tuple[float, float], tuple[float, float]] | None = None,
    resolution: int = 200,
    title: str | None = None,
) -> Path:
    """Fig. 3: predicted progress over a 2-D feature plane, with trajectories and support points.

    ``predict`` maps points (N, 2) to progress (N,) in [0, 1]; ``trajectories``: list of (n_i, 2)
    drawn as lines from start (circle) to end (arrow); ``support_points``: (M, 2), or a list of
    (m_i, 2), drawn as black crosses; ``bounds``: ((x_min, x_max), (y_min, y_max)), default the
    data's extent plus 10 %; ``resolution``: grid points per axis. Returns ``path``.
    """
    if int(resolution) < 2:
        raise ConfigError(f"resolution must be >= 2, got {resolution}")
    resolution = int(resolution)
    paths = [_points(t, f"trajectories[{i}]") for i, t in enumerate(trajectories)]
    if isinstance(support_points, np.ndarray):
        supports = _points(support_points, "support_points")
    else:
        items = [np.asarray(s, dtype=float) for s in support_points]
        if items and all(item.ndim == 2 for item in items):
            supports = np.concatenate(
                [_points(item, f"support_points[{i}]") for i, item in enumerate(items)]
            )
        else:
            supports = _points(np.asarray(items), "support_points")
    if bounds is None:
        everything = np.concatenate([*paths, supports])
        if len(everything) == 0:
            raise DataError("no trajectories or support points, and no bounds given")
        low, high = everything.min(axis=0), everything.max(axis=0)
        margin = np.where(high > low, 0.1 * (high - low), 1.0)
        (x0, y0), (x1, y1) = low - margin, high + margin
    else:
        (x0, x1), (y0, y1) = (tuple(map(float, axis)) for axis in bounds)
        if not (x0 < x1 and y0 < y1):
            raise ConfigError(f"bounds must be ((x_min, x_max), (y_min, y_max)), got {bounds}")

    xs, ys = np.linspace(x0, x1, resolution), np.linspace(y0, y1, resolution)
    grid_x, grid_y = np.meshgrid(xs, ys)
    grid = np.column_stack([grid_x.ravel(), grid_y.ravel()])
    values = np.asarray(predict(grid), dtype=float)
    if values.shape not in ((len(grid),), (len(grid), 1)):
        raise DataError(f"predict must map ({len(grid)}, 2) to ({len(grid)},), got {values.shape}")
    if not np.all(np.isfinite(values)):
        raise DataError("predict returned NaN or inf")

    figure = new_figure(6.0, 5.0)
    ax = figure.add_subplot()
    image = ax.imshow(
        values.reshape(resolution, resolution),
        origin="lower",
        extent=(x0, x1, y0, y1),
        aspect="auto",
        cmap="coolwarm",
        vmin=0.0,
        vmax=1.0,
        interpolation="nearest",
    )
    for points in paths:
        ax.plot(points[:, 0], points[:, 1], color="k", linewidth=1.5)
        ax.plot(*points[0], marker="o", markerfacecolor="w", markeredgecolor="k")
        if len(points) >= 2:
            ax.annotate(
                "",
                xy=points[-1],
                xytext=points[-2],
                arrowprops={"arrowstyle": "-|>", "color": "k", "linewidth": 1.5},
            )
    if len(supports):
        ax.scatter(supports[:, 0], supports[:, 1], marker="x", color="k", s=50, linewidths=1.8)
    figure.colorbar(image, ax=ax, label="predicted progress φ")
    ax.set(xlim=(x0, x1), ylim=(y0, y1), xlabel="feature $x_1$", ylabel="feature $x_2$")
    ax.set_title(title or "predicted progress")
    return save_figure(figure, path)


def plot_progress_curves(
    curves_by_label: Mapping[str, Mapping[str, npt.ArrayLike]],
    path: str | os.PathLike[str],
    title: str | None = None,
) -> Path:
    """Fig. 6: mean predicted progress over normalised time, one panel per label.

    Each panel (e.g. "3 demos") has the mean predicted progress with the spread of the
    predictions over the activations (±2 std, clipped to φ's range [0, 1]: a spread, not an
    uncertainty of the predictor), the mean expected progress (dashed) and the ideal diagonal.

    Each value is a dict from :func:`cpmp.evaluation.offline.progress_curves` (needs
    :data:`CURVE_KEYS`).
    """
    if not curves_by_label:
        raise DataError("curves_by_label is empty")
    for label, curves in curves_by_label.items():
        missing = [key for key in CURVE_KEYS if key not in curves]
        if missing:
            raise DataError(f"curves for {label!r} lack {missing}; use progress_curves()")
        shapes = {np.shape(curves[key]) for key in CURVE_KEYS}
        if len(shapes) != 1 or len(next(iter(shapes))) != 1:
            raise DataError(f"curves for {label!r} must be 1-D arrays of one length, got {shapes}")

    n_panels = len(curves_by_label)
    figure = new_figure(3.6 * n_panels, 3.6)
    axes = figure.subplots(1, n_panels, sharey=True, squeeze=False)[0]
    for ax, (label, curves) in zip(axes, curves_by_label.items(), strict=True):
        time = np.asarray(curves["time"], dtype=float)
        mean = np.asarray(curves["predicted_mean"], dtype=float)
        std = np.asarray(curves["predicted_std"], dtype=float)
        low, high = np.clip(mean - 2 * std, 0.0, 1.0), np.clip(mean + 2 * std, 0.0, 1.0)
        ax.fill_between(time, low, high, alpha=0.3, label="spread over activations (±2 std)")
        ax.plot(time, mean, linewidth=2, label="predicted (mean)")
        ax.plot(time, curves["expected_mean"], "--", color="C1", label="expected (mean)")
        ax.plot([0, 1], [0, 1], color="k", linewidth=1, label="ideal")
        ax.set(xlim=(0, 1), ylim=(-0.1, 1.1), xlabel="normalised time", title=str(label))
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("progress φ")
    axes[0].legend(loc="upper left", fontsize="small")
    if title:
        figure.suptitle(title)
    return save_figure(figure, path)


def _cell_edges(centres: np.ndarray) -> np.ndarray:
    middle = 0.5 * (centres[:-1] + centres[1:])
    return np.concatenate([[2 * centres[0] - middle[0]], middle, [2 * centres[-1] - middle[-1]]])


def _region_boundaries(
    labels: np.ndarray, x_edges: np.ndarray, y_edges: np.ndarray
) -> list[np.ndarray]:
    """Cell-edge segments (2, 2) separating neighbouring cells of ``labels`` (D, W) that differ."""
    segments = []
    for row, column in zip(*np.nonzero(labels[:, 1:] != labels[:, :-1]), strict=True):
        x = x_edges[column + 1]
        segments.append(np.array([[x, y_edges[row]], [x, y_edges[row + 1]]]))
    for row, column in zip(*np.nonzero(labels[1:, :] != labels[:-1, :]), strict=True):
        y = y_edges[row + 1]
        segments.append(np.array([[x_edges[column], y], [x_edges[column + 1], y]]))
    return segments


def _axis_values(values: npt.ArrayLike, name: str) -> np.ndarray:
    array = np.asarray(values, dtype=float)
    if array.ndim != 1 or len(array) < 2:
        raise DataError(f"{name} must have shape (n,) with n >= 2, got {array.shape}")
    if not np.all(np.diff(array) > 0):
        raise DataError(f"{name} must be strictly increasing")
    return array


def plot_strategy_map(
    widths: np.ndarray,
    depths: np.ndarray,
    chosen: np.ndarray,
    correct: np.ndarray,
    path: str | os.PathLike[str],
    *,
    training_boxes: Sequence[tuple[float, float]] | None = None,
    strategies: Sequence[str] = ("both", "right", "left"),
    title: str | None = None,
) -> Path:
    """Fig. 7: the strategy chosen per box size, against the correct one.

    ``widths`` (W,) and ``depths`` (D,) [m], strictly increasing, are the grid's cell centres;
    ``chosen`` and ``correct`` (D, W) hold strategy names. Cells are coloured by the chosen
    strategy (any name not in ``strategies`` is "other", in red); cells where chosen != correct
    are hatched; black lines along cell edges are the boundaries of the correct regions;
    ``training_boxes`` (width, depth) pairs [m] are black crosses. The default title gives the
    fraction correct.
    """
    widths, depths = _axis_values(widths, "widths"), _axis_values(depths, "depths")
    strategies = [str(s) for s in strategies]
    if not strategies or len(set(strategies)) != len(strategies):
        raise ConfigError(f"strategies must be unique names, got {strategies}")
    expected_shape = (len(depths), len(widths))
    grids = {}
    for name, grid in (("chosen", chosen), ("correct", correct)):
        array = np.asarray(grid, dtype=object)
        if array.shape != expected_shape:
            raise DataError(
                f"{name} must have shape (D, W) = {expected_shape} (depths x widths), "
                f"got {array.shape}"
            )
        grids[name] = array
    boxes = _points(training_boxes if training_boxes is not None else [], "training_boxes")

    other = len(strategies)
    lookup = {name: k for k, name in enumerate(strategies)}

    def to_index(names: np.ndarray) -> np.ndarray:
        return np.vectorize(lambda s: lookup.get(str(s), other), otypes=[int])(names)

    chosen_index, correct_index = to_index(grids["chosen"]), to_index(grids["correct"])
    mismatch = grids["chosen"].astype(str) != grids["correct"].astype(str)
    colours = [*_STRATEGY_COLOURS, *(f"C{k + 3}" for k in range(max(0, other - 3)))][:other]
    colours.append(_OTHER_COLOUR)

    figure = new_figure(6.8, 5.0)
    ax = figure.add_subplot()
    x_edges, y_edges = _cell_edges(widths), _cell_edges(depths)
    ax.pcolormesh(
        x_edges,
        y_edges,
        chosen_index,
        cmap=ListedColormap(colours),
        norm=BoundaryNorm(np.arange(other + 2) - 0.5, other + 1),
    )
    for row, column in zip(*np.nonzero(mismatch), strict=True):
        ax.add_patch(
            Rectangle(
                (x_edges[column], y_edges[row]),
                x_edges[column + 1] - x_edges[column],
                y_edges[row + 1] - y_edges[row],
                facecolor="none",
                edgecolor="k",
                hatch="xx",
                linewidth=0.0,
            )
        )
    ax.add_collection(
        LineCollection(_region_boundaries(correct_index, x_edges, y_edges), colors="k")
    )
    if len(boxes):
        ax.scatter(boxes[:, 0], boxes[:, 1], marker="x", color="k", s=60, linewidths=2)

    handles: list[Artist] = [
        Patch(facecolor=colour, label=name)
        for colour, name in zip(colours[:other], strategies, strict=True)
    ]
    handles += [
        Patch(facecolor=_OTHER_COLOUR, label="other (not demonstrated)"),
        Patch(facecolor="none", edgecolor="k", hatch="xx", label="chosen ≠ correct"),
        Line2D([], [], color="k", label="correct boundary"),
    ]
    if len(boxes):
        handles.append(
            Line2D([], [], marker="x", color="k", linestyle="none", label="demonstrations")
        )
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize="small")
    ax.set(
        xlim=(x_edges[0], x_edges[-1]),
        ylim=(y_edges[0], y_edges[-1]),
        xlabel="box width [m]",
        ylabel="box depth [m]",
    )
    accuracy = 1.0 - mismatch.mean()
    ax.set_title(title or f"chosen initial strategy ({accuracy:.1%} correct)")
    return save_figure(figure, path)


def _is_number(value: object) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


def plot_sweep(
    table: Sequence[Mapping[str, Cell]],
    x: str,
    y: str,
    hue: str | None,
    path: str | os.PathLike[str],
    *,
    title: str | None = None,
) -> Path:
    """Plot aggregated multirun results: ``y`` against ``x``, one series per value of ``hue``.

    ``table``: one row per (hue, x) combination. Numeric ``x`` gives lines, categorical ``x``
    grouped bars; the row key ``f"{y}_std"``, where present, gives error bars (± 1 std).
    """
    if not table:
        raise DataError("plot_sweep needs a non-empty table")
    required = [x, y] + ([hue] if hue is not None else [])
    series: dict[Cell, dict[Cell, tuple[float, float]]] = {}
    for i, row in enumerate(table):
        missing = [key for key in required if key not in row]
        if missing:
            raise DataError(f"table[{i}] lacks {missing}; it has {sorted(row)}")
        try:
            value = float(row[y])
            std = float(row.get(f"{y}_std", math.nan))
        except (TypeError, ValueError) as err:
            raise DataError(f"table[{i}]: {y!r} must be a number, got {row[y]!r}") from err
        group = series.setdefault(row[hue] if hue is not None else None, {})
        if row[x] in group:
            raise DataError(
                f"table[{i}] repeats {x}={row[x]!r}"
                + (f", {hue}={row[hue]!r}" if hue else "")
                + "; aggregate the runs first"
            )
        group[row[x]] = (value, std)

    x_values = list(dict.fromkeys(row[x] for row in table))
    numeric = all(_is_number(v) for v in x_values)
    figure = new_figure(6.0, 4.0)
    ax: Axes = figure.add_subplot()
    width = 0.8 / len(series)
    for k, (name, group) in enumerate(series.items()):
        keys = sorted(group) if numeric else [v for v in x_values if v in group]
        means = np.array([group[key][0] for key in keys])
        stds = np.array([group[key][1] for key in keys])
        error = None if np.all(np.isnan(stds)) else np.nan_to_num(stds)
        label = None if hue is None else f"{hue}={name}"
        if numeric:
            ax.errorbar(keys, means, yerr=error, marker="o", capsize=3, label=label)
        else:
            positions = [x_values.index(key) - 0.4 + (k + 0.5) * width for key in keys]
            ax.bar(positions, means, width=width, yerr=error, capsize=3, label=label)
    if not numeric:
        ax.set_xticks(range(len(x_values)), [str(v) for v in x_values])
    ax.set(xlabel=x, ylabel=y)
    ax.set_axisbelow(True)
    ax.grid(alpha=0.3)
    if hue is not None:
        ax.legend(fontsize="small")
    ax.set_title(title or f"{y} by {x}" + (f" and {hue}" if hue else ""))
    return save_figure(figure, path)


__all__ = [
    "CURVE_KEYS",
    "plot_progress_curves",
    "plot_progress_field",
    "plot_strategy_map",
    "plot_sweep",
]
