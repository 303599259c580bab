"""``cpmp-compare`` end to end: its tiny form through ``scripts/compare.py`` (every file, every
row of both worlds with its intervals, the pairs, the report) and the same numbers from a serial
in-process run of part of it."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
import torch
from hydra import compose, initialize_config_dir

from cpmp.compare.job import OUTPUT_FILES, run_compare
from cpmp.compare.pooling import RATES
from cpmp.compare.rows import NO_PREDICTOR
from cpmp.data.datafile import load_demonstrations
from cpmp.evaluation.offline import activation_progress, progress_errors
from cpmp.experiment.fitting import fit_sequencer
from cpmp.experiment.settings import to_dict
from cpmp.experiment.strategies import balanced_subset
from cpmp.sim import OUTCOMES

pytestmark = pytest.mark.slow  # one compare_tiny run (two worker processes) for the module

torch.set_num_threads(1)

ROOT = Path(__file__).resolve().parents[2]
CONF = ROOT / "conf"
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
SAME_IN_EVERY_RUN = ("W", "I", "C", "mae", "supports", "per_seed", "errors", "diverged")
"""Row fields that must not depend on the worker count (``per_seed`` holds no timings)."""
INTERVAL_KEYS = {"estimate", "low", "high", "level", "seeds", "units"}


def compose_cfg(overrides: list[str], config: str = "compare") -> Any:
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        return compose(config, overrides=overrides)


def without_timings(row: dict[str, Any]) -> dict[str, Any]:
    """The fields of ``row`` that no timing enters."""
    out = {k: row[k] for k in SAME_IN_EVERY_RUN}
    out["per_seed"] = {k: v for k, v in row["per_seed"].items() if k not in ("fit_s", "tick_ms")}
    return out


@pytest.fixture(scope="module")
def tiny(tmp_path_factory, script_in_background):
    """``experiment=compare_tiny`` as ``scripts/compare.py`` (two worker processes) and, at
    the same time, a serial in-process run of its ``paper`` rows (the sweep's 2.0 is the paper
    row's own fit). Yields both run dirs and the script's stdout."""
    base = tmp_path_factory.mktemp("compare")
    script, serial = base / "script", base / "serial"
    serial.mkdir()
    argv = ["experiment=compare_tiny", f"hydra.run.dir={script}"]
    with script_in_background(base, "compare.py", *argv, timeout=600) as run:
        cfg = compose_cfg(
            [
                "experiment=compare_tiny",
                "experiment.workers=1",
                "compare.predictors=[paper]",
                "compare.baselines=[]",
                "compare.sweep.support_scale=[2.0]",
            ]
        )
        run_compare(cfg, serial)
    return script, serial, run.stdout.read_text()


def rows_of(run_dir: Path) -> list[dict[str, Any]]:
    return json.loads((run_dir / "compare.json").read_text())["rows"]


def test_tiny_compare_writes_every_number_with_its_interval(tiny):
    script, _, stdout = tiny
    assert stdout.strip().splitlines()[-1] == str(script / "compare.json")
    assert "[12/12]" in stdout  # 4 simulator fits (the sweep's 2.0 is paper's) + 8 two-point
    for name in OUTPUT_FILES:
        assert (script / name).is_file(), name
        if name.endswith(".png"):
            assert (script / name).read_bytes()[:8] == PNG_SIGNATURE
    result = json.loads((script / "compare.json").read_text())
    assert [w["name"] for w in result["worlds"]] == ["sim", "two_point"]
    keys = {(r["world"], r["name"], r["D"]) for r in result["rows"]}
    assert keys == {
        ("sim", "paper", 3),
        ("sim", "klr", 3),
        ("sim", "goal_nearest", 3),
        ("sim", "paper support_scale=1", 3),
        ("sim", "paper support_scale=2", 3),
        *{("two_point", name, d) for name in ("paper", "klr") for d in (2, 4)},
    }
    for row in result["rows"]:
        assert row["errors"] == []
        episodes, seeds = row["episodes"], len(row["seeds"])
        for key in (*RATES, "mae", "fit_s", "tick_ms"):
            value = row[key]
            assert set(value) == INTERVAL_KEYS, (row["name"], key)
            assert value["low"] <= value["estimate"] <= value["high"], (row["name"], key)
        counts = [row["per_seed"][k] for k in RATES]
        assert [sum(c) for c in zip(*counts, strict=True)] == [episodes] * seeds
        for key in RATES:  # a rate is its count over every episode of every seed
            assert row[key]["estimate"] == pytest.approx(
                sum(row["per_seed"][key]) / (episodes * seeds), abs=1e-12
            )
        if row["sequencer"] == "goal_nearest":
            assert row["supports"] is None and row["predictor"] == NO_PREDICTOR
        else:
            assert row["supports"]["estimate"] >= 1
    two_point = [r for r in result["rows"] if r["world"] == "two_point"]
    assert all(r["episodes"] == 6 and r["seeds"] == [0, 1] for r in two_point)
    sweep = {r["value"]: r for r in result["rows"] if r["group"] == "support_sweep"}
    assert sweep[1.0]["supports"]["estimate"] < sweep[2.0]["supports"]["estimate"]
    default = next(r for r in result["rows"] if r["group"] == "predictors" and r["name"] == "paper")
    assert without_timings(default) == without_timings(sweep[2.0])  # one shared fit
    # pairs: 3 in the simulator (paper, klr, goal_nearest), 1 per D in two_point
    pairs = {(p["world"], p["D"], p["a"], p["b"]) for p in result["pairs"]}
    assert len(pairs) == 5 and ("two_point", 4, "paper", "klr") in pairs
    for pair in result["pairs"]:
        for key in (*RATES, "mae"):
            assert pair[key]["significant"] in (True, False)
            assert 0 < pair[key]["p"] <= 1
    assert result["claims"] == []  # the tiny rows hold neither claim's pair
    table = (script / "compare.md").read_text()
    for text in ("`paper`", "`goal_nearest`", "paper, Table I", "Support-count axis", " [", "−"):
        assert text in table
    timings = json.loads((script / "timings.json").read_text())
    assert timings["workers"] == 2 and len(timings["jobs"]) == 12
    episodes = json.loads((script / "episodes.json").read_text())
    assert len(episodes) == 4 + 8 * 6  # one box per simulator fit, 6 per two-point fit
    assert {e["outcome"] for e in episodes} <= set(OUTCOMES)


def test_numbers_do_not_depend_on_the_worker_count(tiny):
    script, serial, _ = tiny
    both = {(r["world"], r["name"], r["D"]): r for r in rows_of(script)}
    alone = rows_of(serial)
    assert len(alone) == 4  # sim: paper, its sweep point; two_point: paper at D = 2, 4
    for row in alone:
        assert without_timings(row) == without_timings(both[(row["world"], row["name"], row["D"])])


def test_row_mae_is_the_fitted_models_error_on_the_held_out_demos(tiny):
    """The simulator's ``paper`` row's MAE is that of ``paper`` fitted here on the balanced D = 3
    subset of the run's own training split and scored on its test split (both read back from
    ``sim/seed_0/demos.h5``): the row fits on the right demos and scores on the held-out
    ones."""
    script, _, _ = tiny
    (row,) = [r for r in rows_of(script) if r["world"] == "sim" and r["name"] == "paper"]
    path = script / "sim" / "seed_0" / "demos.h5"
    train, test = (load_demonstrations(path, split=s) for s in ("train", "test"))
    cfg = compose_cfg(["experiment=compare_tiny"])
    trainer = {**to_dict(cfg.trainer), "progress_bar": False}
    paper = to_dict(compose_cfg(["experiment=compare_tiny", "predictor=paper"]).predictor)
    seq = fit_sequencer(balanced_subset(train, 3), paper, cfg.sequencer, trainer, seed=0)
    expected = progress_errors(activation_progress(seq, test))["mae"]
    # the file keeps the features as collected; rel 1e-9 leaves room for summation order only
    assert row["mae"]["estimate"] == pytest.approx(expected, rel=1e-9)
    assert row["mae"]["estimate"] != pytest.approx(
        progress_errors(activation_progress(seq, train))["mae"], rel=1e-3
    )  # the training demos give another number: the comparison can fail
