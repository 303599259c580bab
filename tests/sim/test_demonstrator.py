"""The scripted demonstrator (cpmp.sim.demonstrator): every strategy completes, with
concurrent switches."""

from __future__ import annotations

import numpy as np
import pytest

from cpmp.sim import (
    Box,
    Simulation,
    TaskConfig,
    correct_strategy,
    mp_sequences,
    record_demonstration,
    sample_box,
)


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


@pytest.mark.slow
def test_demonstrator_succeeds_on_grid_and_random_boxes():
    cfg = TaskConfig()
    grid = [
        Box(w, d, cfg.box_height)
        for w in np.linspace(*cfg.width_range, 5)
        for d in np.linspace(*cfg.depth_range, 4)
    ]
    rng = np.random.default_rng(2024)
    boxes = grid + [sample_box(rng, cfg) for _ in range(10)]
    failures = []
    for box in boxes:
        meta = record_demonstration(box, cfg).metadata
        if not meta["success"] or meta["strategy"] != correct_strategy(box, cfg):
            failures.append((box, meta))
    assert not failures
