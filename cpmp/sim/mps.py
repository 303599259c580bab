"""The movement primitives (MPs) of the pick-and-place task and their goals.

Every MP is a first-order linear attractor ``x' = K (g - x)`` on one control variable (paper
Sec. I-B). Six control variables: ``{left,right}_pos`` (end-effector site position [m]),
``{left,right}_rot`` (site orientation) and ``{left,right}_fingers`` (finger joint angles [rad]).

Goal frames of position MPs:

``world``
    a fixed world point (``home``).
``box``
    an offset from the box centre, re-read every tick (``reach_top``, ``reach_edge``).
``held``
    a world goal for the *held box*; the hand's goal is that point plus the hand-to-box offset
    latched when the hand starts holding (``lift``, ``carry``, ``lower``). These are world-frame
    goals of the object, carried by whichever hands hold it.
``right_ee``
    the left hand relative to the right end-effector, offset latched at activation, with the
    right hand's commanded velocity fed forward (``follow_right``, bimanual carrying).

Differences from the paper's 20 MPs: each variable has its own MP set, so the world-frame
motions exist once per hand, and single-hand (top centre) and bimanual (top edge) grasps are
separate reach MPs, giving 13 position MPs (12 world/box/held + 1 relative) instead of 7 + 1.
Orientation (``home``, ``down``) and finger MPs (4 per hand: ``relax``, ``preshape``,
``grasp``, ``release``) match the paper. Position and orientation have an extra ``idle`` MP per
hand for the hand a strategy leaves unused (see :data:`IDLE`). The ``grasp`` finger MP also
switches the palm's adhesion actuator on. The reach MPs use a smaller vertical gain
(``cfg.reach_descent_ratio``) so the palm is above its grasp point before it touches the box.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from cpmp.config.task import TaskConfig
from cpmp.sim.scene import CONTAINER_FLOOR_Z, FINGER_JOINTS, HANDS, PLATE_TOP_Z, Box

VARIABLES: tuple[str, ...] = (
    "left_pos",
    "left_rot",
    "left_fingers",
    "right_pos",
    "right_rot",
    "right_fingers",
)
POSITION_MPS: tuple[str, ...] = (
    "idle",
    "home",
    "reach_top",
    "reach_edge",
    "lift",
    "carry",
    "lower",
)
ROTATION_MPS: tuple[str, ...] = ("idle", "home", "down")
IDLE = "idle"
"""The MP of a hand the strategy does not use: hold the home pose for the whole episode. Same
attractor as ``home`` but a different MP: ``home`` *returns* a hand after the task. Keeping them
apart keeps the idle hand's start (box on the plate) and the final return (box in the
container) in different nodes, so an idle hand's progress is not confused with the end of the
task. Idle MPs add no goal-distance feature (it would duplicate ``home``'s)."""
FINGER_MPS: tuple[str, ...] = ("relax", "preshape", "grasp", "release")
HELD_MPS: frozenset[str] = frozenset({"lift", "carry", "lower", "follow_right"})

R_DOWN = np.diag([1.0, -1.0, -1.0])
"""Site orientation with the palm facing down and the fingers pointing forward (+x)."""


@dataclass(frozen=True)
class MP:
    """One movement primitive.

    ``target`` is, by ``kind``/``frame``: position offset or world point (3,) [m]; rotation
    matrix (3, 3) (world frame); or finger joint goal angles (k,) [rad]. ``axis_gain`` (3,)
    scales the attractor gain per world axis for position MPs (``K = k diag(axis_gain)``).
    """

    variable: str
    name: str
    kind: str
    frame: str
    target: np.ndarray
    axis_gain: np.ndarray = field(default_factory=lambda: np.ones(3))


def mp_names() -> dict[str, list[str]]:
    """MP names per control variable (short names, unique within a variable)."""
    names: dict[str, list[str]] = {}
    for hand in HANDS:
        pos = list(POSITION_MPS) + (["follow_right"] if hand == "left" else [])
        names[f"{hand}_pos"] = pos
        names[f"{hand}_rot"] = list(ROTATION_MPS)
        names[f"{hand}_fingers"] = list(FINGER_MPS)
    return {v: names[v] for v in VARIABLES}


def container_center() -> np.ndarray:
    """World position [m] of the container floor's top centre, shape (3,)."""
    return np.array([0.38, -0.20, CONTAINER_FLOOR_Z])


def plate_center() -> np.ndarray:
    """World position [m] of the plate's top centre, shape (3,)."""
    return np.array([0.38, 0.16, PLATE_TOP_Z])


def build_library(
    box: Box,
    cfg: TaskConfig,
    home_pos: dict[str, np.ndarray],
    home_rot: dict[str, np.ndarray],
) -> dict[str, dict[str, MP]]:
    """All MPs for an episode with ``box``: ``library[variable][name]``.

    home_pos / home_rot: per hand, the site position (3,) [m] and rotation (3, 3) of the home
    posture.
    """
    top = box.height / 2 - cfg.press_depth
    edge = box.width / 2 - cfg.edge_inset
    lifted = box.height / 2 + cfg.lift_height
    descend = np.array([1.0, 1.0, cfg.reach_descent_ratio])
    lib: dict[str, dict[str, MP]] = {}
    for hand in HANDS:
        side = 1.0 if hand == "left" else -1.0
        var = f"{hand}_pos"
        pos = {
            "idle": MP(var, "idle", "position", "world", home_pos[hand].copy()),
            "home": MP(var, "home", "position", "world", home_pos[hand].copy()),
            "reach_top": MP(
                var, "reach_top", "position", "box", np.array([0.0, 0.0, top]), descend
            ),
            "reach_edge": MP(
                var, "reach_edge", "position", "box", np.array([0.0, side * edge, top]), descend
            ),
            "lift": MP(
                var, "lift", "position", "held", plate_center() + np.array([0.0, 0.0, lifted])
            ),
            "carry": MP(
                var, "carry", "position", "held", container_center() + np.array([0.0, 0.0, lifted])
            ),
            "lower": MP(
                var,
                "lower",
                "position",
                "held",
                container_center() + np.array([0.0, 0.0, box.height / 2 - cfg.press_depth]),
            ),
        }
        if hand == "left":
            pos["follow_right"] = MP(var, "follow_right", "position", "right_ee", np.zeros(3))
        lib[var] = pos
        var = f"{hand}_rot"
        lib[var] = {
            "idle": MP(var, "idle", "orientation", "world", home_rot[hand].copy()),
            "home": MP(var, "home", "orientation", "world", home_rot[hand].copy()),
            "down": MP(var, "down", "orientation", "world", R_DOWN.copy()),
        }
        var = f"{hand}_fingers"
        n = len(FINGER_JOINTS[hand])
        lib[var] = {
            name: MP(var, name, "fingers", "joint", np.full(n, cfg.finger_goals[name]))
            for name in FINGER_MPS
        }
    return {v: lib[v] for v in VARIABLES}
