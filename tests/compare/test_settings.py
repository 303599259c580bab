"""The ``compare`` node: the shipped options resolve, every bad option fails before any work
with a message that names it."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from hydra import compose, initialize_config_dir

from cpmp.compare.settings import CompareJob, compare_settings
from cpmp.errors import ConfigError

CONF = Path(__file__).resolve().parents[2] / "conf"


def compose_cfg(overrides: list[str]) -> Any:
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        return compose("compare", overrides=overrides)


def test_the_shipped_comparison_resolves_its_worlds():
    job = CompareJob.from_cfg(compose_cfg([]))
    worlds = {w.name: w for w in job.worlds}
    assert worlds["sim"].kind == "sim" and worlds["sim"].options == {}
    assert worlds["settle0"].options == {"settle_time": 0.0}
    assert worlds["noise5"].feature_noise == 0.05
    assert worlds["sim"].episodes == job.settings.n_boxes == 20
    synthetic = [w for w in job.worlds if w.kind == "synthetic"]
    assert {w.world for w in synthetic} >= {"two_point", "relay", "paced_relay"}
    assert all(w.episodes * len(w.seeds) >= 200 for w in synthetic)  # per row and D
    assert {(c.a, c.b) for c in job.compare.claims} == {
        ("klr", "regression_clip"),
        ("klr", "time_phase"),
    }


def test_a_world_takes_the_experiments_numbers_where_it_names_none():
    job = CompareJob.from_cfg(compose_cfg(["experiment=compare_tiny"]))
    sim, two_point = job.worlds
    assert sim.seeds == tuple(job.settings.seeds) and sim.train_sizes == (3,)
    assert sim.episodes == job.settings.n_boxes and sim.baselines == ("goal_nearest",)
    assert two_point.seeds == (0, 1) and two_point.train_sizes == (2, 4)
    assert two_point.feature_noise == 0.0 and two_point.baselines == ()
    assert two_point.predictors == ["paper", "klr"]  # compare.predictors


def test_defaults_are_one_simulated_world_and_the_papers_claims():
    settings = compare_settings(None)
    assert list(settings.worlds) == ["sim"] and settings.predictors == "all"
    assert settings.stats.samples == 2000 and settings.stats.level == 0.95


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        (["compare.sweep.support_scale=[1.0,-2.0]"], "numbers > 0"),
        (["compare.sweep.train_sizes=[4]"], "training sizes"),
        (["compare.sweep.worlds=[nope]"], "compare.sweep.worlds"),
        (["+compare.extra=1"], "unknown compare option"),
        (["+compare.worlds.sim.boxes=3"], "compare.worlds.sim.boxes"),
        (["compare.worlds.sim.kind=lab"], "kind must be one of sim, synthetic"),
        (["compare.worlds.two_point.world=nope"], "unknown synthetic world 'nope'"),
        (["+compare.worlds.sim.task.settle=0"], "compare.worlds.sim: unknown task option"),
        (["compare.worlds.sim.episodes=0"], "episodes must be"),
        (["compare.worlds.relay.seeds=[1,1]"], "duplicates"),
        (
            ["compare.worlds.noise5.feature_noise=2.0"],
            r"feature_noise must be a number in \[0, 1\)",
        ),
        (["+compare.worlds.two_point.task.gian=1"], "bad task option for the two_point world"),
        (["compare.stats.level=1.5"], "compare.stats: bootstrap level"),
        (["sequencer=goal_nearest"], "must be a learned one"),
    ],
)
def test_bad_compare_options_fail_before_any_work(overrides, message):
    with pytest.raises(ConfigError, match=message):
        CompareJob.from_cfg(compose_cfg(overrides))
