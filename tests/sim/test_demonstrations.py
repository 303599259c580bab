"""Scripted demonstrator, recording, HDF5 round trip and the closed-loop runner."""

from __future__ import annotations

import numpy as np
import pytest

from cpmp.datafile import load_demonstrations, save_demonstrations
from cpmp.errors import UnknownMPError
from cpmp.sim import (
    STRATEGIES,
    Box,
    Simulation,
    TaskConfig,
    correct_strategy,
    mp_sequences,
    record_demonstration,
    run_episode,
    sample_box,
)
from cpmp.sim.collect import collect_demonstrations, sample_boxes
from cpmp.sim.runner import ReplayPolicy


def test_demonstrator_completes_each_strategy(demos, cfg):
    for strategy, demo in demos.items():
        meta = demo.metadata
        assert meta["strategy"] == strategy
        assert meta["success"], strategy
        # moderate episodes: the recordings stay short enough to learn from quickly
        assert 5.0 < demo.duration < 15.0
        assert demo.features.shape == (demo.n_samples, 33)
        assert len(demo.feature_names) == 33 == len(set(demo.feature_names))
        assert np.all(demo.features > -0.05) and np.all(demo.features < 1.05)
        assert sorted(demo.variables) == sorted(Simulation(cfg, Box(0.2, 0.2, 0.1)).variables)


def test_strategies_start_differently_and_switch_concurrently(demos):
    starts = {s: tuple(str(lab[0]) for lab in d.labels.values()) for s, d in demos.items()}
    assert len(set(starts.values())) == 3
    seqs = {s: mp_sequences(d) for s, d in demos.items()}
    assert seqs["right"]["left_pos"] == ["idle"]  # the idle hand keeps one MP throughout
    assert seqs["right"]["right_pos"] == ["reach_top", "lift", "carry", "lower", "home"]
    assert seqs["both"]["left_pos"] == ["reach_edge", "follow_right", "home"]
    both = demos["both"]
    switch = {v: set(both.time[both.switch_indices(v)]) for v in both.variables}
    # real concurrency: fingers and orientation switch at times of their own ...
    assert switch["right_fingers"] - switch["right_pos"]
    assert switch["right_rot"] - switch["right_pos"]
    # ... and the bimanual lift is one synchronisation point of both position variables
    assert switch["left_pos"] & switch["right_pos"]


def test_grasp_closes_finger_feature(demos):
    demo = demos["right"]
    col = demo.feature_names.index("dist.right_fingers.grasp")
    labels = demo.labels["right_pos"]
    lift_start = int(np.flatnonzero(labels == "lift")[0])
    assert demo.features[0, col] > 0.9
    # the lift starts only once the grasp's goal-distance feature is below finger_tol
    assert demo.features[lift_start, col] < 0.02 + 1e-9
    z = demo.feature_names.index("box_z")
    assert demo.features[-1, z] < demo.features[lift_start, z] + 0.01


def test_same_box_gives_identical_demo(cfg, demos):
    again = record_demonstration(Box(0.15, 0.12, 0.10), cfg, name="demo_right")
    first = demos["right"]
    assert np.array_equal(again.features, first.features)
    for variable in first.variables:
        assert np.array_equal(again.labels[variable], first.labels[variable])


def test_hdf5_round_trip(tmp_path, demos):
    path = tmp_path / "demos.h5"
    save_demonstrations(path, list(demos.values()))
    loaded = {d.name: d for d in load_demonstrations(path)}
    for demo in demos.values():
        back = loaded[demo.name]
        assert np.array_equal(back.features, demo.features)
        assert np.array_equal(back.time, demo.time)
        assert back.feature_names == demo.feature_names
        assert back.metadata["strategy"] == demo.metadata["strategy"]
        for variable in demo.variables:
            assert list(back.labels[variable]) == list(demo.labels[variable])


