"""Arm kinematics (cpmp.sim.kinematics): pytorch-kinematics against MuJoCo, compiled against
eager."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
import torch

from cpmp.sim import (
    Box,
    Simulation,
    kinematics,
)
from cpmp.sim.scene import ARM_JOINTS, HANDS, scene_xml_text
from cpmp.sim.simulation import shared_kinematics


def test_fk_and_jacobian_match_mujoco(cfg):
    sim = Simulation(cfg, Box(0.2, 0.15, 0.1))
    kin = shared_kinematics()
    rng = np.random.default_rng(0)
    m, d = sim.model, sim.data
    for _ in range(10):
        q = rng.uniform(sim.arm_limits[..., 0], sim.arm_limits[..., 1])
        d.qpos[sim._arm_qpos] = q
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        pos, rot, jac = kin.fk_jacobian(q)
        for i, hand in enumerate(HANDS):
            site = m.site(f"{hand}_ee").id
            # float64 chains agree to ~1e-8 m; 1e-5 m is the acceptance bound of the issue
            assert np.max(np.abs(pos[i] - d.site_xpos[site])) < 1e-5
            own_pos, own_rot = kin.fk(hand, q[i])
            assert np.max(np.abs(own_rot[0] - rot[i])) < 1e-9  # same chain layout, float64
            assert np.max(np.abs(own_pos[0] - d.site_xpos[site])) < 1e-5
            assert np.max(np.abs(rot[i] - d.site_xmat[site].reshape(3, 3))) < 1e-6
            jacp, jacr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
            mujoco.mj_jacSite(m, d, jacp, jacr, site)
            dofs = [m.joint(f"{hand}_{j}").dofadr[0] for j in ARM_JOINTS]
            expected = np.vstack([jacp[:, dofs], jacr[:, dofs]])
            assert np.max(np.abs(jac[i] - expected)) < 1e-6


def test_compiled_jacobian_equals_eager_pytorch_kinematics(cfg):
    compiled, eager = shared_kinematics(True), shared_kinematics(False)
    assert compiled.compiled and not eager.compiled
    rng = np.random.default_rng(1)
    limits = Simulation(cfg, Box(0.2, 0.15, 0.1)).arm_limits
    for _ in range(5):
        q = rng.uniform(limits[..., 0], limits[..., 1])
        for got, want in zip(compiled.fk_jacobian(q), eager.fk_jacobian(q), strict=True):
            np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)


def test_failed_compilation_falls_back_to_eager_with_a_warning(monkeypatch):

    def no_compiler(*args, **kwargs):
        raise RuntimeError("no C++ compiler")

    monkeypatch.setattr(kinematics.torch, "compile", no_compiler)
    eager = shared_kinematics(False)
    with pytest.warns(RuntimeWarning, match="no C\\+\\+ compiler"):
        kin = kinematics.ArmKinematics(scene_xml_text(), _mounts(eager), compile=True)
    assert not kin.compiled
    q = np.linspace(-1.0, 1.0, 14).reshape(2, 7)
    for got, want in zip(kin.fk_jacobian(q), eager.fk_jacobian(q), strict=True):
        np.testing.assert_array_equal(got, want)


def _mounts(kin):
    return {hand: kin.mount_pos[i] for i, hand in enumerate(HANDS)}


def test_compiled_jacobian_is_not_recompiled_by_the_rollouts():
    kin = shared_kinematics.__wrapped__(True)  # a fresh build, not the session's cached one
    if not kin.compiled:
        pytest.skip("torch.compile is unavailable here; the eager Jacobian runs")
    # the start-up check compiled it for the inputs fk_jacobian makes: any robot count runs
    # that code (a recompile would cost seconds per process)
    eager = shared_kinematics(False)
    with torch.compiler.set_stance("fail_on_recompile"):
        for q in (np.zeros((2, 7)), np.zeros((1, 2, 7)), np.full((6, 2, 7), 0.3)):
            for got, want in zip(kin.fk_jacobian(q), eager.fk_jacobian(q), strict=True):
                np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
