"""The simulation (cpmp.sim.simulation): batched control ticks and the visual description."""

from __future__ import annotations

import numpy as np
import pytest

from cpmp.errors import CpmpError
from cpmp.sim import (
    Box,
    Simulation,
)
from cpmp.sim.simulation import prepare_steps, shared_kinematics


def test_batched_jacobians_and_controls_equal_single_ones_bit_for_bit(cfg):
    kin = shared_kinematics(cfg.compile_kinematics)
    rng = np.random.default_rng(0)
    sims = [Simulation(cfg, Box(w, d, 0.1)) for w, d in ((0.25, 0.15), (0.15, 0.12), (0.15, 0.2))]
    q = rng.uniform(sims[0].arm_limits[..., 0], sims[0].arm_limits[..., 1], size=(5, 2, 7))
    together = kin.fk_jacobian(q)
    for i in range(len(q)):
        for got, want in zip(together, kin.fk_jacobian(q[i]), strict=True):
            np.testing.assert_array_equal(got[i], want)
    # one tick of three different boxes' controllers together, then alone from the same state
    active = {v: names[0] for v, names in sims[0].mp_names.items()}
    active.update(right_pos="reach_top", right_rot="down", left_pos="reach_edge")
    alone = [Simulation(cfg, sim.box) for sim in sims]
    for group in (sims, alone):
        for sim in group:
            sim.set_active(active)
    prepare_steps(sims)
    for sim, single in zip(sims, alone, strict=True):
        assert sim.step() and single.step()
        np.testing.assert_array_equal(sim.data.ctrl, single.data.ctrl)
        np.testing.assert_array_equal(sim.data.qpos, single.data.qpos)
    # a prepared control belongs to the MPs it was computed for
    prepare_steps(sims[:1])
    with pytest.raises(CpmpError, match="after prepare_steps"):
        sims[0].set_active(dict(active, right_fingers="grasp"))


def test_visual_description(cfg):
    sim = Simulation(cfg, Box(0.15, 0.12, 0.1))
    geoms = sim.geoms()
    assert {g["type"] for g in geoms} == {"box", "capsule", "sphere", "cylinder"}
    poses = sim.body_poses()
    assert {g["body"] for g in geoms} <= set(poses) | {"world"}
    pos, quat = poses["box"]
    assert pos == pytest.approx(sim.box_pos())
    assert np.linalg.norm(quat) == pytest.approx(1.0)
