"""Arm kinematics on pytorch-kinematics chains loaded from the scene MJCF.

One :class:`pytorch_kinematics.SerialChain` per arm runs from the arm's mount body to its
end-effector site (``left_ee`` / ``right_ee``). Both arms are built from the same link and joint
layout in world-aligned mount frames, so :meth:`ArmKinematics.fk_jacobian` evaluates both arms
(of one robot, or of N robots in N simulations) in one batched call of the right chain and shifts
each result by its mount position. Every row of that call is computed on its own: a row's result
does not depend on the batch it is in, to the last bit (tested), so batched rollouts reproduce
one-at-a-time rollouts exactly.

That call runs every control tick. pytorch-kinematics' ``jacobian_tensor`` is written to be
``torch.compile``-able (fullgraph); compiled (inductor with its C++ wrapper), the eager call's
many small tensor operations run as one compiled call. It is compiled once for every batch size
(a dynamic batch dimension). Compiling needs a C++ compiler; without one, or with
``compile=False``, the eager call is used. Timings: see docs/benchmarks.md.
"""

from __future__ import annotations

import logging
import time
import warnings
from collections.abc import Callable

import numpy as np
import pytorch_kinematics as pk
import torch
from pytorch_kinematics import mjcf as pk_mjcf

from cpmp.errors import DataError
from cpmp.sim.scene import ARM_JOINTS, HANDS

log = logging.getLogger(__name__)

COMPILE_SECONDS = (20, 4)
"""What compiling the Jacobian takes [s] on a 2-core machine: the first time, and from torch's
compile cache afterwards (measured: 20.9 and 3.4 s); the log line says so, since the job
prints nothing else meanwhile."""


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

    Args:
        xml: scene MJCF text (the torso subtree is used; the free box is skipped).
        mount_pos: world position [m] of each arm's mount body, shape (3,). Mount frames are
            world-aligned.
        compile: ``torch.compile`` the batched Jacobian (checked against the eager call on
            construction; falls back to eager with a warning if compilation fails).
            :attr:`compiled` says which one runs.
    """

    def __init__(self, xml: str, mount_pos: dict[str, np.ndarray], compile: bool = False) -> None:
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
        self.compiled = False
        self._jacobian = self._make_jacobian(compile)

    def _check_arms_identical(self) -> None:
        """Both arms must share one kinematic layout for the batched call to be valid."""
        q = torch.linspace(-1.0, 1.0, 7, dtype=torch.float64)[None]
        left = self.chains["left"].forward_kinematics(q).get_matrix()
        right = self.chains["right"].forward_kinematics(q).get_matrix()
        if not torch.allclose(left, right, atol=1e-12):
            raise RuntimeError(
                "left and right arm chains differ; the batched IK assumes equal arms"
            )

    def _make_jacobian(
        self, compile: bool
    ) -> Callable[[torch.Tensor], tuple[torch.Tensor, torch.Tensor]]:
        """The batched pose-and-Jacobian function ``(B, 7) -> ((B, 6, 7), (B, 4, 4))``."""
        chain = self.chains["right"]

        def eager(th: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
            return chain.jacobian_tensor(th, ret_eef_pose=True)

        if not compile:
            return eager
        # made like fk_jacobian's input (from numpy, not a view of another tensor): a probe
        # that is a view compiles guards on its base and every real call recompiles
        probe = torch.from_numpy(np.linspace(-1.5, 1.5, 14).reshape(2, 7))
        first, cached = COMPILE_SECONDS
        log.info(
            "compiling the arm kinematics with torch.compile (first run only: about %d s; "
            "about %d s from the compile cache)",
            first,
            cached,
        )
        start = time.perf_counter()
        try:
            compiled = torch.compile(
                eager, fullgraph=True, dynamic=True, options={"cpp_wrapper": True}
            )
            with torch.no_grad():
                got, want = compiled(probe), eager(probe)
            pairs = zip(got, want, strict=True)
            if not all(torch.allclose(g, w, rtol=0, atol=1e-12) for g, w in pairs):
                raise RuntimeError("compiled Jacobian differs from the eager one")
        except Exception as err:  # no C++ compiler, unsupported platform, ...
            warnings.warn(
                f"torch.compile of the arm Jacobian failed ({type(err).__name__}: {err}); "
                "using the eager pytorch-kinematics call (about 2x slower per tick)",
                RuntimeWarning,
                stacklevel=3,
            )
            return eager
        self.compiled = True
        log.info("compiled the arm kinematics in %.1f s", time.perf_counter() - start)
        return compiled

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
        """Poses and Jacobians of both arms of one or many robots in one batched call.

        q: (..., 2, 7) joint angles [rad], the arms in :data:`HANDS` order (left, right).
        Returns ``pos`` (..., 2, 3) [m], ``rot`` (..., 2, 3, 3) and ``jac`` (..., 2, 6, 7) with
        rows (linear [m/rad]; angular [rad/rad]) in the world frame (mount frames are
        world-aligned). Each robot's result is the same, bit for bit, as from a call of its own.
        """
        q = np.ascontiguousarray(q, dtype=np.float64)
        if q.shape[-2:] != (2, 7):
            raise DataError(f"q must have shape (..., 2, 7), got {q.shape}")
        lead = q.shape[:-2]
        th = torch.from_numpy(q.reshape(-1, 7))
        with torch.no_grad():
            jac, pose = self._jacobian(th)
        mat = pose.numpy().reshape(*lead, 2, 4, 4)
        pos = mat[..., :3, 3] + self.mount_pos
        return pos, mat[..., :3, :3], jac.numpy().reshape(*lead, 2, 6, 7)
