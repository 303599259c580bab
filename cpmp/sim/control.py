"""MP execution: task-space attractors -> damped-least-squares resolved-rate IK -> joint targets.

Per control tick (:meth:`MPController.update`):

1. pose and Jacobian of both arms' *reference* configuration (one batched pytorch-kinematics
   call);
2. each active MP's goal in the world (box-relative goals read the measured box position);
3. attractor velocities ``v = K (g - x)``, speed-limited, and for orientation
   ``w = K log(R_g R^T)``;
4. DLS: ``dq = J^T (J J^T + l^2 I)^-1 [v; w] + N (k_p (q_home - q) + limit push)``, with
   ``N = I - J^+ J`` the null-space projector; joint speeds limited, then integrated and clipped
   to the joint ranges;
5. fingers follow their joint-space attractor exactly (exponential step).

The reference configuration is what the position actuators track; using it (not the measured
joints) for the IK keeps the loop free of wind-up when a palm presses on the box.
"""

from __future__ import annotations

import mujoco
import numpy as np

from cpmp.sim.config import TaskConfig
from cpmp.sim.kinematics import ArmKinematics
from cpmp.sim.mps import HELD_MPS, MP
from cpmp.sim.scene import HANDS


def rotation_error(goal: np.ndarray, rot: np.ndarray) -> np.ndarray:
    """Rotation vector [rad] taking ``rot`` (3, 3) to ``goal`` (3, 3), world frame, shape (3,).

    Goes through a standardised quaternion (w >= 0), so the angle is in [0, pi].
    """
    quat = np.empty(4)
    mujoco.mju_mat2Quat(quat, (goal @ rot.T).ravel())
    if quat[0] < 0:
        quat = -quat
    sin_half = float(np.linalg.norm(quat[1:]))
    if sin_half < 1e-12:
        return np.zeros(3)
    return quat[1:] * (2.0 * np.arctan2(sin_half, quat[0]) / sin_half)


def rotation_angle(goal: np.ndarray, rot: np.ndarray) -> np.ndarray:
    """Angle [rad] between two rotations, (..., 3, 3) -> (...), in [0, pi]."""
    err = goal @ np.swapaxes(rot, -1, -2)
    cos = 0.5 * (np.trace(err, axis1=-2, axis2=-1) - 1.0)
    return np.arccos(np.clip(cos, -1.0, 1.0))


NULLSPACE_REGULARISER = 1e-6
"""Tiny damping [m^2] of the pseudo-inverse used for the null-space projector: the DLS-damped
inverse would leak the posture term into the task space and leave a steady-state error."""


class MPController:
    """Turns the active MPs of the six control variables into joint position targets.

    Parameters
    ----------
    cfg : TaskConfig
    kin : ArmKinematics
    limits : (2, 7, 2) arm joint ranges [rad], rows (left, right).
    q_home : (2, 7) home arm posture [rad] (also the null-space posture).
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
        self.ref_pos = np.zeros((2, 3))
        self.ref_rot = np.zeros((2, 3, 3))

    def reset(self, q: np.ndarray, fingers: dict[str, np.ndarray]) -> None:
        """Start from arm posture ``q`` (2, 7) and finger angles per hand."""
        self.q_ref = q.copy()
        self.fingers_ref = {h: f.copy() for h, f in fingers.items()}
        self._latched.clear()
        self._previous.clear()

    def update(self, active: dict[str, MP], box_pos: np.ndarray) -> None:
        """Advance the references one control tick for the ``active`` MPs.

        box_pos: measured box centre (3,) [m].
        """
        cfg = self.cfg
        dt = cfg.control_dt
        pos, rot, jac = self.kin.fk_jacobian(self.q_ref)
        self.ref_pos, self.ref_rot = pos, rot
        twist = np.zeros((2, 6))
        velocity: dict[str, np.ndarray] = {}
        for hand in ("right", "left"):
            i = HANDS.index(hand)
            mp = active[f"{hand}_pos"]
            self._latch(mp, pos, box_pos)
            feedforward = np.zeros(3)
            if mp.frame == "world":
                goal = mp.target
            elif mp.frame == "box":
                goal = box_pos + mp.target
            elif mp.frame == "held":
                goal = mp.target + self._latched[mp.variable]
            else:
                goal = pos[HANDS.index("right")] + self._latched[mp.variable]
                feedforward = velocity["right"]
            v = cfg.pos_gain * mp.axis_gain * (goal - pos[i])
            speed = np.linalg.norm(v)
            if speed > cfg.max_speed:
                v *= cfg.max_speed / speed
            velocity[hand] = v + feedforward
            twist[i, :3] = velocity[hand]
            twist[i, 3:] = cfg.rot_gain * rotation_error(active[f"{hand}_rot"].target, rot[i])
        self.q_ref = self._resolve(jac, twist, dt)
        for hand in HANDS:
            goal = active[f"{hand}_fingers"].target
            decay = np.exp(-cfg.finger_gain * dt)
            self.fingers_ref[hand] = goal + (self.fingers_ref[hand] - goal) * decay
        self._previous = {v: mp.name for v, mp in active.items()}

    def _latch(self, mp: MP, pos: np.ndarray, box_pos: np.ndarray) -> None:
        """Latch the hand offset of a held/relative MP when it starts (pos: (2, 3) [m])."""
        previous = self._previous.get(mp.variable)
        if mp.frame == "held" and (previous not in HELD_MPS or mp.variable not in self._latched):
            self._latched[mp.variable] = pos[HANDS.index(mp.variable.split("_")[0])] - box_pos
        elif mp.frame == "right_ee" and (previous != mp.name or mp.variable not in self._latched):
            self._latched[mp.variable] = pos[HANDS.index("left")] - pos[HANDS.index("right")]

    def _resolve(self, jac: np.ndarray, twist: np.ndarray, dt: float) -> np.ndarray:
        """One DLS resolved-rate step of both arms. jac (2, 6, 7), twist (2, 6) -> q (2, 7)."""
        cfg = self.cfg
        q = self.q_ref
        jt = np.swapaxes(jac, 1, 2)
        gram = jac @ jt + (cfg.ik_damping**2) * np.eye(6)
        pinv = jt @ np.linalg.inv(gram)
        dq = np.einsum("bij,bj->bi", pinv, twist)
        margin = cfg.limit_margin
        push = np.clip((self.lo + margin - q) / margin, 0.0, None) - np.clip(
            (q - (self.hi - margin)) / margin, 0.0, None
        )
        secondary = cfg.posture_gain * (self.q_home - q) + cfg.limit_gain * push
        exact = jt @ np.linalg.inv(jac @ jt + NULLSPACE_REGULARISER * np.eye(6))
        null = np.eye(7) - exact @ jac
        dq += np.einsum("bij,bj->bi", null, secondary)
        peak = np.max(np.abs(dq), axis=1, keepdims=True)
        dq *= np.minimum(1.0, cfg.max_joint_speed / np.maximum(peak, 1e-12))
        return np.clip(q + dq * dt, self.lo, self.hi)
