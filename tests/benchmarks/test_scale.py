"""The scale benchmark (cpmp.benchmarks.scale, scripts/bench_scale.py): the quick run writes the
documented JSON from a process per size and its lerobot leg (written, imported by cpmp-import's
entry point, fitted), its numbers other than times and memory are reproducible, the exponents are
least-squares slopes, the targets read the right sizes, and bad options fail with exit status 2."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
import torch

from cpmp.benchmarks import scale
from cpmp.benchmarks.lerobot_data import import_mapping, write_demonstrations
from cpmp.benchmarks.scale import (
    IMPORT_ENTRY_POINT,
    LEROBOT_WORLD,
    TARGETS,
    ScaleSettings,
    growth_exponent,
    main,
    measure_size,
    run_import,
    run_scale_benchmark,
    summarise,
)
from cpmp.errors import ConfigError
from cpmp.worlds.registry import make_world

MEASURED = ("fit_s", "predictor_s", "peak_rss_gb", "base_rss_gb", "threads")


@pytest.mark.slow
def test_quick_run_writes_the_documented_json(tmp_path, capsys):
    out = tmp_path / "scale.json"
    assert main(["--quick", "--out", str(out)]) == 0
    result = json.loads(out.read_text())
    assert result["targets"] == TARGETS
    assert [(r["world"], r["D"]) for r in result["rows"]] == [("two_point", 4), ("two_point", 8)]
    for row in result["rows"]:
        assert "error" not in row
        assert set(row) >= {"samples", "supports", "mae", "complete", *MEASURED}
        assert 0 < row["predictor_s"] < row["fit_s"]
        assert 0 < row["base_rss_gb"] <= row["peak_rss_gb"]
        assert 0 <= row["complete"] <= row["episodes"] == 2 and 0 < row["mae"] < 1
    small, large = result["rows"]
    assert large["samples"] > small["samples"] and large["supports"] > small["supports"]
    exponents = result["summary"]["two_point"]["exponents"]
    samples = [small["samples"], large["samples"]]
    assert exponents["fit"] == growth_exponent(samples, [small["fit_s"], large["fit_s"]])
    assert exponents["fit_last"] == exponents["fit"]  # two sizes: the same two points
    assert result["summary"]["two_point"]["targets"] == {}  # no 768 in a quick run
    # the lerobot leg: 3 episodes written, imported by cpmp-import, fitted; not an exponent's row
    lerobot = result["lerobot"]
    drawn = make_world(LEROBOT_WORLD, {}).demonstrations(3, 0)
    assert (lerobot["world"], lerobot["D"], lerobot["source"]) == ("two_point", 3, "lerobot")
    assert "error" not in lerobot and lerobot["demos"] == 3 and lerobot["files"] == 1
    assert lerobot["samples"] == lerobot["frames"] == sum(d.n_samples for d in drawn)
    assert set(lerobot) >= {"supports", "mae", "write_s", "import_s", *MEASURED}
    assert 0 < lerobot["import_rss_gb"] and 0 < lerobot["import_s"]
    assert 0 < lerobot["predictor_s"] < lerobot["fit_s"] and lerobot["supports"] > 0
    assert 0 <= lerobot["complete"] <= lerobot["episodes"] == 2 and 0 < lerobot["mae"] < 1
    table = capsys.readouterr().out
    assert "| two_point | 4 |" in table and str(out) in table
    assert "| two_point via LeRobot v3 | 3 |" in table and "cpmp-import" in table
    # a fresh process per size: the same settings give the same numbers (times aside)
    again = measure_size("two_point", 4, ScaleSettings.quick())
    assert {k: v for k, v in again.items() if k not in MEASURED} == {
        k: v for k, v in small.items() if k not in MEASURED
    }
    # --dtype float32 fits the predictors in float32: the same data, another rounding
    assert result["settings"]["dtype"] == "auto" and small["dtype"] == "float64"  # small data
    # the fit's accelerator: "auto" takes a GPU where there is one, --accelerator names one
    assert result["settings"]["accelerator"] == "auto"
    assert small["device"] == ("cuda:0" if torch.cuda.is_available() else "cpu")
    single = measure_size("two_point", 4, ScaleSettings.quick(dtype="float32", accelerator="cpu"))
    assert "error" not in single and single["dtype"] == "float32" and single["device"] == "cpu"
    assert single["samples"] == small["samples"] and single["supports"] > 0
    assert single["mae"] != small["mae"] and abs(single["mae"] - small["mae"]) < 0.01


def test_growth_exponent_is_the_log_log_slope():
    assert growth_exponent([10, 100, 1000], [2.0, 20.0, 200.0]) == pytest.approx(1.0)
    assert growth_exponent([10, 100, 1000], [1.0, 100.0, 1e4]) == pytest.approx(2.0)
    assert growth_exponent([10, 40], [3.0, 3.0]) == pytest.approx(0.0)
    assert growth_exponent([10], [1.0]) is None


def _row(d, samples, fit_s, rss, supports, mae, complete):
    return {
        "world": "w", "D": d, "samples": samples, "fit_s": fit_s, "peak_rss_gb": rss,
        "supports": supports, "mae": mae, "complete": complete,
    }  # fmt: skip


def test_targets_read_768_against_48_and_192():
    rows = [
        _row(48, 1000, 2.0, 0.5, 100, 0.03, 18),
        _row(192, 4000, 8.0, 0.6, 150, 0.02, 20),
        _row(768, 16000, 40.0, 2.5, 250, 0.02, 19),
        {"world": "w", "D": 1536, "error": "ran past the timeout of 1 s"},
    ]
    summary = summarise(rows)["w"]
    targets = summary["targets"]
    assert targets["fit_s"] == {"value": 40.0, "met": True}
    assert targets["peak_rss_gb"] == {"value": 2.5, "met": False}
    assert targets["supports_ratio"] == {"value": 2.5, "met": False}
    assert targets["fit_exponent"]["value"] == pytest.approx(math.log(5) / math.log(4))
    assert targets["fit_exponent"]["met"] is False
    assert targets["mae"] == {"value": [0.02, 0.02], "met": True}
    assert targets["complete"] == {"value": [20, 19], "met": False}
    assert summary["exponents"]["fit_last"] == targets["fit_exponent"]["value"]


@pytest.mark.parametrize(
    "options",
    [
        {"worlds": ("nowhere",)},
        {"sizes": (48, 12)},
        {"sizes": (0,)},
        {"episodes": 0},
        {"pythonpath": "/nonexistent"},
        {"lerobot": -1},
        {"dtype": "float16"},
        {"accelerator": ""},
    ],
)
def test_bad_settings_are_config_errors(options):
    with pytest.raises(ConfigError):
        ScaleSettings(**options)


def test_bad_options_exit_with_status_2(tmp_path, capsys):
    assert main(["--sizes", "12", "0", "--out", str(tmp_path / "x.json")]) == 2
    assert "bench_scale: error: sizes" in capsys.readouterr().err
    assert not (tmp_path / "x.json").exists()


def test_the_import_runs_the_console_script_of_cpmp_import():
    tomllib = pytest.importorskip("tomllib")
    pyproject = Path(__file__).parents[2] / "pyproject.toml"
    scripts = tomllib.loads(pyproject.read_text())["project"]["scripts"]
    assert scripts["cpmp-import"] == IMPORT_ENTRY_POINT


def test_the_lerobot_row_is_kept_out_of_the_rows_and_skipped_at_zero(monkeypatch):
    sizes = []

    def fake_size(world, demos, settings):
        sizes.append(demos)
        return _row(demos, 10 * demos, 1.0, 1.0, 1, 0.1, 1) | {"episodes": 1}

    legs = []

    def fake_lerobot(settings):
        legs.append(settings.lerobot)
        return {
            "world": "two_point",
            "D": settings.lerobot,
            "source": "lerobot",
            "error": "not run",
        }

    monkeypatch.setattr(scale, "measure_size", fake_size)
    monkeypatch.setattr(scale, "measure_lerobot", fake_lerobot)
    skipped = run_scale_benchmark(ScaleSettings(worlds=("two_point",), sizes=(2, 4), lerobot=0))
    assert "lerobot" not in skipped and legs == [] and sizes == [2, 4]
    result = run_scale_benchmark(ScaleSettings(worlds=("two_point",), sizes=(2, 4), lerobot=7))
    assert result["lerobot"]["D"] == 7 and legs == [7]
    assert [r["D"] for r in result["rows"]] == [2, 4] and list(result["summary"]) == ["w"]
    assert "| two_point via LeRobot v3 | 7 | - | not run |" in scale.markdown(result)


@pytest.mark.slow
def test_a_failed_import_is_the_rows_error(tmp_path):
    demos = make_world(LEROBOT_WORLD, {}).demonstrations(2, 0)
    dataset = write_demonstrations(tmp_path / "ds", demos)
    mapping = import_mapping(demos)
    mapping["labels"]["a"]["column"] = "no_such_column"
    path = tmp_path / "mapping.yaml"
    path.write_text(json.dumps(mapping))
    output = tmp_path / "demos.hdf5"
    row = run_import(path, dataset, output, tmp_path / "run", ScaleSettings.quick())
    assert set(row) == {"error"} and row["error"].startswith("cpmp-import: exit status 2")
    assert "no_such_column" in row["error"] and not output.exists()
