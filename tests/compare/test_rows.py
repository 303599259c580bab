"""Which rows the comparison runs in which world, the fits they share, and the row options
that fail before any work."""

from __future__ import annotations

import copy
import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from hydra import compose, initialize_config_dir

from cpmp.compare import rows
from cpmp.compare.rows import NO_PREDICTOR, fit_jobs, group_options, row_specs
from cpmp.compare.settings import CompareJob
from cpmp.errors import ConfigError
from cpmp.predictors import PREDICTORS

CONF = Path(__file__).resolve().parents[2] / "conf"


@pytest.fixture(scope="module", autouse=True)
def composed_once() -> Iterator[None]:
    """Every predictor and sequencer option composed once for the module (a composition per
    option, seconds per test otherwise): ``group_options`` answers from them. Composing the
    options is tested in tests/experiment/test_config.py."""
    options = {group: group_options(group) for group in ("predictor", "sequencer")}
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(rows, "group_options", lambda group: copy.deepcopy(options[group]))
        yield


def specs_of(overrides: list[str]) -> tuple[CompareJob, list[Any]]:
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfg = compose("compare", overrides=overrides)
        job = CompareJob.from_cfg(cfg)
        return job, row_specs(cfg, job)


def test_all_compares_every_predictor_option_and_registered_kind():
    job, specs = specs_of(["compare.predictors=all", "compare.baselines=[goal_nearest]"])
    options = rows.group_options("predictor")  # the module's composed options
    sim = [s for s in specs if s.world == "sim" and s.group == "predictors"]
    assert {s.predictor for s in sim} == set(options)
    assert {s.predictor_cfg["kind"] for s in sim} >= set(PREDICTORS)
    assert all(s.sequencer == "coupled" for s in sim)
    baselines = [(s.world, s.predictor, s.sequencer) for s in specs if s.group == "baselines"]
    # every world that names no baselines of its own takes compare.baselines
    assert baselines == [(w.name, NO_PREDICTOR, "goal_nearest") for w in job.worlds]


def test_each_world_runs_its_own_rows_at_its_own_sizes():
    job, specs = specs_of([])
    worlds = {w.name: w for w in job.worlds}
    for spec in specs:
        if spec.group != "support_sweep":
            assert spec.train_sizes == worlds[spec.world].train_sizes
    relay = {s.predictor for s in specs if s.world == "relay"}
    assert relay == set(worlds["relay"].predictors)
    sweep = [s for s in specs if s.group == "support_sweep"]
    assert {s.world for s in sweep} == set(job.compare.sweep.worlds)
    assert all(s.train_sizes == (9,) for s in sweep)  # the world's largest D
    scales = [s.value for s in sweep if s.option == "support_scale"]
    assert len(set(scales)) == len(scales) >= 4 and None not in scales
    levels = [s.value for s in sweep if s.predictor == "klr_sparse"]
    assert {s.option for s in sweep if s.predictor == "klr_sparse"} == {"level"}
    assert None in levels and len(levels) >= 4  # its own choice, and fixed levels


def test_fits_are_shared_once_and_keyed_by_world():
    job, specs = specs_of([])
    worlds = {w.name: w for w in job.worlds}
    jobs = fit_jobs(specs, worlds)
    keys = [
        s.fit_key(seed, d) for s in specs for seed in worlds[s.world].seeds for d in s.train_sizes
    ]
    assert list(jobs) == list(dict.fromkeys(keys)) and len(jobs) < len(keys)
    for key, fit in jobs.items():
        loaded = json.loads(key)
        assert (fit.seed, fit.d, fit.spec.world) == (loaded["seed"], loaded["D"], loaded["world"])
    # the same predictor in two worlds is two fits
    sim = next(s for s in specs if s.world == "sim" and s.predictor == "klr")
    settle = next(s for s in specs if s.world == "settle0" and s.predictor == "klr")
    assert sim.fit_key(0, 3) != settle.fit_key(0, 3)


def test_a_series_adds_its_values_and_its_own_default():
    _, specs = specs_of(
        [
            "experiment=compare_tiny",
            "+compare.sweep.series=[{predictor: klr, option: l2, values: [0.01, 0.1]}]",
        ]
    )
    series = [s for s in specs if s.group == "support_sweep" and s.predictor == "klr"]
    assert [(s.option, s.value) for s in series] == [("l2", 0.01), ("l2", 0.1), ("l2", None)]
    assert series[0].predictor_cfg["l2"] == 0.01
    assert series[2].predictor_cfg == rows.group_options("predictor")["klr"]
    assert series[2].point() == "l2=default"


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        (["compare.predictors=[klr,nope]"], "unknown predictor option"),
        (["compare.worlds.relay.predictors=[nope]"], "compare.worlds.relay.predictors"),
        (["compare.baselines=[coupled]"], "not a sequencer option of kind 'goal_nearest'"),
        (["compare.sweep.predictor=mlp"], "support_scale"),
        (["+compare.sweep.series=[{predictor: mlp, option: level, values: [1]}]"], "'level'"),
        (["compare.claims=[{name: x, a: klr, b: nope}]"], "compare.claims"),
    ],
)
def test_bad_row_options_fail_before_any_work(overrides, message):
    with pytest.raises(ConfigError, match=message):
        specs_of(overrides)
