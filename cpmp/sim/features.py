"""The 33-D feature vector of the task (paper Sec. IV).

Layout (names from :func:`feature_names`):

* ``box_width, box_depth, box_height`` - box size, scaled to [0, 1] over the configured width
  and depth ranges and over [0, 0.2] m for the height;
* ``box_x, box_y, box_z`` - measured box centre, scaled over the workspace bounds
  :data:`WORKSPACE_LO`..:data:`WORKSPACE_HI`;
* ``left_ee_{x,y,z}, right_ee_{x,y,z}`` - measured end-effector site positions, same scaling;
* ``left_to_box_{x,y,z}, right_to_box_{x,y,z}`` - end-effector position relative to the box
  centre ``Δ``, squashed to (0, 1) as ``0.5 + 0.5 tanh(Δ / RELATIVE_SCALE)``: sensitive within a
  few centimetres of the box, saturated far from it (like eq. 6's goal distances).
  The paper's feature set has no such term; without it the last centimetres of an approach (the
  ones that decide a grasp) barely move any feature, so progress along a reach saturates before
  the hand arrives;
* ``left_palm_contact, right_palm_contact, box_supported`` - binary touch signals (1 = in
  contact): the palm touches the box; the box touches a support surface (plate, table,
  container). Realistic sensor information (a palm tactile/force switch; the object resting on
  a surface, as a wrist force sensor or vision would report) and not in the paper's feature set.
  They make the demonstrator's contact guards observable: a grasp starts when the palm touches
  the box, and releasing starts when the box rests on the container floor. Without them the
  states just before and after these events are a few millimetres apart in feature space, so
  the learned progress cannot tell "about to touch" from "touching" (premature grasps), nor the
  end of ``carry`` (box in the air above the container) from the start of ``release``;
* ``dist.<variable>.<mp>`` for every orientation and finger MP (except ``idle``): the
  goal-distance feature ``f = 1 - exp(-1/2 D^T S^-1 D)`` (eq. 6) with ``S = sigma^2 I``;
  ``D`` is the rotation angle [rad] to the MP's goal (``cfg.rot_sigma``) or the finger-angle
  difference vector (``cfg.finger_sigma``). ``f`` is 0 at the goal and tends to 1 far from it.
"""

from __future__ import annotations

import numpy as np

from cpmp.config.task import TaskConfig
from cpmp.sim.mps import IDLE, MP
from cpmp.sim.scene import HANDS, Box

WORKSPACE_LO = np.array([0.0, -0.5, 0.6])
"""Lower workspace bound [m] for position scaling (x, y, z)."""
WORKSPACE_HI = np.array([0.7, 0.5, 1.2])
"""Upper workspace bound [m] for position scaling (x, y, z)."""
_WORKSPACE_SPAN = WORKSPACE_HI - WORKSPACE_LO
HEIGHT_SCALE = 0.2
"""Box heights are divided by this [m]."""
RELATIVE_SCALE = 0.15
"""Length scale [m] of the squashed hand-to-box offsets."""


def feature_names(library: dict[str, dict[str, MP]]) -> list[str]:
    """Names of the features, in vector order."""
    names = ["box_width", "box_depth", "box_height", "box_x", "box_y", "box_z"]
    for hand in HANDS:
        names += [f"{hand}_ee_{axis}" for axis in "xyz"]
    for hand in HANDS:
        names += [f"{hand}_to_box_{axis}" for axis in "xyz"]
    names += [f"{hand}_palm_contact" for hand in HANDS] + ["box_supported"]
    for variable, mps in library.items():
        if variable.endswith(("_rot", "_fingers")):
            names += [f"dist.{variable}.{name}" for name in mps if name != IDLE]
    return names


def scale_position(pos: np.ndarray) -> np.ndarray:
    """Workspace position(s) [m], (..., 3) -> roughly [0, 1]."""
    return (pos - WORKSPACE_LO) / _WORKSPACE_SPAN


def box_size_features(box: Box, cfg: TaskConfig) -> np.ndarray:
    """Scaled (width, depth, height), shape (3,)."""
    (w_lo, w_hi), (d_lo, d_hi) = cfg.width_range, cfg.depth_range
    width = (box.width - w_lo) / max(w_hi - w_lo, 1e-6)
    depth = (box.depth - d_lo) / max(d_hi - d_lo, 1e-6)
    return np.array([width, depth, box.height / HEIGHT_SCALE])


