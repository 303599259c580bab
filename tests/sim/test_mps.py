"""The MPs (cpmp.sim.mps) under the controller: attractors converge, the relative MP follows."""

from __future__ import annotations

import numpy as np

from cpmp.sim import (
    Box,
    Simulation,
)
from cpmp.sim.control import rotation_angle
from cpmp.sim.scene import HANDS


def _run(sim, active, seconds):
    sim.set_active(active)
    for _ in range(round(seconds / sim.cfg.control_dt)):
        assert sim.step()


def test_world_rotation_and_finger_mps_converge_from_random_start(cfg):
    sim = Simulation(cfg, Box(0.15, 0.12, 0.1))
    rng = np.random.default_rng(3)
    start = sim.q_home + rng.uniform(-0.3, 0.3, size=sim.q_home.shape)
    fingers = {h: rng.uniform(0.0, 1.5, size=len(f)) for h, f in sim.finger_angles().items()}
    sim.reset(arm_posture=start, fingers=fingers)
    active = {
        "left_pos": "home",
        "left_rot": "down",
        "left_fingers": "grasp",
        "right_pos": "home",
        "right_rot": "home",
        "right_fingers": "release",
    }
    _run(sim, active, 4.0)
    # 4 s is > 10 time constants of every attractor; a few mm remain from actuator tracking
    assert np.max(np.linalg.norm(sim.ee_pos() - sim.home_pos, axis=1)) < 0.005
    for i, hand in enumerate(HANDS):
        goal = sim.goal(f"{hand}_rot")
        assert rotation_angle(goal, sim.ee_rot()[i]) < 0.02  # rad, same reason
        err = sim.finger_angles()[hand] - sim.goal(f"{hand}_fingers")
        assert np.max(np.abs(err)) < 0.02  # rad
    features = dict(zip(sim.feature_names, sim.features(), strict=True))
    assert features["dist.left_fingers.grasp"] < 0.01
    assert features["dist.left_fingers.relax"] > 0.9
    assert features["dist.left_rot.down"] < 0.01


def test_relative_mp_keeps_left_hand_offset_to_right(cfg):
    sim = Simulation(cfg, Box(0.15, 0.12, 0.1))
    offset = sim.ee_pos()[0] - sim.ee_pos()[1]
    active = {v: names[0] for v, names in sim.mp_names.items()}
    active["left_pos"] = "follow_right"
    active["right_pos"] = "carry"  # held MP: hand moves with its latched offset to the box goal
    _run(sim, active, 3.0)
    moved = np.linalg.norm(sim.ee_pos()[1] - sim.home_pos[1])
    assert moved > 0.2
    # feed-forward of the right hand's velocity keeps the offset to within a few mm
    assert np.linalg.norm(sim.ee_pos()[0] - sim.ee_pos()[1] - offset) < 0.01
