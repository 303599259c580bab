"""The options of the simulated pick-and-place task (paper Sec. IV; ``conf/task/``).

:class:`TaskConfig` belongs to :mod:`cpmp.sim` (which re-exports it); it lives here, apart
from the simulator, so that a command line is checked without importing MuJoCo. Every tunable
number of the simulation, the MP controllers, the features and the scripted demonstrator is a
field; nothing is baked into code. Units: metres, seconds, radians, kilograms.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from cpmp.errors import ConfigError


@dataclass(frozen=True)
class TaskConfig:
    """Box ranges, strategy regions, control rates, MP gains and demonstrator thresholds.

    Strategy regions in the width x depth plane (see :func:`cpmp.sim.correct_strategy`):
    ``width > both_min_width`` -> "both"; otherwise ``depth > left_min_depth`` -> "left";
    otherwise "right". Width is the box extent along world y (across the robot), depth along x.

    Attributes:
        width_range: [min, max] box extent across the robot (world y) [m].
        depth_range: [min, max] box extent away from the robot (world x) [m].
        box_height: box height [m].
        box_mass: box mass [kg].
        both_min_width: boxes wider than this are carried with both hands [m].
        left_min_depth: otherwise, boxes deeper than this are carried with the left hand, the
            others with the right hand [m].
        control_dt: control period [s] (0.01: 100 Hz).
        physics_dt: MuJoCo time step [s]; ``control_dt`` is a whole multiple of it.
        max_time: episode limit [s].
        seed: the task's seed (box sampling of ``collect``).
        compile_kinematics: run the IK's pytorch-kinematics Jacobian through ``torch.compile``
            (see :mod:`cpmp.sim.kinematics`; the same Jacobian to 1e-12; timings: see
            docs/benchmarks.md).
        pos_gain: position MP attractor gain [1/s].
        rot_gain: orientation MP attractor gain [1/s].
        finger_gain: finger MP attractor gain [1/s].
        max_speed: end-effector speed limit [m/s].
        max_joint_speed: joint speed limit [rad/s].
        ik_damping: damped-least-squares damping λ of the IK.
        posture_gain: null-space pull to the home posture [1/s].
        limit_margin: joint-limit avoidance starts this far from a limit [rad].
        limit_gain: joint-limit avoidance speed at the limit [rad/s].
        press_depth: palm goal below the box top [m].
        reach_descent_ratio: vertical / lateral gain of the reach MPs.
        edge_inset: bimanual grasp points inset from the box's side faces [m].
        lift_height: box lift above the plate / container floor [m].
        rot_sigma: σ of the orientation goal-distance features ``f = 1 - exp(-0.5 d² / σ²)``
            [rad].
        finger_sigma: σ of the finger goal-distance features [rad].
        pos_tol: a position MP counts as reached within this distance [m].
        rot_tol: an orientation MP counts as reached within this angle [rad].
        finger_tol: a finger MP counts as reached below this goal-distance feature.
        preshape_distance: the demonstrator starts preshaping this close to the grasp goal [m].
        rise_distance: it rotates home after rising this far from the release point [m].
        relax_distance: it relaxes the fingers this close to home [m].
        settle_time: a demonstrator switch fires once its guard has held this long [s].
        home_tol: hands count as home within this distance [m].
        deadlock_time: no transition for this long while standing still is a deadlock [s].
        finger_goals: finger joint goal of each finger MP (``relax``, ``preshape``, ``grasp``,
            ``release``) [rad].
    """

    width_range: tuple[float, float] = (0.10, 0.30)
    depth_range: tuple[float, float] = (0.10, 0.22)
    box_height: float = 0.10
    box_mass: float = 0.4
    both_min_width: float = 0.20
    left_min_depth: float = 0.16

    control_dt: float = 0.01
    physics_dt: float = 0.002
    max_time: float = 20.0
    seed: int = 0
    compile_kinematics: bool = True

    pos_gain: float = 3.0
    rot_gain: float = 5.0
    finger_gain: float = 8.0
    max_speed: float = 0.5
    max_joint_speed: float = 3.0
    ik_damping: float = 0.05
    posture_gain: float = 1.0
    limit_margin: float = 0.15
    limit_gain: float = 2.0

    press_depth: float = 0.005
    reach_descent_ratio: float = 0.5
    edge_inset: float = 0.05
    lift_height: float = 0.12

    rot_sigma: float = 0.5
    finger_sigma: float = 0.4

    pos_tol: float = 0.01
    rot_tol: float = 0.05
    finger_tol: float = 0.02
    preshape_distance: float = 0.15
    rise_distance: float = 0.05
    relax_distance: float = 0.10
    settle_time: float = 0.2
    home_tol: float = 0.03
    deadlock_time: float = 5.0

    finger_goals: dict[str, float] = field(
        default_factory=lambda: {"relax": 0.3, "preshape": 0.6, "grasp": 1.3, "release": 0.0}
    )

    def __post_init__(self) -> None:
        for name in ("width_range", "depth_range"):
            lo_hi = tuple(float(v) for v in getattr(self, name))
            if len(lo_hi) != 2 or not (0.0 < lo_hi[0] <= lo_hi[1]):
                raise ConfigError(f"{name} must be [min, max] with 0 < min <= max, got {lo_hi}")
            object.__setattr__(self, name, lo_hi)
        if self.width_range[1] > 0.34 or self.depth_range[1] > 0.28:
            raise ConfigError(
                f"boxes up to {self.width_range[1]} x {self.depth_range[1]} m do not fit the "
                "container (inner 0.36 x 0.30 m); use width <= 0.34 and depth <= 0.28"
            )
        if self.width_range[0] < 0.10 or self.depth_range[0] < 0.10:
            raise ConfigError(
                "boxes must be at least 0.10 x 0.10 m (a palm is 0.09 x 0.10 m), got minima "
                f"{self.width_range[0]}, {self.depth_range[0]}"
            )
        positive = (
            "box_height box_mass control_dt physics_dt max_time pos_gain rot_gain finger_gain "
            "max_speed "
            "max_joint_speed ik_damping rot_sigma finger_sigma pos_tol rot_tol finger_tol "
            "lift_height deadlock_time reach_descent_ratio"
        ).split()
        for name in positive:
            value = getattr(self, name)
            if not isinstance(value, int | float) or not math.isfinite(value) or value <= 0:
                raise ConfigError(f"{name} must be a positive number, got {value!r}")
        if not isinstance(self.settle_time, int | float) or not self.settle_time >= 0:
            raise ConfigError(f"settle_time must be >= 0 seconds, got {self.settle_time!r}")
        if not 0.04 <= self.box_height <= 0.16:
            raise ConfigError(f"box_height must be in [0.04, 0.16] m, got {self.box_height}")
        ratio = self.control_dt / self.physics_dt
        if ratio < 1 - 1e-9 or abs(ratio - round(ratio)) > 1e-6:
            raise ConfigError(
                f"control_dt ({self.control_dt} s) must be a whole multiple of physics_dt "
                f"({self.physics_dt} s)"
            )
        if not isinstance(self.seed, int) or self.seed < 0:
            raise ConfigError(f"seed must be a non-negative int, got {self.seed!r}")
        if not isinstance(self.compile_kinematics, bool):
            raise ConfigError(
                f"compile_kinematics must be true or false, got {self.compile_kinematics!r}"
            )
        missing = {"relax", "preshape", "grasp", "release"} - set(self.finger_goals)
        if missing:
            raise ConfigError(f"finger_goals lacks {sorted(missing)}")
        object.__setattr__(
            self, "finger_goals", {k: float(v) for k, v in dict(self.finger_goals).items()}
        )

    @classmethod
    def from_dict(cls, cfg: Mapping[str, Any] | None) -> TaskConfig:
        """Build from a mapping (plain or OmegaConf); unknown keys raise :class:`ConfigError`."""
        if cfg is None:
            return cls()
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(cfg) - known)
        if unknown:
            raise ConfigError(f"unknown task option(s) {unknown}; known: {sorted(known)}")
        values = dict(cfg)
        for name in ("width_range", "depth_range"):
            if name in values:
                values[name] = tuple(values[name])
        try:
            return cls(**values)
        except TypeError as exc:
            raise ConfigError(f"invalid task config: {exc}") from exc

    def to_dict(self) -> dict[str, Any]:
        """Plain-dict form (lists for ranges), the inverse of :meth:`from_dict`."""
        out = dataclasses.asdict(self)
        out["width_range"] = list(self.width_range)
        out["depth_range"] = list(self.depth_range)
        return out


def as_task_config(cfg: TaskConfig | Mapping[str, Any] | None) -> TaskConfig:
    """``cfg`` as a :class:`TaskConfig`: itself, built from a mapping, or the defaults for None."""
    return cfg if isinstance(cfg, TaskConfig) else TaskConfig.from_dict(cfg)
