"""report.json / report.md from a hand-made report: JSON conversion, formatting, paper column."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from fake_reports import table_one_entry

from cpmp.errors import CpmpFileError
from cpmp.experiment.report import (
    PAPER_TABLE_I,
    jsonable,
    mean_std,
    predictor_entry,
    render_markdown,
    write_json,
    write_report,
)


def make_report() -> dict:
    """A report shaped like run_experiment's, with D = 3 (in the paper) and D = 12 (not)."""

    def rep(w, i, c, dist):
        return table_one_entry((w, i, c), (0.5, 0.0, 1.25), dist, 0.01, n_boxes=20, diverged=0.0)

    return {
        "experiment": {"name": "handmade", "seeds": [0, 1], "n_boxes": 20},
        "predictor": {"kind": "klr_sparse", "gamma": np.float32(4.0)},
        "reproduction": {"3": rep(2.5, 4.0, 13.5, 0.1234), "12": rep(0.0, 1.0, 19.0, None)},
        "progress": {
            "mae": np.float64(0.0456),
            "by_train_size": {
                "3": {"mae": 0.0456, "mae_std": 0.002, "mae_first": 0.08, "mae_last": float("nan")},
                "12": {"mae": 0.02, "mae_std": 0.001, "mae_first": 0.03, "mae_last": 0.01},
            },
        },
        "strategy_map": {"accuracy": 0.875, "grid": (8, 6), "train_size": 12},
        "files": {"report.json": "all numbers"},
        "seconds": float("inf"),
    }


def test_jsonable_converts_numpy_tuples_and_non_finite():
    out = jsonable(
        {
            1: np.float32(1.5),
            "t": (1, np.int64(2)),
            "a": np.array([[0.5, np.nan]]),
            "b": np.bool_(True),
            "inf": -math.inf,
            "nested": [{"x": float("nan")}],
        }
    )
    assert out == {
        "1": 1.5,
        "t": [1, 2],
        "a": [[0.5, None]],
        "b": True,
        "inf": None,
        "nested": [{"x": None}],
    }
    assert type(out["t"][1]) is int
    json.dumps(out, allow_nan=False)


def test_mean_std_skips_missing_values():
    assert mean_std([1.0, None, 3.0]) == (2.0, 1.0)
    assert mean_std([2]) == (2.0, 0.0)
    assert mean_std([]) == (None, None)
    assert mean_std([None, None]) == (None, None)


def test_render_markdown_formats_numbers_and_paper_column():
    text = render_markdown(jsonable(make_report()))
    assert text.startswith("# cpmp experiment `handmade`")
    assert (
        "Predictor `klr_sparse` (feature weighting `–`, scaling `–`), start rule "
        "`independent`, switching rule `plateau`, coupling `none`, recovery `False`; task "
        "settle time – s, demonstration feature noise 0.0; seeds [0, 1], 20 random boxes" in text
    )
    assert "| W / I / C (paper) |" in text
    paper = PAPER_TABLE_I["3"]
    assert (
        f"| 3 | 2.5 ± 0.5 | 4.0 ± 0.0 | 13.5 ± 1.2 | {paper['W']} / {paper['I']} / {paper['C']} "
        "| 0.12 ± 0.01 | – | 0.13 ± 0.08 | – |" in text
    )
    # D = 12 is not in the paper's table; no complete episode -> no distance
    assert "| 12 | 0.0 ± 0.5 | 1.0 ± 0.0 | 19.0 ± 1.2 | – | – | – | – | – |" in text
    assert "| 3 | 0.046 ± 0.002 | 0.080 | – |" in text
    assert "| 12 | 0.020 ± 0.001 | 0.030 | 0.010 |" in text
    assert "Initial strategy correct on 87.5 % of a 8 x 6 width x depth grid (D = 12" in text
    assert "- `report.json`: all numbers" in text
    assert "nan" not in text.lower()


def test_render_markdown_without_strategy_map():
    report = make_report()
    del report["strategy_map"]
    text = render_markdown(jsonable(report))
    assert "Strategy map" not in text
    assert "## Files" in text


