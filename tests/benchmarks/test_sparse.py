"""The sparsity benchmark (cpmp.benchmarks.sparse, scripts/bench_sparse.py): the quick run
writes the documented JSON, its numbers other than times are reproducible, the ratios are
those of the measures, and bad options fail with exit status 2."""

from __future__ import annotations

import json

import pytest

from cpmp.benchmarks.sparse import (
    TARGETS,
    SparseSettings,
    main,
    markdown,
    ratios,
    run_sparse_benchmark,
)
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
        assert set(row[kind]) >= {"fit_s", "supports", "mae", "complete"}
        assert set(row[kind]) >= {"predictor_ms", "floor_ms", "batch_ms", "step_ms"}
        assert "supports_all" not in row[kind]  # there are no start heads to count apart
        assert 0 <= row[kind]["complete"] <= 4 and 0 < row[kind]["mae"] < 1
    assert row["sparse"]["supports"] <= 0.25 * row["default"]["supports"]
    assert row["sparse"]["validation"] == "held-out activations"
    assert row["ratios"] == ratios(row["default"], row["sparse"])
    assert row["ratios"]["supports"] == row["sparse"]["supports"] / row["default"]["supports"]
    floor = row["default"]["floor_ms"] / row["default"]["predictor_ms"]
    assert row["ratios"]["tick_floor"] == floor
    assert result["summary"]["two_point"]["3"]["ratios"]["met"]["supports"] is True
    table = capsys.readouterr().out
    assert "| two_point | 3 |" in table and str(out) in table
    assert "all supports x" not in table
    # the same settings give the same numbers (times aside)
    again = run_sparse_benchmark(SparseSettings.quick())
    assert _untimed(again) == _untimed(result)


def test_a_fixed_level_reaches_the_fits(tmp_path):
    result = run_sparse_benchmark(SparseSettings.quick(options={"level": 0.0625}))
    (row,) = result["rows"]
    assert row["sparse"]["level"] == 0.0625
    assert row["sparse"]["supports"] < result["rows"][0]["default"]["supports"] * 0.2


def _summary(**extra: float) -> dict:
    """A result's ``summary`` of one world and D with the ratios ``extra`` added."""
    r = {"mae": 0.9, "supports": 0.2, "tick": 0.4, "tick_floor": 0.3, "batch": 0.5}
    r |= {"step": 0.6, "fit": 1.5, "complete": 0.0, **extra}
    return {"summary": {"relay": {"3": {"ratios": {**r, "met": {"fit": True}}}}}}


def test_the_table_keeps_the_start_heads_column_of_an_older_result():
    """A result written while the sequencer could add start heads counts their supports too
    (``supports_all``, results/sparse.json): its table keeps that column; a new one has none."""
    old, new = markdown(_summary(supports_all=0.25)), markdown(_summary())
    assert old.splitlines()[0].startswith("| world | D | MAE x | supports x | all supports x |")
    assert "| relay | 3 | 0.90 | 0.20 | 0.25 | 0.40 | 0.30 | 0.50 | 0.60 | 1.50 | +0.0 |" in old
    assert "all supports x" not in new
    assert "| relay | 3 | 0.90 | 0.20 | 0.40 | 0.30 | 0.50 | 0.60 | 1.50 | +0.0 |" in new
    for table in (old, new):
        header, rule, row = table.splitlines()
        assert header.count("|") == rule.count("|") == row.count("|")


def test_start_share_is_no_longer_an_option(tmp_path):
    with pytest.raises(SystemExit) as exit_info:
        main(["--quick", "--start-share", "1", "--out", str(tmp_path / "x.json")])
    assert exit_info.value.code == 2
    assert not (tmp_path / "x.json").exists()


@pytest.mark.parametrize(
    "argv",
    [
        ["--quick", "--episodes", "0"],
        ["--quick", "--sizes", "0"],
        ["--quick", "--level", "2"],
    ],
)
def test_bad_options_exit_2(tmp_path, capsys, argv):
    assert main([*argv, "--out", str(tmp_path / "x.json")]) == 2
    assert "bench_sparse: error:" in capsys.readouterr().err
    assert not (tmp_path / "x.json").exists()


def test_unknown_world_is_a_config_error():
    with pytest.raises(ConfigError, match="unknown world"):
        SparseSettings(worlds=("moon",))
