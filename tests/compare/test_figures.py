"""The comparison's figures are drawn from pooled fake results (PNG files)."""

from __future__ import annotations

from fake_runs import SEEDS, fake_inputs, result, spec

from cpmp.compare.figures import plot_c_vs_d, plot_claims, plot_supports
from cpmp.compare.pooling import pool

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def test_every_figure_is_a_png(tmp_path):
    inputs = fake_inputs()
    point = spec("a", group="support_sweep", option="support_scale", value=0.5)
    for seed in SEEDS:
        for d in point.train_sizes:
            inputs["results"][point.fit_key(seed, d)] = result(20, supports=40)
    inputs["specs"] = [*inputs["specs"], point]
    pooled = pool(**inputs)
    for path in (
        plot_c_vs_d(pooled, tmp_path / "c.png"),
        plot_claims(pooled, tmp_path / "claims.png"),
        plot_supports(pooled["rows"], tmp_path / "supports.png"),
    ):
        assert path.read_bytes()[:8] == PNG_SIGNATURE
        assert path.stat().st_size > 10_000  # drawn, not an empty canvas


def test_figures_without_claims_or_sweep_still_draw(tmp_path):
    inputs = fake_inputs()
    inputs["claims"] = []
    pooled = pool(**inputs)
    assert plot_claims(pooled, tmp_path / "claims.png").is_file()
    assert plot_supports(pooled["rows"], tmp_path / "supports.png").is_file()