def test_write_report_writes_valid_json_with_nulls(tmp_path):
    path = write_report(make_report(), tmp_path)
    assert path == tmp_path / "report.json"
    raw = path.read_text()
    assert "NaN" not in raw and "Infinity" not in raw
    report = json.loads(raw)
    assert report["seconds"] is None
    assert report["progress"]["by_train_size"]["3"]["mae_last"] is None
    assert report["reproduction"]["12"]["distance_mean"] is None
    assert report["predictor"]["gamma"] == 4.0
    assert report["strategy_map"]["grid"] == [8, 6]
    assert (tmp_path / "report.md").read_text() == render_markdown(report)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["report.json", "report.md"]


def test_write_json_into_missing_directory_fails_cleanly(tmp_path):

    with pytest.raises(CpmpFileError, match="does not exist"):
        write_json(tmp_path / "missing" / "x.json", {"a": 1})


def test_render_markdown_lists_fit_warnings_only_when_there_are_some():
    report = make_report()
    assert "Fit warnings" not in render_markdown(jsonable(report))
    report["fit_warnings"] = ["seed 0, D = 3: node c/wait: the features do not change"]
    text = render_markdown(jsonable(report))
    assert "## Fit warnings" in text and "- seed 0, D = 3: node c/wait" in text


def goal_nearest_report() -> dict:
    """``make_report`` as a ``sequencer=goal_nearest`` run writes it (predictor entry from
    :func:`predictor_entry`, which drops the unused predictor group)."""
    report = make_report()
    sequencer = {
        "kind": "goal_nearest",
        "speed_threshold": 0.02,
        "hold_time": 0.1,
        "motion_share": 0.1,
        "feature_scaling": "global",
    }
    report["sequencer"] = sequencer
    report["predictor"] = predictor_entry("klr", {"gamma": 4.0}, sequencer)
    for row in report["reproduction"].values():
        row["recoveries"] = 0.0
    return report


def test_predictor_entry_names_the_predictor_that_ran():
    learned = predictor_entry("klr", {"gamma": 4.0}, {"coupling": "context"})
    assert learned == {"kind": "klr", "gamma": 4.0}
    assert predictor_entry("mlp", {"lr": 0.1}, None) == {"kind": "mlp", "lr": 0.1}
    baseline = predictor_entry("klr", {"gamma": 4.0}, {"kind": "goal_nearest"})
    assert baseline["kind"] == "none" and "gamma" not in baseline
    assert baseline["progress_estimate"] == "nearest_sample"
    assert baseline["used_to_switch"] is False
    assert "never uses to switch" in baseline["note"]


def test_goal_nearest_report_says_what_ran():
    text = render_markdown(jsonable(goal_nearest_report()))
    header = text.split("## Reproduction")[0]
    assert "Sequencer `goal_nearest`" in header
    assert "slower than 0.02 scaled units/s for 0.1 s" in header
    assert "L1 path share >= 0.1" in header and "feature scaling `global`" in header
    assert "No progress predictor is trained or used" in header
    # nothing of the learned sequencer or of the unused predictor group
    for absent in ("Predictor `", "switching rule", "coupling `", "start rule", "klr"):
        assert absent not in header, absent
    assert "## Progress estimate (nearest-sample lookup, not used to switch)" in text
    assert "Progress prediction (Fig. 6)" not in text
    assert "nearest-training-sample lookup of the expected progress (eq. 1)" in text
    assert "| 3 | 0.046 ± 0.002 | 0.080 | – |" in text  # the numbers stay
    # no stall recovery in this baseline: the column shows none rather than a count of 0
    assert "| 0.12 ± 0.01 | – | 0.13 ± 0.08 | – |" in text


def test_learned_report_keeps_its_header_and_recoveries():
    report = make_report()
    report["sequencer"] = {"start_rule": "joint", "switch_rule": "paper", "coupling": "context"}
    for row in report["reproduction"].values():
        row["recoveries"] = 1.5
    text = render_markdown(jsonable(report))
    assert "Predictor `klr_sparse`" in text and "coupling `context`" in text
    assert "goal_nearest" not in text and "## Progress prediction (Fig. 6)" in text
    assert "| 0.12 ± 0.01 | – | 0.13 ± 0.08 | 1.5 |" in text