def goal_distance(delta_sq: float, sigma: float) -> float:
    """Eq. (6) with ``S = sigma^2 I``: ``1 - exp(-delta_sq / (2 sigma^2))``."""
    return float(1.0 - np.exp(-0.5 * delta_sq / sigma**2))


class GoalDistances:
    """The ``dist.*`` features of one MP library, evaluated for all MPs in one vectorised pass.

    The goals of orientation MPs (world rotations) and finger MPs (joint angles) are fixed for
    an episode, so they are stacked once here, in :func:`feature_names` order.

    Args:
        library: ``library[variable][name]``, as from :func:`cpmp.sim.mps.build_library`.
        cfg: supplies ``rot_sigma`` and ``finger_sigma``.
    """

    def __init__(self, library: dict[str, dict[str, MP]], cfg: TaskConfig) -> None:
        rot_rows, rot_targets = [], []
        finger_targets: dict[str, list[np.ndarray]] = {h: [] for h in HANDS}
        row_by_hand: dict[str, list[int]] = {h: [] for h in HANDS}
        sigmas = []
        for variable, mps in library.items():
            hand = variable.split("_")[0]
            for mp in mps.values():
                if mp.name == IDLE:
                    continue
                row = len(sigmas)
                if variable.endswith("_rot"):
                    # trace(R_goal R^T) = <R_goal, R>: a row over both hands' flat rotations
                    block = np.zeros((len(HANDS), 9))
                    block[HANDS.index(hand)] = np.asarray(mp.target, dtype=np.float64).ravel()
                    rot_rows.append(row)
                    rot_targets.append(block.ravel())
                    sigmas.append(cfg.rot_sigma)
                elif variable.endswith("_fingers"):
                    finger_targets[hand].append(np.asarray(mp.target, dtype=np.float64))
                    row_by_hand[hand].append(row)
                    sigmas.append(cfg.finger_sigma)
        self._rot_rows = np.array(rot_rows, dtype=np.intp)
        # halved, so that cos(angle) = 0.5 (trace - 1) is one product and one subtraction
        self._half_rot_targets = 0.5 * np.array(rot_targets).reshape(len(rot_rows), -1)
        self._finger_rows = {h: np.array(r, dtype=np.intp) for h, r in row_by_hand.items() if r}
        self._finger_targets = {h: np.stack(finger_targets[h]) for h in self._finger_rows}
        # eq. (6) exponent -D^2 / (2 sigma^2) as D^2 / (-2 sigma^2)
        self._neg_two_sigma_sq = -2.0 * np.array(sigmas) ** 2

    def __call__(self, ee_rot: np.ndarray, fingers: dict[str, np.ndarray]) -> np.ndarray:
        """Goal distances (m,) in [0, 1): eq. (6) of every orientation and finger MP.

        ee_rot (2, 3, 3): end-effector rotation matrices, rows (left, right); fingers: per
        hand, joint angles (k,) [rad].
        """
        sq = np.empty(self._neg_two_sigma_sq.shape)
        cos = self._half_rot_targets @ ee_rot.reshape(-1) - 0.5
        sq[self._rot_rows] = np.arccos(np.minimum(np.maximum(cos, -1.0), 1.0)) ** 2
        for hand, rows in self._finger_rows.items():
            diff = fingers[hand] - self._finger_targets[hand]
            sq[rows] = np.vecdot(diff, diff)
        return 1.0 - np.exp(sq / self._neg_two_sigma_sq)


def compute_features(
    size_features: np.ndarray,
    box_pos: np.ndarray,
    ee_pos: np.ndarray,
    ee_rot: np.ndarray,
    fingers: dict[str, np.ndarray],
    contacts: np.ndarray,
    goals: GoalDistances,
) -> np.ndarray:
    """Feature vector (d,) from the measured state.

    size_features (3,); box_pos (3,) [m]; ee_pos (2, 3) [m] and ee_rot (2, 3, 3), rows
    (left, right); fingers: per hand, joint angles (k,) [rad]; contacts (3,): left palm-box,
    right palm-box, box-support contact (0 or 1); goals: the episode's goal-distance table.
    """
    relative = 0.5 + 0.5 * np.tanh((ee_pos - box_pos) / RELATIVE_SCALE)
    return np.concatenate(
        (
            size_features,
            scale_position(np.concatenate((box_pos[None], ee_pos))).ravel(),
            relative.ravel(),
            contacts,
            goals(ee_rot, fingers),
        )
    )
