"""Scene, kinematics and MP controller tests."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from cpmp.errors import ConfigError
from cpmp.sim import Box, Simulation, TaskConfig, correct_strategy
from cpmp.sim.control import rotation_angle
from cpmp.sim.scene import ARM_JOINTS, HANDS, build_model, scene_xml_text
from cpmp.sim.simulation import shared_kinematics


def test_model_has_25_actuated_hinges(cfg):
    model = build_model(Box(0.2, 0.15, 0.1), cfg)
    hinge = int(mujoco.mjtJoint.mjJNT_HINGE)
    position = [
        i
        for i in range(model.nu)
        if model.actuator_trntype[i] == int(mujoco.mjtTrn.mjTRN_JOINT)
        and model.jnt_type[model.actuator_trnid[i, 0]] == hinge
    ]
    assert len(position) == 25
    assert sum(model.jnt_type == hinge) == 25
    assert np.all(model.jnt_limited[model.jnt_type == hinge])
    assert model.geom("box").size == pytest.approx([0.075, 0.1, 0.05])


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
    from cpmp.sim import kinematics

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


def test_strategy_regions(cfg, boxes):
    for strategy, box in boxes.items():
        assert correct_strategy(box, cfg) == strategy
    assert correct_strategy(Box(0.2, 0.22, 0.1), cfg) == "left"
    assert correct_strategy(Box(0.2001, 0.22, 0.1), cfg) == "both"


def test_invalid_config_raises_config_error():
    with pytest.raises(ConfigError):
        TaskConfig(width_range=(0.3, 0.1))
    with pytest.raises(ConfigError):
        TaskConfig.from_dict({"control_dt": 0.003})
    with pytest.raises(ConfigError):
        TaskConfig.from_dict({"no_such_option": 1})
    with pytest.raises(ConfigError):
        Box(-0.1, 0.1, 0.1)
    with pytest.raises(ConfigError, match="compile_kinematics must be true or false"):
        TaskConfig.from_dict({"compile_kinematics": "yes"})


def test_visual_description(cfg):
    sim = Simulation(cfg, Box(0.15, 0.12, 0.1))
    geoms = sim.geoms()
    assert {g["type"] for g in geoms} == {"box", "capsule", "sphere", "cylinder"}
    poses = sim.body_poses()
    assert {g["body"] for g in geoms} <= set(poses) | {"world"}
    pos, quat = poses["box"]
    assert pos == pytest.approx(sim.box_pos())
    assert np.linalg.norm(quat) == pytest.approx(1.0)
