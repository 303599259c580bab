"""The simulation speed benchmark (:mod:`cpmp.benchmarks.sim`): report structure, not
speed."""

from __future__ import annotations

import pytest

from cpmp.benchmarks.sim import TARGET_REAL_TIME_FACTOR, benchmark, time_rollouts
from cpmp.errors import ConfigError
from cpmp.sim import Box
from cpmp.sim.policies import ReplayPolicy


def _check_episode(report, cfg):
    assert report["wall_time_s"] > 0 and report["sim_time_s"] > 0
    assert report["real_time_factor"] == pytest.approx(report["sim_time_s"] / report["wall_time_s"])
    assert report["meets_target"] == (report["real_time_factor"] >= TARGET_REAL_TIME_FACTOR)
    assert set(report["share"]) == {"physics", "kinematics", "policy", "other"}
    assert sum(report["share"].values()) == pytest.approx(1.0)
    # physics and kinematics (IK + features) run every tick: both are timed
    assert report["share"]["physics"] > 0 and report["share"]["kinematics"] > 0
    ticks = round(report["sim_time_s"] / cfg.control_dt)
    per_tick = sum(report["ms_per_tick"].values()) * ticks / 1e3
    assert per_tick == pytest.approx(report["wall_time_s"], rel=1e-6)


def test_replay_benchmark_times_a_complete_episode(cfg, boxes):
    report = benchmark(cfg, boxes["right"], n_demos=0)
    assert report["strategy"] == "right"
    assert report["demonstration"]["success"]
    assert report["kinematics"]["compiled"] is cfg.compile_kinematics
    assert report["replay"]["outcome"] == "complete"
    _check_episode(report["replay"], cfg)
    assert "learned" not in report


@pytest.mark.slow
def test_learned_policy_benchmark_reports_the_full_loop(cfg, boxes):
    report = benchmark(cfg, boxes["right"], n_demos=3, seed=1)
    learned = report["learned"]
    _check_episode(learned, cfg)
    assert learned["n_demos"] == 3 and learned["fit_seconds"] > 0
    assert learned["n_heads"] > 0 and learned["n_support_total"] > 0
    assert learned["ms_per_tick"]["policy"] > 0


@pytest.mark.slow
def test_batched_rollouts_time_the_same_episodes(cfg, demos):
    """Replaying each box's demonstration, one at a time and batched: the same outcomes and
    simulated time, and each report's shares and real-time factor add up."""

    order = ["right", "left"]
    expected = [demos[s] for s in order]
    boxes = [Box(*(d.metadata[f"box_{k}"] for k in ("width", "depth", "height"))) for d in expected]
    reports = [
        time_rollouts(boxes, [ReplayPolicy(d) for d in expected], cfg, expected, batched=b)
        for b in (False, True)
    ]
    single, batched = reports
    assert single.outcomes == batched.outcomes == ["complete", "complete"]
    assert single.sim_time_s == pytest.approx(batched.sim_time_s, abs=1e-9)
    assert (single.batched, batched.batched) == (False, True)
    for report in reports:
        assert report.n_episodes == 2
        assert sum(report.share.values()) == pytest.approx(1.0)
        ticks = round(report.sim_time_s / cfg.control_dt)
        total = sum(report.ms_per_tick.values()) * ticks / 1e3
        assert total == pytest.approx(report.wall_time_s, rel=1e-6)


def test_rollouts_need_one_expected_demo_per_box(cfg, demos, boxes):

    with pytest.raises(ConfigError, match="one expected demonstration per box: 1 boxes, 0"):
        time_rollouts([boxes["right"]], [ReplayPolicy(demos["right"])], cfg, [])
