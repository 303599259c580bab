"""``cpmp-compare``: its tiny form end to end through ``scripts/compare.py`` (every field in every
row, the figures, the table), the same numbers from a serial in-process run, the choice of rows,
the option errors, and ``sequencer=goal_nearest`` in the training stage."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
import torch
from hydra import compose, initialize_config_dir

from cpmp.baselines.goal_nearest import GoalNearestSequencer
from cpmp.compare.job import OUTPUT_FILES, run_compare
from cpmp.compare.report import ROW_FIELDS
from cpmp.compare.rows import NO_PREDICTOR, fit_jobs, group_options, row_specs
from cpmp.compare.settings import CompareJob
from cpmp.data.datafile import load_demonstrations
from cpmp.errors import ConfigError
from cpmp.evaluation.offline import activation_progress, progress_errors
from cpmp.experiment.config import validate_common
from cpmp.experiment.fitting import fit_sequencer
from cpmp.experiment.settings import to_dict
from cpmp.experiment.strategies import balanced_subset
from cpmp.predictors import PREDICTORS
from cpmp.sim import OUTCOMES
from cpmp.worlds.two_point import make_demonstrations

torch.set_num_threads(1)

ROOT = Path(__file__).resolve().parents[2]
CONF = ROOT / "conf"
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
SAME_IN_EVERY_RUN = ("W", "I", "C", "diverged", "mae", "supports", "per_seed", "errors")
"""Row fields that must not depend on the worker count (the others are timings)."""


def compose_cfg(overrides: list[str], config: str = "compare") -> Any:
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        return compose(config, overrides=overrides)


@pytest.fixture(scope="module")
def tiny(tmp_path_factory, script_in_background):
    """``experiment=compare_tiny`` as ``scripts/compare.py`` (two worker processes) and, at
    the same time, a serial in-process run of three of its rows (two fits: klr's default is
    the sweep's 2.0). Yields both run dirs and the script's stdout."""
    base = tmp_path_factory.mktemp("compare")
    script, serial = base / "script", base / "serial"
    serial.mkdir()
    argv = ["experiment=compare_tiny", f"hydra.run.dir={script}"]
    with script_in_background(base, "compare.py", *argv, timeout=600) as run:
        cfg = compose_cfg(
            [
                "experiment=compare_tiny",
                "experiment.workers=1",
                "compare.predictors=[klr]",
                "compare.sweep.support_scale=[2.0]",
            ]
        )
        run_compare(cfg, serial)
    return script, serial, run.stdout.read_text()


def test_tiny_compare_writes_every_field_of_every_row(tiny):
    script, _, stdout = tiny
    assert stdout.strip().splitlines()[-1] == str(script / "compare.json")
    assert "[4/4]" in stdout  # progress: 4 fits (the sweep's 2.0 is klr's own fit)
    for name in OUTPUT_FILES:
        assert (script / name).is_file(), name
    for name in OUTPUT_FILES:
        if name.endswith(".png"):
            assert (script / name).read_bytes()[:8] == PNG_SIGNATURE
    rows = json.loads((script / "compare.json").read_text())
    assert isinstance(rows, list)
    keys = {(r["predictor"], r["sequencer"], r["D"], r["support_scale"]) for r in rows}
    assert keys == {
        ("klr", "coupled", 3, None),
        ("klr_path", "coupled", 3, None),
        (NO_PREDICTOR, "goal_nearest", 3, None),
        ("klr", "coupled", 3, 1.0),
        ("klr", "coupled", 3, 2.0),
    }
    for row in rows:
        missing = [f for f in ROW_FIELDS if f not in row]
        assert not missing, (row["predictor"], missing)
        assert row["errors"] == []
        assert row["W"] + row["I"] + row["C"] == row["n_boxes"] == 1
        assert row["mae"] == row["per_seed"]["mae"][0]  # one seed: its value is the mean
        assert row["fit_s"] > 0 and row["tick_ms"] > 0
        if row["sequencer"] == "goal_nearest":
            assert row["supports"] is None
        else:
            assert row["supports"] >= 1
    sweep = {r["support_scale"]: r for r in rows if r["group"] == "support_sweep"}
    assert sweep[1.0]["supports"] < sweep[2.0]["supports"]  # denser supports, more of them
    default = next(r for r in rows if r["group"] == "predictors" and r["predictor"] == "klr")
    assert {k: default[k] for k in SAME_IN_EVERY_RUN} == {
        k: sweep[2.0][k] for k in SAME_IN_EVERY_RUN
    }
    table = (script / "compare.md").read_text()
    for name in ("`klr`", "`klr_path`", "`goal_nearest`", "paper, Table I", "Support-density"):
        assert name in table
    timings = json.loads((script / "timings.json").read_text())
    assert timings["workers"] == 2 and len(timings["jobs"]) == 4
    episodes = json.loads((script / "episodes.json").read_text())
    assert len(episodes) == 4  # one box for each of the 4 fits
    assert {e["outcome"] for e in episodes} <= set(OUTCOMES)
    assert all(e["reason"] and e["D"] == 3 and e["seed"] == 0 for e in episodes)


def test_numbers_do_not_depend_on_the_worker_count(tiny):
    script, serial, _ = tiny
    rows = json.loads((script / "compare.json").read_text())
    alone = json.loads((serial / "compare.json").read_text())
    assert len(alone) == 3

    def key(row: dict[str, Any]) -> tuple:
        return (row["predictor"], row["sequencer"], row["D"], row["support_scale"])

    both = {key(r): r for r in rows}
    for row in alone:
        assert {k: row[k] for k in SAME_IN_EVERY_RUN} == {
            k: both[key(row)][k] for k in SAME_IN_EVERY_RUN
        }


def test_row_mae_is_the_fitted_models_error_on_the_held_out_demos(tiny):
    """The ``klr`` row's MAE is that of ``klr`` fitted here on the balanced D = 3 subset of the
    run's own training split and scored on its test split (both read back from
    ``seed_0/demos.h5``): the row fits on the right demos and scores on the held-out ones."""
    script, _, _ = tiny
    rows = json.loads((script / "compare.json").read_text())
    (row,) = [r for r in rows if r["group"] == "predictors" and r["predictor"] == "klr"]
    path = script / "seed_0" / "demos.h5"
    train, test = (load_demonstrations(path, split=s) for s in ("train", "test"))
    cfg = compose_cfg(["experiment=compare_tiny"])
    trainer = {**to_dict(cfg.trainer), "progress_bar": False}
    klr = group_options("predictor")["klr"]
    seq = fit_sequencer(balanced_subset(train, 3), klr, cfg.sequencer, trainer, seed=0)
    expected = progress_errors(activation_progress(seq, test))["mae"]
    # the file keeps the features as collected; rel 1e-9 leaves room for summation order only
    assert row["mae"] == pytest.approx(expected, rel=1e-9)
    assert row["mae"] != pytest.approx(
        progress_errors(activation_progress(seq, train))["mae"], rel=1e-3
    )  # the training demos give another number: the comparison can fail


def test_all_compares_every_predictor_option_and_registered_kind():
    cfg = compose_cfg([])  # conf/compare.yaml: experiment=compare
    job = CompareJob.from_cfg(cfg)
    specs = row_specs(cfg, job.settings, job.compare)
    options = group_options("predictor")
    rows = [s for s in specs if s.group == "predictors"]
    assert {s.predictor for s in rows} == set(options)
    assert {s.predictor_cfg["kind"] for s in rows} >= set(PREDICTORS)
    assert all(s.train_sizes == (3, 6, 9) and s.sequencer == "coupled" for s in rows)
    assert [(s.predictor, s.sequencer) for s in specs if s.group == "baselines"] == [
        (NO_PREDICTOR, "goal_nearest")
    ]
    sweep = [s for s in specs if s.group == "support_sweep"]
    assert len(sweep) >= 5 and len({s.support_scale for s in sweep}) == len(sweep)
    assert all(s.train_sizes == (9,) and s.predictor_cfg["kind"] == "klr" for s in sweep)
    # every fit once: the sweep's point at klr's own support_scale shares klr's fit
    jobs = fit_jobs(specs, job.settings.seeds)
    keys = [s.fit_key(seed, d) for s in specs for seed in job.settings.seeds for d in s.train_sizes]
    assert list(jobs) == list(dict.fromkeys(keys)) and len(jobs) < len(keys)
    for key, fit in jobs.items():
        assert (fit.seed, fit.d) == (json.loads(key)["seed"], json.loads(key)["D"])
        assert fit.spec.fit_key(fit.seed, fit.d) == key


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        (["compare.predictors=[klr,nope]"], "unknown predictor option"),
        (["compare.baselines=[coupled]"], "not a sequencer option of kind 'goal_nearest'"),
        (["compare.sweep.predictor=mlp"], "with support points"),
        (["compare.sweep.support_scale=[1.0,-2.0]"], "numbers > 0"),
        (["compare.sweep.train_sizes=[4]"], "experiment.train_sizes"),
        (["+compare.extra=1"], "unknown compare option"),
        (["sequencer=goal_nearest"], "must be a learned one"),
    ],
)
def test_bad_compare_options_fail_before_any_work(overrides, message):
    cfg = compose_cfg(overrides)
    with pytest.raises(ConfigError, match=message):
        job = CompareJob.from_cfg(cfg)
        row_specs(cfg, job.settings, job.compare)


def test_sequencer_goal_nearest_is_fitted_by_the_training_stage():
    cfg = compose_cfg(["sequencer=goal_nearest", "sequencer.hold_time=0.2"], "experiment")
    validate_common(cfg)
    demos = make_demonstrations(3, seed=0)
    seq = fit_sequencer(demos, cfg.predictor, cfg.sequencer, cfg.trainer, seed=0)
    assert isinstance(seq, GoalNearestSequencer)
    assert seq.config.hold_time == 0.2
    bad = compose_cfg(["sequencer=goal_nearest", "sequencer.kind=other"], "experiment")
    with pytest.raises(ConfigError, match=r"sequencer\.kind must be"):
        validate_common(bad)
    with pytest.raises(ConfigError, match=r"sequencer\.kind must be"):
        fit_sequencer(demos, bad.predictor, bad.sequencer, bad.trainer, seed=0)
    typo = compose_cfg(["sequencer=goal_nearest", "+sequencer.hold=0.2"], "experiment")
    with pytest.raises(ConfigError, match="valid options: speed_threshold"):
        validate_common(typo)
