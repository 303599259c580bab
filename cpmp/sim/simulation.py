"""The simulated world of one episode: MuJoCo model + MP controller + features."""

from __future__ import annotations

import functools
import time
from collections.abc import Mapping, Sequence

import mujoco
import numpy as np

from cpmp.config.task import TaskConfig
from cpmp.errors import CpmpError, UnknownMPError
from cpmp.sim.control import MPController, rotation_angle, update_controllers
from cpmp.sim.features import GoalDistances, box_size_features, compute_features, feature_names
from cpmp.sim.kinematics import ArmKinematics
from cpmp.sim.mps import MP, VARIABLES, build_library, container_center
from cpmp.sim.scene import (
    ARM_JOINTS,
    FINGER_JOINTS,
    HANDS,
    Box,
    build_spec,
    home_posture,
    scene_xml_text,
)

CONTAINER_INNER_HALF = np.array([0.15, 0.18])
"""Half extents [m] (x, y) of the container's inner floor."""

_GEOM_TYPES = {
    int(mujoco.mjtGeom.mjGEOM_BOX): "box",
    int(mujoco.mjtGeom.mjGEOM_CAPSULE): "capsule",
    int(mujoco.mjtGeom.mjGEOM_SPHERE): "sphere",
    int(mujoco.mjtGeom.mjGEOM_CYLINDER): "cylinder",
}


_INSTABILITY_WARNINGS = np.array(
    [
        int(mujoco.mjtWarning.mjWARN_BADQPOS),
        int(mujoco.mjtWarning.mjWARN_BADQVEL),
        int(mujoco.mjtWarning.mjWARN_BADQACC),
    ]
)
"""MuJoCo warnings that mean the integration blew up (MuJoCo then resets the state itself)."""


@functools.lru_cache(maxsize=2)
def shared_kinematics(compile: bool = True) -> ArmKinematics:
    """The arm kinematics (independent of the box), built once per process and ``compile``.

    See :class:`~cpmp.sim.kinematics.ArmKinematics`.
    """
    xml = scene_xml_text()
    model = mujoco.MjModel.from_xml_string(xml)
    mounts = {h: model.body(f"{h}_mount").pos.copy() for h in HANDS}
    return ArmKinematics(xml, mounts, compile=compile)


