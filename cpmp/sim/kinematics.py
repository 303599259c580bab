"""Arm kinematics on pytorch-kinematics chains loaded from the scene MJCF.

One :class:`pytorch_kinematics.SerialChain` per arm runs from the arm's mount body to its
end-effector site (``left_ee`` / ``right_ee``). Both arms are built from the same link and joint
layout in world-aligned mount frames, so :meth:`ArmKinematics.fk_jacobian` evaluates both arms in
one batched call of the right chain and shifts each result by its mount position.
"""

from __future__ import annotations

import numpy as np
import pytorch_kinematics as pk
import torch
from pytorch_kinematics import mjcf as pk_mjcf

from cpmp.sim.scene import ARM_JOINTS, HANDS


def _patch_pk_joint_type_map() -> None:
    """Make pytorch_kinematics 0.10's MJCF loader work with mujoco >= 4.

    ``mjcf.JOINT_TYPE_MAP`` is keyed by ``mujoco.mjtJoint`` enums, but mujoco 4 reports joint
    types as ``np.int32``, so every lookup raises ``KeyError``. Re-keying by ``int`` fixes it;
    int keys also match the enums, so the patch is harmless on older mujoco.
    """
    table = pk_mjcf.JOINT_TYPE_MAP
    if not all(type(k) is int for k in table):
        pk_mjcf.JOINT_TYPE_MAP = {int(k): v for k, v in table.items()}


class ArmKinematics:
    """Forward kinematics and Jacobians of both arms, float64, world frame.

    Parameters
    ----------
    xml : str
        Scene MJCF text (the torso subtree is used; the free box is skipped).
    mount_pos : dict[str, np.ndarray]
        World position [m] of each arm's mount body, shape (3,). Mount frames are world-aligned.
    """

    def __init__(self, xml: str, mount_pos: dict[str, np.ndarray]) -> None:
        _patch_pk_joint_type_map()
        tree = pk.build_chain_from_mjcf(xml, body="torso")
        self.chains: dict[str, pk.SerialChain] = {
            hand: pk.SerialChain(tree, f"{hand}_ee", f"{hand}_mount").to(dtype=torch.float64)
            for hand in HANDS
        }
        for hand, chain in self.chains.items():
            names = chain.get_joint_parameter_names()
            expected = [f"{hand}_{j}" for j in ARM_JOINTS]
            if names != expected:
                raise RuntimeError(f"{hand} arm chain has joints {names}, expected {expected}")
        self.mount_pos = np.stack([np.asarray(mount_pos[h], dtype=np.float64) for h in HANDS])
        self._check_arms_identical()

    def _check_arms_identical(self) -> None:
        """Both arms must share one kinematic layout for the batched call to be valid."""
        q = torch.linspace(-1.0, 1.0, 7, dtype=torch.float64)[None]
        left = self.chains["left"].forward_kinematics(q).get_matrix()
        right = self.chains["right"].forward_kinematics(q).get_matrix()
        if not torch.allclose(left, right, atol=1e-12):
            raise RuntimeError(
                "left and right arm chains differ; the batched IK assumes equal arms"
            )

    def fk(self, hand: str, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """End-effector site pose of one arm.

        q: (B, 7) or (7,) joint angles [rad]. Returns position (B, 3) [m] and rotation matrix
        (B, 3, 3), world frame, from that arm's own chain.
        """
        th = torch.as_tensor(np.atleast_2d(q), dtype=torch.float64)
        mat = self.chains[hand].forward_kinematics(th).get_matrix().numpy()
        pos = mat[:, :3, 3] + self.mount_pos[HANDS.index(hand)]
        return pos, mat[:, :3, :3]

    def fk_jacobian(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Poses and Jacobians of both arms in one batched call.

        q: (2, 7) joint angles [rad], rows in :data:`HANDS` order (left, right).
        Returns ``pos`` (2, 3) [m], ``rot`` (2, 3, 3) and ``jac`` (2, 6, 7) with rows
        (linear [m/rad]; angular [rad/rad]) in the world frame (mount frames are world-aligned).
        """
        th = torch.from_numpy(np.ascontiguousarray(q, dtype=np.float64))
        with torch.inference_mode():
            jac, pose = self.chains["right"].jacobian_tensor(th, ret_eef_pose=True)
        mat = pose.numpy()
        return mat[:, :3, 3] + self.mount_pos, mat[:, :3, :3], jac.numpy()
