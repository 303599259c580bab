"""Figures: PNG output and argument validation (the statistics behind Fig. 6 are tested with
:func:`cpmp.evaluation.offline.progress_curves` in ``tests/test_evaluation.py``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from matplotlib import colormaps
from matplotlib.colors import to_rgb
from matplotlib.image import imread

from cpmp.errors import ConfigError, DataError
from cpmp.evaluation.offline import progress_curves
from cpmp.experiment import plots
from cpmp.experiment.plots import (
    plot_progress_curves,
    plot_progress_field,
    plot_strategy_map,
    plot_sweep,
)

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _png_pixels(path: Path) -> np.ndarray:
    """Check ``path`` is a non-trivial PNG; return its RGB pixels (H, W, 3) in [0, 1]."""
    data = path.read_bytes()
    assert data[:8] == PNG_SIGNATURE
    assert len(data) > 1000
    return imread(path, format="png")[..., :3]


def _fraction_of_colour(pixels: np.ndarray, rgb: tuple[float, float, float]) -> float:
    # PNG stores 8-bit channels: 2/255 absorbs rounding of the colour.
    return float(np.mean(np.all(np.abs(pixels - np.array(rgb)) < 2 / 255, axis=-1)))


def _trajectories() -> list[np.ndarray]:
    s = np.linspace(0.0, 1.0, 20)
    return [np.column_stack([s, s**2 + offset]) for offset in (0.0, 0.5)]


@pytest.mark.parametrize("level", [0.0, 1.0])
def test_progress_field_shows_prediction(tmp_path: Path, level: float) -> None:
    trajectories = _trajectories()
    path = plot_progress_field(
        lambda points: np.full(len(points), level),
        trajectories,
        [t[[0, 10, 19]] for t in trajectories],
        tmp_path / "field.png",
        resolution=50,
        title="synthetic",
    )
    pixels = _png_pixels(path)
    colour_of = colormaps["coolwarm"]
    shown = _fraction_of_colour(pixels, colour_of(level)[:3])
    other = _fraction_of_colour(pixels, colour_of(1.0 - level)[:3])
    assert shown > 0.3  # the background fills most of the figure
    assert shown > 5 * other  # the other end only appears in the colour bar


def test_progress_field_rejects_bad_input(tmp_path: Path) -> None:
    target = tmp_path / "field.png"
    with pytest.raises(DataError, match=r"predict must map \(100, 2\)"):
        plot_progress_field(
            lambda p: np.zeros((len(p), 2)), _trajectories(), [], target, resolution=10
        )
    with pytest.raises(DataError, match=r"trajectories\[0\] must have shape \(n, 2\)"):
        plot_progress_field(lambda p: p[:, 0], [np.zeros((5, 3))], [], target)
    with pytest.raises(ConfigError, match="bounds"):
        plot_progress_field(lambda p: p[:, 0], [], [], target, bounds=((1, 0), (0, 1)))
    assert list(tmp_path.iterdir()) == []


def test_plot_progress_curves(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    curves = {}
    for demos in (3, 6, 9):
        activations = []
        for _ in range(5):
            expected = np.linspace(0, 1, 40)
            activations.append((expected, expected + rng.normal(0, 0.1 / demos, 40)))
        curves[f"{demos} demos"] = progress_curves(activations)
    _png_pixels(plot_progress_curves(curves, tmp_path / "curves.png", title="Fig. 6"))
    with pytest.raises(DataError, match="lack"):
        plot_progress_curves({"bad": {"time": np.zeros(3)}}, tmp_path / "bad.png")
    assert not (tmp_path / "bad.png").exists()


def test_strategy_map_colours_other_red(tmp_path: Path) -> None:
    widths, depths = np.linspace(0.1, 0.5, 8), np.linspace(0.1, 0.4, 6)
    correct = np.full((6, 8), "both", dtype=object)
    correct[:, :3] = "right"
    all_other = plot_strategy_map(
        widths,
        depths,
        np.full((6, 8), "rotate"),
        correct,
        tmp_path / "other.png",
        training_boxes=[(0.2, 0.2), (0.4, 0.3)],
    )
    all_right = plot_strategy_map(widths, depths, correct, correct, tmp_path / "right.png")
    red = to_rgb("#e41a1c")
    assert _fraction_of_colour(_png_pixels(all_other), red) > 0.1
    # Only the legend's swatch for "other" is red when every choice is a known strategy.
    assert _fraction_of_colour(_png_pixels(all_right), red) < 0.005


def test_strategy_map_rejects_bad_shapes(tmp_path: Path) -> None:
    widths, depths = np.linspace(0.1, 0.5, 8), np.linspace(0.1, 0.4, 6)
    grid = np.full((6, 8), "both")
    with pytest.raises(DataError, match=r"chosen must have shape \(D, W\) = \(6, 8\)"):
        plot_strategy_map(widths, depths, grid.T, grid, tmp_path / "s.png")
    with pytest.raises(DataError, match="strictly increasing"):
        plot_strategy_map(widths[::-1], depths, grid, grid, tmp_path / "s.png")
    assert list(tmp_path.iterdir()) == []


def test_plot_sweep(tmp_path: Path) -> None:
    table = [
        {"n_demos": n, "model": model, "success": 0.5 + 0.05 * n, "success_std": 0.02}
        for n in (3, 6, 9)
        for model in ("klr", "mlp")
    ]
    _png_pixels(plot_sweep(table, "n_demos", "success", "model", tmp_path / "lines.png"))
    _png_pixels(plot_sweep(table[:2], "model", "success", None, tmp_path / "bars.png"))
    with pytest.raises(DataError, match="lacks"):
        plot_sweep([{"n_demos": 3}], "n_demos", "success", None, tmp_path / "bad.png")
    with pytest.raises(DataError, match="repeats"):
        plot_sweep(table, "n_demos", "success", None, tmp_path / "bad.png")
    assert not (tmp_path / "bad.png").exists()


def test_fig6_band_is_named_a_spread_and_stays_in_phis_range(monkeypatch, tmp_path):
    """The band is the predictions' spread over activations (not an uncertainty), and φ lies
    in [0, 1]: the band is clipped there instead of running past the axes."""
    figures = []
    monkeypatch.setattr(plots, "save_figure", lambda figure, path: figures.append(figure))
    t = np.linspace(0.0, 1.0, 50)
    curves = dict(time=t, predicted_mean=t, predicted_std=np.full(50, 0.2), expected_mean=t)
    plots.plot_progress_curves({"3 demos": curves}, tmp_path / "fig6.png")
    (ax,) = figures[0].axes
    (band,) = ax.collections
    y = np.concatenate([path.vertices[:, 1] for path in band.get_paths()])
    assert y.min() >= 0.0 and y.max() <= 1.0
    assert band.get_label() == "spread over activations (±2 std)"
