"""The sparsity benchmark (cpmp.benchmarks.sparse, scripts/bench_sparse.py): the quick run
writes the documented JSON, its numbers other than times are reproducible, the ratios are
those of the measures, and bad options fail with exit status 2."""

from __future__ import annotations

import json

import pytest

from cpmp.benchmarks.sparse import TARGETS, SparseSettings, main, ratios, run_sparse_benchmark
from cpmp.errors import ConfigError

TIMES = ("fit_s", "predictor_ms", "floor_ms", "step_ms", "batch_ms")


def _untimed(result):
    """The rows without wall times (and the ratios of times)."""
    return [
        {
            kind: {k: v for k, v in row[kind].items() if k not in TIMES}
            for kind in ("default", "sparse")
        }
        for row in result["rows"]
    ]


@pytest.mark.slow
def test_quick_run_writes_the_documented_json(tmp_path, capsys):
    out = tmp_path / "sparse.json"
    assert main(["--quick", "--out", str(out)]) == 0
    result = json.loads(out.read_text())
    assert result["targets"] == TARGETS
    (row,) = result["rows"]
    assert (row["world"], row["D"], row["seed"]) == ("two_point", 3, 0)
    for kind in ("default", "sparse"):
        assert set(row[kind]) >= {"fit_s", "supports", "supports_all", "mae", "complete"}
        assert set(row[kind]) >= {"predictor_ms", "floor_ms", "batch_ms", "step_ms"}
        # the graph nodes' supports (a tick's) and all of them: the same, as the default
        # learned start fits no start heads
        assert row[kind]["supports"] == row[kind]["supports_all"]
        assert 0 <= row[kind]["complete"] <= 4 and 0 < row[kind]["mae"] < 1
    assert row["sparse"]["supports"] <= 0.25 * row["default"]["supports"]
    assert row["sparse"]["supports_all"] <= 0.25 * row["default"]["supports_all"]
    assert row["sparse"]["validation"] == "held-out activations"
    assert row["ratios"] == ratios(row["default"], row["sparse"])
    assert row["ratios"]["supports"] == row["sparse"]["supports"] / row["default"]["supports"]
    floor = row["default"]["floor_ms"] / row["default"]["predictor_ms"]
    assert row["ratios"]["tick_floor"] == floor
    assert result["summary"]["two_point"]["3"]["ratios"]["met"]["supports"] is True
    table = capsys.readouterr().out
    assert "| two_point | 3 |" in table and str(out) in table
    # the same settings give the same numbers (times aside)
    again = run_sparse_benchmark(SparseSettings.quick())
    assert _untimed(again) == _untimed(result)


def test_a_fixed_level_reaches_the_fits(tmp_path):
    result = run_sparse_benchmark(SparseSettings.quick(options={"level": 0.0625}))
    (row,) = result["rows"]
    assert row["sparse"]["level"] == 0.0625
    assert row["sparse"]["supports"] < result["rows"][0]["default"]["supports"] * 0.2


def test_start_share_reaches_the_fits(tmp_path):
    out = tmp_path / "share.json"
    assert main(["--quick", "--start-share", "1", "--out", str(out)]) == 0
    (row,) = json.loads(out.read_text())["rows"]
    # the start heads keep the fixed rule's supports: the default model's
    start = row["default"]["supports_all"] - row["default"]["supports"]
    assert row["sparse"]["supports_all"] - row["sparse"]["supports"] == start


@pytest.mark.parametrize(
    "argv",
    [
        ["--quick", "--episodes", "0"],
        ["--quick", "--sizes", "0"],
        ["--quick", "--level", "2"],
        ["--quick", "--start-share", "0"],
    ],
)
def test_bad_options_exit_2(tmp_path, capsys, argv):
    assert main([*argv, "--out", str(tmp_path / "x.json")]) == 2
    assert "bench_sparse: error:" in capsys.readouterr().err
    assert not (tmp_path / "x.json").exists()


def test_unknown_world_is_a_config_error():
    with pytest.raises(ConfigError, match="unknown world"):
        SparseSettings(worlds=("moon",))