class Simulation:
    """One episode's world: the robot, the scene with ``box``, the MPs and the features.

    Attributes:
        variables: the six control variables.
        mp_names: MP names per variable.
        feature_names: names of :meth:`features`, length d = 33.
        t: simulated time [s] since :meth:`reset`.
        timing: wall time [s] spent in ``physics`` and ``kinematics`` (IK + features) since
            reset.
    """

    def __init__(self, cfg: TaskConfig, box: Box) -> None:
        self.cfg = cfg
        self.box = box
        self.model = build_spec(box, cfg).compile()
        self.model.opt.timestep = cfg.physics_dt
        self.data = mujoco.MjData(self.model)
        self._warnings = self.data.warning.number  # a live view, read every tick
        self.kin = shared_kinematics(cfg.compile_kinematics)
        m = self.model
        self.n_substeps = round(cfg.control_dt / m.opt.timestep)
        self._arm_qpos = np.array(
            [[m.joint(f"{h}_{j}").qposadr[0] for j in ARM_JOINTS] for h in HANDS]
        )
        self._arm_act = np.array([[m.actuator(f"{h}_{j}").id for j in ARM_JOINTS] for h in HANDS])
        self._finger_qpos = {
            h: np.array([m.joint(f"{h}_{j}").qposadr[0] for j in FINGER_JOINTS[h]]) for h in HANDS
        }
        self._finger_act = {
            h: np.array([m.actuator(f"{h}_{j}").id for j in FINGER_JOINTS[h]]) for h in HANDS
        }
        self._adhesion = {h: m.actuator(f"{h}_adhesion").id for h in HANDS}
        # actuators written each tick: arms (rows left, right), fingers per hand, adhesion
        self._ctrl_index = np.concatenate(
            [self._arm_act.ravel()]
            + [self._finger_act[h] for h in HANDS]
            + [np.array([self._adhesion[h] for h in HANDS])]
        )
        self._site = np.array([m.site(f"{h}_ee").id for h in HANDS])
        self._box_body = m.body("box").id
        named = [i for i in range(1, m.nbody) if m.body(i).name]
        self._named_bodies = (np.array(named, dtype=int), [m.body(i).name for i in named])
        self._box_geom = m.geom("box").id
        self._palm_geom = {h: m.geom(f"{h}_palm").id for h in HANDS}
        support_bodies = {m.body(name).id for name in ("world", "table", "plate", "container")}
        # per geom: (is the left palm, is the right palm, belongs to a support body)
        self._touch_table = np.zeros((m.ngeom, 3), dtype=bool)
        for i, hand in enumerate(HANDS):
            self._touch_table[self._palm_geom[hand], i] = True
        self._touch_table[:, 2] = np.isin(m.geom_bodyid, list(support_bodies))
        self._robot_dofs = np.array(
            [m.joint(i).dofadr[0] for i in range(m.njnt) if m.joint(i).name != "box_free"]
        )
        self._box_qpos = m.joint("box_free").qposadr[0]
        self.arm_limits = np.array([[m.joint(f"{h}_{j}").range for j in ARM_JOINTS] for h in HANDS])
        self.q_home = np.stack([home_posture(h) for h in HANDS])
        home_pos, home_rot = {}, {}
        for i, hand in enumerate(HANDS):
            pos, rot = self.kin.fk(hand, self.q_home[i])
            home_pos[hand], home_rot[hand] = pos[0], rot[0]
        self.home_pos = np.stack([home_pos[h] for h in HANDS])
        self.library: dict[str, dict[str, MP]] = build_library(box, cfg, home_pos, home_rot)
        self.variables: list[str] = list(VARIABLES)
        self.mp_names: dict[str, list[str]] = {v: list(mps) for v, mps in self.library.items()}
        self.feature_names: list[str] = feature_names(self.library)
        self._size_features = box_size_features(box, cfg)
        self._goal_distances = GoalDistances(self.library, cfg)
        self.controller = MPController(cfg, self.kin, self.arm_limits, self.q_home)
        self.active: dict[str, str] = {}
        self._control: np.ndarray | None = None
        self.timing = {"physics": 0.0, "kinematics": 0.0}
        self.reset()

    def reset(
        self, arm_posture: np.ndarray | None = None, fingers: dict[str, np.ndarray] | None = None
    ) -> None:
        """Reset to a start posture and finger angles, the box at rest on the plate, ``t = 0``.

        The posture defaults to home, the fingers to the ``relax`` goal. arm_posture: (2, 7)
        [rad], rows (left, right).
        """
        m, d = self.model, self.data
        mujoco.mj_resetData(m, d)
        relax = self.cfg.finger_goals["relax"]
        if fingers is None:
            fingers = {h: np.full(len(FINGER_JOINTS[h]), relax) for h in HANDS}
        q = self.q_home if arm_posture is None else np.asarray(arm_posture, dtype=np.float64)
        d.qpos[self._arm_qpos] = q
        d.ctrl[self._arm_act] = q
        for hand in HANDS:
            d.qpos[self._finger_qpos[hand]] = fingers[hand]
            d.ctrl[self._finger_act[hand]] = fingers[hand]
        mujoco.mj_forward(m, d)
        self.controller.reset(q, fingers)
        self.active = {}
        self._control = None
        self.t = 0.0
        self.timing = {"physics": 0.0, "kinematics": 0.0}

    def set_active(self, active: Mapping[str, str]) -> None:
        """Activate one MP per control variable (short names from :attr:`mp_names`)."""
        if active == self.active:
            return
        for variable in self.variables:
            if variable not in active:
                raise UnknownMPError(f"no MP given for control variable {variable!r}")
            if active[variable] not in self.library[variable]:
                raise UnknownMPError(
                    f"unknown MP {active[variable]!r} for {variable!r}; "
                    f"known: {self.mp_names[variable]}"
                )
        unknown = sorted(set(active) - set(self.variables))
        if unknown:
            raise UnknownMPError(f"unknown control variable(s) {unknown}; known: {self.variables}")
        if self._control is not None:
            raise CpmpError(
                "set_active() changed the MPs after prepare_steps() computed this tick's control;"
                " set the MPs first, then prepare_steps(), then step()"
            )
        self.active = {v: str(active[v]) for v in self.variables}

    def set_speeds(self, speeds: Mapping[str, float]) -> None:
        """Pace the MPs of the next ticks: variable -> factor on its velocity (0: it holds).

        A variable not named runs at its nominal speed (see :mod:`cpmp.sim.control`).
        """
        if self._control is not None:
            raise CpmpError(
                "set_speeds() changed the pace after prepare_steps() computed this tick's "
                "control; set the MPs and speeds first, then prepare_steps(), then step()"
            )
        unknown = sorted(set(speeds) - set(self.variables))
        if unknown:
            raise UnknownMPError(f"unknown control variable(s) {unknown}; known: {self.variables}")
        self.controller.speed = {v: float(f) for v, f in speeds.items()}

    def goal_distances(self, active: Mapping[str, str] | None = None) -> dict[str, float]:
        """Each variable's distance to the goal of an MP (default: the active ones).

        Positions [m] of the end-effector site, orientations [rad] of the site, finger angles
        [rad] (Euclidean over a hand's finger joints).
        """
        active = self.active if active is None else active
        out = {}
        ee_pos, ee_rot, fingers = self.ee_pos(), self.ee_rot(), self.finger_angles()
        for variable in self.variables:
            hand, kind = variable.split("_")
            goal = self.goal(variable, active[variable])
            i = HANDS.index(hand)
            if kind == "pos":
                out[variable] = float(np.linalg.norm(ee_pos[i] - goal))
            elif kind == "rot":
                out[variable] = float(rotation_angle(goal, ee_rot[i]))
            else:
                out[variable] = float(np.linalg.norm(fingers[hand] - goal))
        return out

    def step(self) -> bool:
        """Run the active MPs for one control tick. Returns False if the physics diverged.

        Applies the control that :func:`prepare_steps` computed for this tick (together with
        other simulations'), or computes it here.
        """
        if not self.active:
            raise UnknownMPError("call set_active() before step()")
        if self._control is None:
            prepare_steps([self])
        d = self.data
        d.ctrl[self._ctrl_index] = self._control
        self._control = None
        start = time.perf_counter()
        mujoco.mj_step(self.model, d, nstep=self.n_substeps)
        mujoco.mj_kinematics(self.model, d)
        self.timing["physics"] += time.perf_counter() - start
        self.t += self.cfg.control_dt
        return not self.diverged()

    def _control_vector(self) -> np.ndarray:
        """Actuator targets of the controller's references, in ``_ctrl_index`` order."""
        ctl = self.controller
        adhesion = [1.0 if self.active[f"{h}_fingers"] == "grasp" else 0.0 for h in HANDS]
        return np.concatenate(
            [ctl.q_ref.ravel()] + [ctl.fingers_ref[h] for h in HANDS] + [adhesion]
        )

    def diverged(self) -> bool:
        """True if the state holds NaN/inf, MuJoCo flagged bad accelerations, or speeds blew up."""
        d = self.data
        # NaN/inf speeds fail the comparison too
        if not (np.isfinite(d.qpos).all() and np.abs(d.qvel).max() <= 1e3):
            return True
        return bool(self._warnings[_INSTABILITY_WARNINGS].any())

    # measured state -------------------------------------------------------------------------
    def box_pos(self) -> np.ndarray:
        """Measured box centre [m], shape (3,)."""
        return self.data.xpos[self._box_body].copy()

    def ee_pos(self) -> np.ndarray:
        """Measured end-effector site positions [m], (2, 3), rows (left, right)."""
        return self.data.site_xpos[self._site]  # fancy indexing copies

    def ee_rot(self) -> np.ndarray:
        """Measured end-effector site rotation matrices, (2, 3, 3)."""
        return self.data.site_xmat[self._site].reshape(2, 3, 3)  # fancy indexing copies

    def finger_angles(self) -> dict[str, np.ndarray]:
        """Measured finger joint angles [rad] per hand."""
        return {h: self.data.qpos[self._finger_qpos[h]].copy() for h in HANDS}

    def _touches(self) -> np.ndarray:
        """Touch flags (3,) bool: left palm-box, right palm-box, box-support contact."""
        pairs = self.data.contact.geom[: self.data.ncon]
        # the other geom of every contact pair that involves the box
        partners = pairs[:, ::-1][pairs == self._box_geom]
        return self._touch_table[partners].any(axis=0)

    def palm_touches_box(self, hand: str) -> bool:
        """True if ``hand``'s palm is in contact with the box."""
        return bool(self._touches()[HANDS.index(hand)])

    def box_supported(self) -> bool:
        """True if the box touches a static surface (table, plate or container)."""
        return bool(self._touches()[2])

    def contacts(self) -> np.ndarray:
        """Touch signals (3,): left palm-box, right palm-box, box-support (0 or 1)."""
        return self._touches().astype(np.float64)

    def robot_speed(self) -> float:
        """Largest arm/finger joint speed [rad/s]."""
        return float(np.max(np.abs(self.data.qvel[self._robot_dofs])))

    def features(self) -> np.ndarray:
        """Feature vector (33,) of the current state; see :mod:`cpmp.sim.features`."""
        start = time.perf_counter()
        out = compute_features(
            self._size_features,
            self.box_pos(),
            self.ee_pos(),
            self.ee_rot(),
            self.finger_angles(),
            self.contacts(),
            self._goal_distances,
        )
        self.timing["kinematics"] += time.perf_counter() - start
        return out

    def goal(self, variable: str, name: str | None = None) -> np.ndarray:
        """Current world goal of an MP (default: the active one).

        A position (3,), rotation (3, 3) or finger angles (k,). Held/relative goals use the
        controller's latched offset (or the current offset if the MP has not run yet).
        """
        mp = self.library[variable][name or self.active[variable]]
        hand = HANDS.index(variable.split("_")[0])
        if mp.kind != "position" or mp.frame == "world":
            return mp.target.copy()
        if mp.frame == "box":
            return self.box_pos() + mp.target
        latched = self.controller._latched.get(variable)
        if mp.frame == "held":
            offset = latched if latched is not None else self.ee_pos()[hand] - self.box_pos()
            return mp.target + offset
        ref = self.controller.ref_pos
        offset = latched if latched is not None else ref[0] - ref[1]
        return self.ee_pos()[1] + offset

    def box_in_container(self) -> bool:
        """Box rests inside the container: footprint within the inner floor, bottom on it."""
        pos = self.box_pos()
        rot = self.data.xmat[self._box_body].reshape(3, 3)
        half = np.abs(rot[:2, :2]) @ np.array([self.box.depth, self.box.width]) / 2
        inside = np.all(
            np.abs(pos[:2] - container_center()[:2]) + half <= CONTAINER_INNER_HALF + 1e-3
        )
        resting = abs(pos[2] - self.box.height / 2 - container_center()[2]) < 0.02
        return bool(inside and resting)

    def hands_home(self) -> bool:
        """Both end-effectors within ``cfg.home_tol`` of their home positions."""
        dist = np.linalg.norm(self.ee_pos() - self.home_pos, axis=1)
        return bool(np.all(dist < self.cfg.home_tol))

    # visualisation -------------------------------------------------------------------------
    def body_poses(self) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """World pose of every named body: name -> (pos (3,) [m], quat wxyz (4,))."""
        ids, names = self._named_bodies
        # rows of two fresh copies: one fancy index per array, not two copies per body
        poses = zip(self.data.xpos[ids], self.data.xquat[ids], strict=True)
        return dict(zip(names, poses, strict=True))

    def geoms(self) -> list[dict]:
        """Static description of the visual geoms (floor plane excluded).

        Each dict: ``body`` (name), ``name`` (MuJoCo's, or ``<type>_<geom id>`` for an unnamed
        geom: unique per body), ``type`` ('box' | 'capsule' | 'sphere' |
        'cylinder'), ``size`` (MuJoCo convention: box half-extents (3,); capsule/cylinder
        (radius, half-length along local z); sphere (radius,)), ``pos`` (3,) and ``quat`` wxyz
        (4,) in the body frame, ``rgba`` (4,).
        """
        m = self.model
        out = []
        for i in range(m.ngeom):
            kind = _GEOM_TYPES.get(int(m.geom_type[i]))
            if kind is None:
                continue
            n_size = {"box": 3, "capsule": 2, "cylinder": 2, "sphere": 1}[kind]
            out.append(
                {
                    "body": m.body(int(m.geom_bodyid[i])).name,
                    # unnamed geoms (arm links, fingers) get their own entity path
                    "name": m.geom(i).name or f"{kind}_{i}",
                    "type": kind,
                    "size": m.geom_size[i][:n_size].copy(),
                    "pos": m.geom_pos[i].copy(),
                    "quat": m.geom_quat[i].copy(),
                    "rgba": m.geom_rgba[i].copy(),
                }
            )
        return out


def prepare_steps(sims: Sequence[Simulation]) -> None:
    """Compute the next control tick of every simulation in ``sims`` together.

    One batched pose/Jacobian call and one batched IK step for all of them (see
    :func:`~cpmp.sim.control.update_controllers`); each :meth:`Simulation.step` then applies its
    own, exactly what it would have computed alone. The wall time counts as ``kinematics``,
    shared equally. ``sims`` must share one task config (any boxes).
    """
    start = time.perf_counter()
    for sim in sims:
        if not sim.active:
            raise UnknownMPError("call set_active() before step()")
    update_controllers(
        [sim.controller for sim in sims],
        [{v: sim.library[v][name] for v, name in sim.active.items()} for sim in sims],
        np.stack([sim.box_pos() for sim in sims]),
    )
    for sim in sims:
        sim._control = sim._control_vector()
    share = (time.perf_counter() - start) / len(sims)
    for sim in sims:
        sim.timing["kinematics"] += share
