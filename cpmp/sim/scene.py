"""Scene building: the box of an episode, the strategy regions and the MuJoCo model.

The robot, table, plate and container are authored in ``assets/scene.xml``; :func:`build_spec`
loads it as an ``MjSpec`` and writes the episode's box size and resting pose (centred on the
plate) before compiling. Units: metres, kilograms.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from importlib import resources

import mujoco
import numpy as np

from cpmp.config.task import TaskConfig
from cpmp.errors import ConfigError

STRATEGIES: tuple[str, ...] = ("both", "right", "left")
"""Grasp strategies: both hands, the right hand alone, the left hand alone."""

HANDS: tuple[str, ...] = ("left", "right")
ARM_JOINTS: tuple[str, ...] = (
    "shoulder_pitch",
    "shoulder_roll",
    "upper_arm_yaw",
    "elbow",
    "wrist_yaw",
    "wrist_pitch",
    "wrist_roll",
)
FINGER_JOINTS: dict[str, tuple[str, ...]] = {
    "left": ("finger_a1", "finger_a2", "finger_b1", "finger_b2"),
    "right": ("thumb1", "thumb2", "index1", "index2", "middle1", "middle2", "ring1"),
}

HOME_POSTURE_RIGHT: tuple[float, ...] = (-0.283, 0.18, -0.715, -2.216, -0.567, 1.11, 0.137)
"""Right-arm joint angles [rad] of the home pose, in :data:`ARM_JOINTS` order."""

PLATE_TOP_Z = 0.71
"""Height [m] of the plate's top surface (the box rests on it)."""
CONTAINER_FLOOR_Z = 0.71
"""Height [m] of the container floor's top surface."""
RESTING_PENETRATION = 1e-4
"""Depth [m] the box sinks into the plate at rest (MuJoCo's soft contact). The box starts at
this depth, already in contact, so the ``box_supported`` feature is 1 from the first sample
instead of switching on at the first tick."""


def home_posture(hand: str) -> np.ndarray:
    """Home arm angles [rad], shape (7,). The left arm mirrors the right across the xz-plane."""
    q = np.asarray(HOME_POSTURE_RIGHT, dtype=np.float64)
    if hand == "right":
        return q.copy()
    mirror = np.array([1.0, -1.0, -1.0, 1.0, -1.0, 1.0, -1.0])
    return q * mirror


@dataclass(frozen=True)
class Box:
    """A box of the pick-and-place task: ``width`` (world y), ``depth`` (x), ``height`` (z) [m]."""

    width: float
    depth: float
    height: float

    def __post_init__(self) -> None:
        for name in ("width", "depth", "height"):
            value = getattr(self, name)
            if not isinstance(value, int | float) or not math.isfinite(value) or value <= 0:
                raise ConfigError(f"Box.{name} must be a positive length in metres, got {value!r}")
            object.__setattr__(self, name, float(value))

    @property
    def size(self) -> np.ndarray:
        """Full extents ``(width, depth, height)`` [m], shape (3,)."""
        return np.array([self.width, self.depth, self.height])


def sample_box(rng: np.random.Generator, cfg: TaskConfig) -> Box:
    """Draw width and depth uniformly from the configured ranges; height is ``cfg.box_height``."""
    width = float(rng.uniform(*cfg.width_range))
    depth = float(rng.uniform(*cfg.depth_range))
    return Box(width, depth, cfg.box_height)


def correct_strategy(box: Box, cfg: TaskConfig) -> str:
    """Strategy the demonstrator uses for ``box``: ``"both"``, ``"right"`` or ``"left"``.

    Three contiguous regions of the width x depth plane: wide boxes (``width >
    cfg.both_min_width``) are lifted with both hands; narrower boxes with the left hand if they
    are deep (``depth > cfg.left_min_depth``) and with the right hand otherwise.
    """
    if box.width > cfg.both_min_width:
        return "both"
    if box.depth > cfg.left_min_depth:
        return "left"
    return "right"


def scene_xml_text() -> str:
    """The MJCF text of ``assets/scene.xml`` (placeholder box)."""
    return resources.files("cpmp.sim").joinpath("assets/scene.xml").read_text(encoding="utf-8")


def build_spec(box: Box, cfg: TaskConfig) -> mujoco.MjSpec:
    """Scene spec with the box of size ``box`` resting centred on the plate."""
    spec = mujoco.MjSpec.from_string(scene_xml_text())
    geom = spec.geom("box")
    geom.size = [box.depth / 2, box.width / 2, box.height / 2]
    geom.mass = cfg.box_mass
    body = spec.body("box")
    plate = spec.body("plate")
    body.pos = [plate.pos[0], plate.pos[1], PLATE_TOP_Z + box.height / 2 - RESTING_PENETRATION]
    return spec


def build_model(box: Box, cfg: TaskConfig) -> mujoco.MjModel:
    """Compiled MuJoCo model of the scene with ``box``."""
    return build_spec(box, cfg).compile()
