"""Aggregating a multirun: a fake sweep directory of hand-made reports and overrides."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest
from fake_reports import table_one_entry

from cpmp.analysis.aggregate import (
    METRIC_COLUMNS,
    OUTPUT_FILES,
    aggregate_sweep,
    collect_sweep,
    find_job_dirs,
    plot_axes,
    plot_table,
    read_overrides,
    write_aggregate,
)
from cpmp.errors import ConfigError, CpmpFileError
from cpmp.experiment.report import write_json

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def fake_report(c3: float, c6: float, distance: float | None = 0.1) -> dict:
    """A report of one job with D = 3 and 6 over two seeds of 4 boxes; the map at D = 6."""

    def rep(c: float) -> dict:
        return table_one_entry((1.0, 3.0 - c, c), (0.0, 0.5, 0.5), distance, 0.02, n_boxes=4)

    return {
        "experiment": {"name": "fake", "seeds": [0, 1], "n_boxes": 4},
        "reproduction": {"6": rep(c6), "3": rep(c3)},
        "progress": {
            "mae": 0.05,
            "by_train_size": {
                "3": {"mae": 0.08, "mae_std": 0.01},
                "6": {"mae": 0.05, "mae_std": 0.01},
            },
        },
        "strategy_map": {"accuracy": 0.75, "accuracy_std": 0.05, "train_size": 6},
    }


def make_job(sweep: Path, name: str, overrides: list[str], report: dict | None) -> Path:
    job = sweep / name
    (job / ".hydra").mkdir(parents=True)
    (job / ".hydra" / "overrides.yaml").write_text("".join(f"- {o}\n" for o in overrides))
    if report is not None:
        write_json(job / "report.json", report)
    return job


JOBS = {
    # job: (predictor, support_scale, C at D=3, C at D=6, distance)
    "0": ("klr", 0.5, 1.0, 2.0, 0.1),
    "1": ("klr", 2.0, 1.5, 2.5, None),
    "10": ("mlp", 0.5, 0.0, 0.5, 0.1),
    "2": ("mlp", 2.0, 0.5, 1.0, 0.1),
}
"""A sweep over ``predictor`` and ``predictor.support_scale``; job 10 checks natural order."""


@pytest.fixture
def sweep(tmp_path) -> Path:
    """The :data:`JOBS`, plus job 3 that failed (no report)."""
    root = tmp_path / "sweep"
    for name, (predictor, scale, c3, c6, distance) in JOBS.items():
        overrides = ["experiment=quick", f"predictor={predictor}"]
        overrides.append(f"predictor.support_scale={scale}")
        make_job(root, name, overrides, fake_report(c3, c6, distance))
    make_job(root, "3", ["experiment=quick", "predictor=mlp", "predictor.support_scale=4.0"], None)
    return root


def test_find_job_dirs_in_natural_order_skipping_failed_and_hidden(sweep):
    hidden = sweep / ".submitit" / "123"
    hidden.mkdir(parents=True)
    write_json(hidden / "report.json", fake_report(0, 0))
    assert [p.name for p in find_job_dirs(sweep)] == ["0", "1", "2", "10"]


def test_read_overrides_parses_values(tmp_path):
    overrides = ["predictor=klr_sparse", "predictor.level=0.125", "+experiment.seeds=[0,1]"]
    job = make_job(tmp_path, "0", overrides, None)
    assert read_overrides(job) == {
        "predictor": "klr_sparse",
        "predictor.level": 0.125,
        "experiment.seeds": "[0,1]",
    }
    assert read_overrides(tmp_path / "nowhere") == {}


def test_table_rows_and_columns(sweep):
    table = collect_sweep(sweep)
    assert table.override_keys == ["experiment", "predictor", "predictor.support_scale"]
    assert table.swept == ["predictor", "predictor.support_scale"]
    assert table.columns == ["job", *table.override_keys, *METRIC_COLUMNS]
    assert [(r["job"], r["D"]) for r in table.rows] == [
        ("0", 3), ("0", 6), ("1", 3), ("1", 6), ("2", 3), ("2", 6), ("10", 3), ("10", 6),
    ]  # fmt: skip
    by_key = {(r["job"], r["D"]): r for r in table.rows}
    row = by_key[("10", 6)]
    assert row["predictor"] == "mlp"
    assert row["predictor.support_scale"] == 0.5
    assert (row["C"], row["C_std"], row["W"], row["I"]) == (0.5, 0.5, 1.0, 2.5)
    assert (row["n_seeds"], row["n_boxes"]) == (2, 4)
    assert (row["progress_mae"], row["progress_mae_std"]) == (0.05, 0.01)
    assert (row["strategy_accuracy"], row["strategy_accuracy_std"]) == (0.75, 0.05)
    assert by_key[("10", 3)]["strategy_accuracy"] is None  # the map is made at the largest D
    assert by_key[("10", 3)]["progress_mae"] == 0.08
    assert by_key[("1", 6)]["distance_mean"] is None
    assert by_key[("0", 6)]["distance_mean"] == 0.1


def test_plot_axes(sweep):
    table = collect_sweep(sweep)
    # two swept keys and two D: x and hue are the overrides, only the largest D is plotted
    assert plot_axes(table) == ("predictor", "predictor.support_scale", 6)
    cells = plot_table(table, "predictor", "predictor.support_scale", 6)
    assert sorted((c["predictor"], c["predictor.support_scale"], c["C"]) for c in cells) == [
        ("klr", 0.5, 2.0), ("klr", 2.0, 2.5), ("mlp", 0.5, 0.5), ("mlp", 2.0, 1.0),
    ]  # fmt: skip
    table.swept = ["predictor.support_scale"]
    assert plot_axes(table) == ("predictor.support_scale", "D", None)
    # one swept key: x = it, jobs with the same x are averaged
    cells = plot_table(table, "predictor.support_scale", None, 6)
    assert sorted((c["predictor.support_scale"], c["C"], c["C_std"]) for c in cells) == [
        (0.5, 1.25, 0.75), (2.0, 1.75, 0.75),
    ]  # fmt: skip
    table.swept = []
    assert plot_axes(table) == ("D", None, None)


def test_write_aggregate_files(sweep):
    path = write_aggregate(collect_sweep(sweep))
    assert path == sweep / "aggregate.json"
    for name in OUTPUT_FILES:
        assert (sweep / name).is_file()
    assert (sweep / "aggregate.png").read_bytes()[:8] == PNG_SIGNATURE
    data = json.loads(path.read_text())
    assert len(data["rows"]) == 8
    assert data["swept"] == ["predictor", "predictor.support_scale"]
    assert data["plot"] == {
        "x": "predictor",
        "y": "C",
        "hue": "predictor.support_scale",
        "D": 6,
        "file": "aggregate.png",
    }
    with open(sweep / "aggregate.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0]) == data["columns"]
    assert [(r["job"], r["D"], r["C"]) for r in rows[:2]] == [("0", "3", "1.0"), ("0", "6", "2.0")]
    assert rows[2]["distance_mean"] == ""  # None -> empty cell
    text = (sweep / "aggregate.md").read_text()
    assert "swept: `predictor`, `predictor.support_scale`" in text
    header = "| job | experiment | predictor | predictor.support_scale | D | W | I | C |"
    assert header in text
    assert (
        "| 10 | quick | mlp | 0.5 | 6 | 1.0 ± 0.0 | 2.5 ± 0.5 | 0.5 ± 0.5 | 0.10 ± 0.02 |" in text
    )
    assert "| 0.050 ± 0.010 | 75.0 ± 5.0 % |" in text
    assert "| 1 | quick | klr | 2.0 | 3 | 1.0 ± 0.0 | 1.5 ± 0.5 | 1.5 ± 0.5 | – |" in text
    assert (
        len([line for line in text.splitlines() if line.startswith("| ")]) == 2 + 8
    )  # header, rule, rows


def test_single_run_dir_aggregates_as_one_job(tmp_path):
    write_json(tmp_path / "report.json", fake_report(1.0, 2.0))
    table = collect_sweep(tmp_path)
    assert [r["job"] for r in table.rows] == [".", "."]
    assert table.override_keys == [] and table.swept == []
    write_aggregate(table)
    assert json.loads((tmp_path / "aggregate.json").read_text())["plot"]["x"] == "D"


def test_empty_or_missing_sweep_dir_is_a_clear_error(tmp_path):
    with pytest.raises(CpmpFileError, match=r"no report\.json under"):
        collect_sweep(tmp_path)
    with pytest.raises(CpmpFileError, match="does not exist"):
        collect_sweep(tmp_path / "missing")
    with pytest.raises(ConfigError, match="sweep_dir is required"):
        aggregate_sweep({"sweep_dir": None}, tmp_path)
    assert list(tmp_path.iterdir()) == []


def test_broken_report_is_named(sweep):
    (sweep / "1" / "report.json").write_text("{not json")
    with pytest.raises(CpmpFileError, match=r"1/report\.json"):
        collect_sweep(sweep)
    write_json(sweep / "1" / "report.json", {"experiment": {}})
    with pytest.raises(CpmpFileError, match="not a cpmp experiment report"):
        collect_sweep(sweep)


@pytest.mark.slow
def test_script_writes_into_sweep_dir_and_prints_json_path_last(sweep, tmp_path, run_script):
    proc = run_script("aggregate.py", f"sweep_dir={sweep}", f"hydra.run.dir={tmp_path / 'run'}")
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip().splitlines()[-1] == str(sweep / "aggregate.json")
    assert (sweep / "aggregate.md").is_file()
    assert not (tmp_path / "run" / "aggregate.json").exists()


@pytest.mark.slow
def test_real_multirun_then_aggregate(tmp_path, run_script):
    """Two tiny jobs through Hydra's multirun (~40 s), then the aggregate of their sweep dir:
    only the override that differs between the jobs is swept, each job has its rows.

    The arm Jacobian is eager (``task.compile_kinematics=false``, the same in both jobs, so
    not swept): compiling it costs the process more CPU than it saves over two tiny jobs, and
    nothing here depends on it."""
    sweep = tmp_path / "multirun"
    argv = ["-m", "experiment=tiny", "task.compile_kinematics=false", "predictor.gamma=2.0,4.0"]
    argv.append(f"hydra.sweep.dir={sweep}")
    proc = run_script("experiment.py", *argv, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    table = collect_sweep(sweep)
    assert table.override_keys == ["experiment", "task.compile_kinematics", "predictor.gamma"]
    assert table.swept == ["predictor.gamma"]
    assert [(r["job"], r["predictor.gamma"], r["D"]) for r in table.rows] == [
        ("0", 2.0, 3),
        ("1", 4.0, 3),
    ]
    for row in table.rows:
        assert row["W"] + row["I"] + row["C"] == row["n_boxes"] == 2
    write_aggregate(table)
    assert json.loads((sweep / "aggregate.json").read_text())["plot"]["x"] == "predictor.gamma"
