"""MP execution: task-space attractors -> damped-least-squares resolved-rate IK -> joint targets.

Per control tick (:meth:`MPController.update`, or :func:`update_controllers` for the
controllers of many simulations at once):

1. pose and Jacobian of both arms' *reference* configuration (one batched pytorch-kinematics
   call for every arm of every controller);
2. each active MP's goal in the world (box-relative goals read the measured box position);
3. attractor velocities ``v = K (g - x)``, speed-limited, and for orientation
   ``w = K log(R_g R^T)``;
4. DLS: ``dq = J^T (J J^T + l^2 I)^-1 [v; w] + N (k_p (q_home - q) + limit push)``, with
   ``N = I - J^+ J`` the null-space projector; joint speeds limited, then integrated and clipped
   to the joint ranges;
5. fingers follow their joint-space attractor exactly (exponential step).

A variable's pace (:attr:`MPController.speed`, set by a paced run: see
:mod:`cpmp.worlds.pacing`) multiplies its commanded velocity after the speed limit (positions,
orientations) or its attractor gain (fingers): the same path at that factor of the speed, and
standing still at 0.

The reference configuration is what the position actuators track; using it (not the measured
joints) for the IK keeps the loop free of wind-up when a palm presses on the box.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import mujoco
import numpy as np

from cpmp.config.task import TaskConfig
from cpmp.errors import ConfigError
from cpmp.sim.kinematics import ArmKinematics
from cpmp.sim.mps import HELD_MPS, MP
from cpmp.sim.scene import HANDS


def rotation_error(goal: np.ndarray, rot: np.ndarray) -> np.ndarray:
    """Rotation vector [rad] taking ``rot`` (3, 3) to ``goal`` (3, 3), world frame, shape (3,).

    Goes through the quaternion of ``goal rot^T``; :func:`mujoco.mju_quat2Vel` maps an angle
    above pi to its complement, so this equals the rotation vector of the standardised
    quaternion (w >= 0) and its angle is in [0, pi].
    """
    quat = np.empty(4)
    mujoco.mju_mat2Quat(quat, (goal @ rot.T).ravel())
    out = np.empty(3)
    mujoco.mju_quat2Vel(out, quat, 1.0)
    return out


def rotation_angle(goal: np.ndarray, rot: np.ndarray) -> np.ndarray:
    """Angle [rad] between two rotations, (..., 3, 3) -> (...), in [0, pi]."""
    err = goal @ np.swapaxes(rot, -1, -2)
    cos = 0.5 * (np.trace(err, axis1=-2, axis2=-1) - 1.0)
    return np.arccos(np.clip(cos, -1.0, 1.0))


LEFT, RIGHT = HANDS.index("left"), HANDS.index("right")
"""Rows of the two arms in the (2, ...) arrays."""

NULLSPACE_REGULARISER = 1e-6
"""Tiny damping [m^2] of the pseudo-inverse used for the null-space projector: the DLS-damped
inverse would leak the posture term into the task space and leave a steady-state error."""


class MPController:
    """Turns the active MPs of the six control variables into joint position targets.

    Args:
        cfg: the task's gains, limits and control period.
        kin: the arms' kinematics.
        limits: (2, 7, 2) arm joint ranges [rad], rows (left, right).
        q_home: (2, 7) home arm posture [rad] (also the null-space posture).
    """

    def __init__(
        self, cfg: TaskConfig, kin: ArmKinematics, limits: np.ndarray, q_home: np.ndarray
    ) -> None:
        self.cfg = cfg
        self.kin = kin
        self.lo = limits[..., 0]
        self.hi = limits[..., 1]
        self.q_home = q_home.copy()
        self.q_ref = q_home.copy()
        self.fingers_ref: dict[str, np.ndarray] = {}
        self._latched: dict[str, np.ndarray] = {}
        self._previous: dict[str, str] = {}
        self.speed: dict[str, float] = {}
        """Per control variable the pace of its MP (factor on its commanded velocity; 0: it
        holds); a variable not named runs at 1 (:meth:`Simulation.set_speeds`)."""
        self.ref_pos = np.zeros((2, 3))
        self.ref_rot = np.zeros((2, 3, 3))
        # per-tick constants: finger decay factor, joint-limit band edges [rad] and push gain
        # [1/s per rad], gram regularisers (4, 6, 6) (DLS damping for both arms, then the
        # null-space regulariser for both arms)
        self._finger_decay = float(np.exp(-cfg.finger_gain * cfg.control_dt))
        self._band_lo = self.lo + cfg.limit_margin
        self._band_hi = self.hi - cfg.limit_margin
        self._push_gain = cfg.limit_gain / cfg.limit_margin
        eye6 = np.eye(6)
        self._gram_diag = np.stack(
            [cfg.ik_damping**2 * eye6] * 2 + [NULLSPACE_REGULARISER * eye6] * 2
        )

    def reset(self, q: np.ndarray, fingers: dict[str, np.ndarray]) -> None:
        """Start from arm posture ``q`` (2, 7) and finger angles per hand."""
        self.q_ref = q.copy()
        self.fingers_ref = {h: f.copy() for h, f in fingers.items()}
        self._latched.clear()
        self._previous.clear()
        self.speed = {}

    def update(self, active: Mapping[str, MP], box_pos: np.ndarray) -> None:
        """Advance the references one control tick for the ``active`` MPs.

        box_pos: measured box centre (3,) [m].
        """
        update_controllers([self], [active], np.asarray(box_pos)[None])

    def _twist(
        self, active: Mapping[str, MP], pos: np.ndarray, rot: np.ndarray, box_pos: np.ndarray
    ) -> np.ndarray:
        """Commanded twists (2, 6) [m/s; rad/s] of both hands, rows (left, right).

        From the reference poses ``pos`` (2, 3) [m] and ``rot`` (2, 3, 3) and the box centre
        (3,) [m].
        """
        self.ref_pos, self.ref_rot = pos, rot
        twist = np.empty((2, 6))
        right = self._velocity(active["right_pos"], RIGHT, pos, box_pos, None)
        twist[RIGHT, :3] = right
        twist[LEFT, :3] = self._velocity(active["left_pos"], LEFT, pos, box_pos, right)
        twist[LEFT, 3:] = rotation_error(active["left_rot"].target, rot[LEFT])
        twist[RIGHT, 3:] = rotation_error(active["right_rot"].target, rot[RIGHT])
        twist[:, 3:] *= self.cfg.rot_gain
        if self.speed:
            for row, hand in ((LEFT, "left"), (RIGHT, "right")):
                twist[row, 3:] *= self.speed.get(f"{hand}_rot", 1.0)
        return twist

    def _follow_fingers(self, active: Mapping[str, MP]) -> None:
        """Fingers' exponential step towards the active finger MPs' goals; remember the MPs."""
        for hand in HANDS:
            goal = active[f"{hand}_fingers"].target
            decay = self._finger_decay
            pace = self.speed.get(f"{hand}_fingers", 1.0)
            if pace != 1.0:
                decay = math.exp(-pace * self.cfg.finger_gain * self.cfg.control_dt)
            self.fingers_ref[hand] = goal + (self.fingers_ref[hand] - goal) * decay
        self._previous = {v: mp.name for v, mp in active.items()}

    def _velocity(
        self,
        mp: MP,
        i: int,
        pos: np.ndarray,
        box_pos: np.ndarray,
        right_velocity: np.ndarray | None,
    ) -> np.ndarray:
        """Commanded linear velocity [m/s] (3,) of hand row ``i`` under position MP ``mp``.

        pos: (2, 3) reference end-effector positions [m]; box_pos (3,) [m];
        right_velocity: the right hand's commanded velocity (3,), fed forward by ``right_ee``
        MPs.
        """
        cfg = self.cfg
        self._latch(mp, pos, box_pos)
        frame = mp.frame
        if frame == "world":
            goal = mp.target
        elif frame == "box":
            goal = box_pos + mp.target
        elif frame == "held":
            goal = mp.target + self._latched[mp.variable]
        else:
            goal = pos[RIGHT] + self._latched[mp.variable]
        v = cfg.pos_gain * mp.axis_gain * (goal - pos[i])
        speed = math.sqrt(v.dot(v))
        if speed > cfg.max_speed:
            v *= cfg.max_speed / speed
        pace = self.speed.get(mp.variable, 1.0)
        if pace != 1.0:
            v *= pace
        if frame == "right_ee":
            v += right_velocity
        return v

    def _latch(self, mp: MP, pos: np.ndarray, box_pos: np.ndarray) -> None:
        """Latch the hand offset of a held/relative MP when it starts (pos: (2, 3) [m])."""
        previous = self._previous.get(mp.variable)
        if mp.frame == "held" and (previous not in HELD_MPS or mp.variable not in self._latched):
            self._latched[mp.variable] = pos[HANDS.index(mp.variable.split("_")[0])] - box_pos
        elif mp.frame == "right_ee" and (previous != mp.name or mp.variable not in self._latched):
            self._latched[mp.variable] = pos[LEFT] - pos[RIGHT]

    def _resolve(self, q: np.ndarray, jac: np.ndarray, twist: np.ndarray) -> np.ndarray:
        """One DLS resolved-rate step of both arms of N robots sharing this controller's gains.

        The robots share its limits too: q (N, 2, 7) [rad], jac (N, 2, 6, 7), twist (N, 2, 6)
        -> q (N, 2, 7).

        ``J^T (J J^T + l^2 I)^-1 v + (I - J^T (J J^T + e I)^-1 J) s`` is evaluated as
        ``s + J^T (a - b)``: ``a`` and ``b`` solve each robot's damped and null-space grams
        (4, 6, 6, symmetric positive definite through their regularisers) against ``v`` and
        ``J s`` with MuJoCo's dense Cholesky, cheaper per call than ``np.linalg.solve`` at this
        size. Every matrix is solved on its own, so a robot's step does not depend on N.
        """
        cfg = self.cfg
        jt = np.swapaxes(jac, -1, -2)
        gram = jac @ jt
        push = np.maximum(self._band_lo - q, 0.0) + np.minimum(self._band_hi - q, 0.0)
        secondary = cfg.posture_gain * (self.q_home - q) + self._push_gain * push
        rhs = np.concatenate((twist, (jac @ secondary[..., None])[..., 0]), axis=-2)
        grams = np.concatenate((gram, gram), axis=-3) + self._gram_diag
        sol = np.empty(rhs.shape)
        for g, x, b in zip(
            grams.reshape(-1, 6, 6), sol.reshape(-1, 6), rhs.reshape(-1, 6), strict=True
        ):
            mujoco.mju_cholFactor(g, 0.0)
            mujoco.mju_cholSolve(x, g, b)
        dq = (jt @ (sol[:, :2] - sol[:, 2:])[..., None])[..., 0] + secondary
        peak = np.abs(dq).max(axis=-1, keepdims=True)
        dq *= cfg.max_joint_speed / np.maximum(peak, cfg.max_joint_speed)
        return np.minimum(np.maximum(q + dq * cfg.control_dt, self.lo), self.hi)


def update_controllers(
    controllers: Sequence[MPController],
    active: Sequence[Mapping[str, MP]],
    box_pos: np.ndarray,
) -> None:
    """Advance N controllers one control tick together, each exactly as it would alone.

    Each as its own :meth:`MPController.update` would: one batched pose/Jacobian call and one
    batched DLS step for all arms.

    controllers: of N simulations of one robot and task config; active: per controller, the
    active MP per variable; box_pos: (N, 3) measured box centres [m].
    """
    first = controllers[0]
    for c in controllers[1:]:
        if c.kin is not first.kin or (c.cfg is not first.cfg and c.cfg != first.cfg):
            raise ConfigError("controllers updated together must share kinematics and config")
    q = np.stack([c.q_ref for c in controllers])
    pos, rot, jac = first.kin.fk_jacobian(q)
    rows = zip(controllers, active, pos, rot, box_pos, strict=True)
    twist = np.stack([c._twist(a, p, r, b) for c, a, p, r, b in rows])
    q_new = first._resolve(q, jac, twist)
    for c, a, q_ref in zip(controllers, active, q_new, strict=True):
        c.q_ref = q_ref
        c._follow_fingers(a)