def test_balanced_box_sampling_is_seeded(cfg):
    a = sample_boxes(np.random.default_rng(7), cfg, 6, balanced=True)
    b = sample_boxes(np.random.default_rng(7), cfg, 6, balanced=True)
    assert a == b
    assert [correct_strategy(box, cfg) for box in a] == list(STRATEGIES) * 2
    box = sample_box(np.random.default_rng(0), cfg)
    assert cfg.width_range[0] <= box.width <= cfg.width_range[1]


def test_replayed_demo_completes(demos, boxes, cfg):
    demo, ticks = demos["left"], []
    policy = ReplayPolicy(demo)
    result = run_episode(boxes["left"], policy, cfg, expected=demo, on_tick=ticks.append)
    assert result.outcome == "complete", result.reason
    assert result.box_in_container and result.hands_home
    assert result.sequences == mp_sequences(demo)
    # the replay switches when the labels do: the runner's records are the demonstration's
    ran = sorted((e.t, e.variable, e.source, e.target) for e in result.transitions)
    assert ran == [(e.t, e.variable, e.source, e.target) for e in demo.transitions()]
    assert result.transitions[0].state.shape == (33,)
    assert all(np.isnan(e.probability) for e in result.transitions)
    # one tick record per control tick, with what the runner observed
    dt = cfg.control_dt
    assert [tick.t for tick in ticks[:3]] == pytest.approx([0.0, dt, 2 * dt])
    np.testing.assert_array_equal(ticks[0].features, demo.features[0])
    assert ticks[0].active == {v: str(labels[0]) for v, labels in demo.labels.items()}
    assert "box" in ticks[0].body_poses and ticks[0].progress == {}


def test_wrong_start_and_wrong_transition(demos, boxes, cfg):
    result = run_episode(boxes["right"], ReplayPolicy(demos["left"]), cfg, expected=demos["right"])
    assert result.outcome == "wrong_start"
    assert result.initial["left_pos"] == "reach_top"

    class SkipLift(ReplayPolicy):
        def step(self, t, x):
            active = super().step(t, x)
            if active["right_pos"] == "lift":
                active["right_pos"] = "carry"
            return active

    result = run_episode(boxes["right"], SkipLift(demos["right"]), cfg, expected=demos["right"])
    assert result.outcome == "incomplete"
    assert "right_pos: reach_top -> carry" in result.reason


def test_time_out_and_unknown_mp(demos, boxes, cfg):
    class Frozen(ReplayPolicy):
        def step(self, t, x):
            return self.reset(0.0, x)

    result = run_episode(
        boxes["right"], Frozen(demos["right"]), cfg, max_time=1.0, expected=demos["right"]
    )
    assert result.outcome == "incomplete" and "time-out" in result.reason
    assert result.duration == pytest.approx(1.0)

    class Bogus(ReplayPolicy):
        def reset(self, t, x):
            return dict(super().reset(t, x), right_pos="fly")

    with pytest.raises(UnknownMPError):
        run_episode(boxes["right"], Bogus(demos["right"]), cfg, expected=demos["right"])


def test_divergence_is_reported_not_raised(demos, boxes, cfg, monkeypatch):
    original = Simulation.step

    def blow_up(self):
        if self.t > 0.5:
            self.data.qvel[:] = np.nan  # what an unstable integration leaves behind
        return original(self)

    monkeypatch.setattr(Simulation, "step", blow_up)
    result = run_episode(boxes["both"], ReplayPolicy(demos["both"]), cfg, expected=demos["both"])
    assert result.outcome == "diverged"
    assert "diverged" in result.reason
    assert not result.box_in_container


def test_collect_writes_seeded_file(tmp_path):
    cfg = TaskConfig()
    path, demos = collect_demonstrations(cfg, 1, seed=3, path=tmp_path / "d.h5")
    loaded = load_demonstrations(path)
    assert len(loaded) == 1 and loaded[0].metadata["strategy"] == "both"
    assert np.array_equal(loaded[0].features, demos[0].features)
