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

from cpmp.config.validation import OptionValue
from cpmp.errors import ConfigError

MAX_SPEED_FACTOR = 4.0
"""The largest speed factor a :class:`Pacing` may draw: at 4x the attractors of both worlds still
take several control ticks to converge (the relay world's ``dt * gain`` stays below 1)."""


@dataclass(frozen=True)
class Pacing:
    """How fast the MPs of a run go and whether they pause mid-MP (off by default).

    Every *activation* draws its own pace: a speed factor log-uniform in ``speed`` (the MP's
    commanded velocity, hence its attractor gain and speed limit, times the factor: the same
    path in ``1 / factor`` of the time) and, with probability ``pause_probability``, one hold of
    a duration uniform in ``pause`` seconds, which starts once the activation has covered a
    fraction uniform in :data:`PAUSE_AT` of its initial goal distance (the MP stays active, its
    variable stands still). :class:`cpmp.worlds.pacing.Pacer` applies it.

    Attributes:
        speed: ``[min, max]`` speed factor, ``0 < min <= max <= MAX_SPEED_FACTOR``; ``None``:
            every MP at its nominal speed (factor 1).
        pause: ``[min, max]`` hold duration [s], ``0 <= min <= max``; ``None``: no holds.
        pause_probability: the probability that an activation holds once, in [0, 1].
    """

    speed: tuple[float, float] | None = None
    pause: tuple[float, float] | None = None
    pause_probability: float = 1.0

    def __post_init__(self) -> None:
        speed, pause, probability = _checked_pacing(
            self.speed, self.pause, self.pause_probability, "Pacing.{}"
        )
        object.__setattr__(self, "speed", speed)
        object.__setattr__(self, "pause", pause)
        object.__setattr__(self, "pause_probability", probability)

    @property
    def varied(self) -> bool:
        """Whether any MP runs off its nominal speed or holds."""
        return self.speed is not None or (self.pause is not None and self.pause_probability > 0)


PAUSE_AT: tuple[float, float] = (0.2, 0.8)
"""A hold starts once the activation has covered this fraction (drawn uniformly) of its initial
goal distance: a random point inside the motion, not at its very start or end."""


def pacing_options(speed: object, pause: object, pause_probability: object, prefix: str) -> Pacing:
    """A :class:`Pacing` from option values, each checked under its option's name.

    Args:
        speed: ``None`` or ``[min, max]`` speed factors.
        pause: ``None`` or ``[min, max]`` hold durations [s].
        pause_probability: in [0, 1].
        prefix: the options' prefix in error messages (``demo``: ``demo_speed``, ...).

    Returns:
        The pacing.

    Raises:
        ConfigError: a value out of range, naming ``<prefix>_speed``, ``<prefix>_pause`` or
            ``<prefix>_pause_probability``.
    """
    return Pacing(*_checked_pacing(speed, pause, pause_probability, prefix + "_{}"))


def _checked_pacing(
    speed: object, pause: object, pause_probability: object, name: str
) -> tuple[tuple[float, float] | None, tuple[float, float] | None, float]:
    """The pacing options checked; ``name`` formats an option's name in messages."""
    speed_range = _range_option(speed, name.format("speed"), open_low=True)
    if speed_range is not None and speed_range[1] > MAX_SPEED_FACTOR:
        raise ConfigError(
            f"{name.format('speed')} must be [min, max] with max <= {MAX_SPEED_FACTOR}, got "
            f"{list(speed_range)}"
        )
    pause_range = _range_option(pause, name.format("pause"), open_low=False)
    p = pause_probability
    if isinstance(p, bool) or not isinstance(p, int | float) or not 0.0 <= p <= 1.0:
        raise ConfigError(
            f"{name.format('pause_probability')} must be a number in [0, 1], got {p!r}"
        )
    return speed_range, pause_range, float(p)


def _range_option(value: object, name: str, open_low: bool) -> tuple[float, float] | None:
    """``value`` as ``(min, max)``, or ``None``.

    The numbers are finite, ``min <= max`` and ``min > 0`` (``>= 0`` unless ``open_low``).
    """
    if value is None:
        return None
    bound = "> 0" if open_low else ">= 0"
    try:
        lo_hi = tuple(value)  # type: ignore[call-overload]
    except TypeError:
        lo_hi = ()
    numbers = all(
        not isinstance(v, bool) and isinstance(v, int | float) and math.isfinite(v) for v in lo_hi
    )
    if len(lo_hi) != 2 or not numbers:
        raise ConfigError(f"{name} must be null or [min, max] (two numbers), got {value!r}")
    lo, hi = float(lo_hi[0]), float(lo_hi[1])
    if not (lo > 0.0 if open_low else lo >= 0.0) or lo > hi:
        raise ConfigError(
            f"{name} must be [min, max] with min {bound} and min <= max, got {[lo, hi]}"
        )
    return lo, hi


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
        demo_speed: ``[min, max]`` speed factor of every activation of the scripted
            demonstrator's MPs, drawn per activation (log-uniform); ``null``: nominal speed.
            See :class:`Pacing`.
        demo_pause: ``[min, max]`` [s] of one hold at a random point of an activation of the
            demonstrator's MPs; ``null``: no holds.
        demo_pause_probability: the probability that an activation of the demonstrator holds.
        robot_speed: as ``demo_speed``, for the closed-loop robot (the MPs a policy runs in
            :func:`cpmp.sim.run_episodes`).
        robot_pause: as ``demo_pause``, for the closed-loop robot.
        robot_pause_probability: as ``demo_pause_probability``, for the closed-loop robot.

    The six pacing options (``demo_*``, ``robot_*``) are off by default; :meth:`to_dict` lists
    them only when one of a kind is set, so that the records of unpaced runs keep their form.
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

    demo_speed: tuple[float, float] | None = None
    demo_pause: tuple[float, float] | None = None
    demo_pause_probability: float = 1.0
    robot_speed: tuple[float, float] | None = None
    robot_pause: tuple[float, float] | None = None
    robot_pause_probability: float = 1.0

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
        for kind in PACED_RUNS:
            pacing = pacing_options(
                getattr(self, f"{kind}_speed"),
                getattr(self, f"{kind}_pause"),
                getattr(self, f"{kind}_pause_probability"),
                kind,
            )
            object.__setattr__(self, f"{kind}_speed", pacing.speed)
            object.__setattr__(self, f"{kind}_pause", pacing.pause)
            object.__setattr__(self, f"{kind}_pause_probability", pacing.pause_probability)

    @property
    def demo_pacing(self) -> Pacing:
        """The scripted demonstrator's :class:`Pacing` (``demo_*`` options)."""
        return Pacing(self.demo_speed, self.demo_pause, self.demo_pause_probability)

    @property
    def robot_pacing(self) -> Pacing:
        """The closed-loop robot's :class:`Pacing` (``robot_*`` options)."""
        return Pacing(self.robot_speed, self.robot_pause, self.robot_pause_probability)

    @classmethod
    def from_dict(cls, cfg: Mapping[str, OptionValue] | None) -> TaskConfig:
        """Build from a mapping (plain or OmegaConf); unknown keys raise :class:`ConfigError`."""
        if cfg is None:
            return cls()
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(cfg) - known)
        if unknown:
            raise ConfigError(f"unknown task option(s) {unknown}; known: {sorted(known)}")
        values = dict(cfg)
        for name in ("width_range", "depth_range", *PACING_RANGES):
            if values.get(name) is not None and not isinstance(values[name], str):
                try:
                    values[name] = tuple(values[name])
                except TypeError:
                    pass  # not a sequence: __post_init__ names the option
        try:
            return cls(**values)
        except TypeError as exc:
            raise ConfigError(f"invalid task config: {exc}") from exc

    def to_dict(self) -> dict[str, OptionValue]:
        """Plain-dict form (lists for ranges), the inverse of :meth:`from_dict`."""
        out = dataclasses.asdict(self)
        out["width_range"] = list(self.width_range)
        out["depth_range"] = list(self.depth_range)
        for kind in PACED_RUNS:
            names = [f"{kind}_speed", f"{kind}_pause", f"{kind}_pause_probability"]
            if getattr(self, f"{kind}_speed") is None and getattr(self, f"{kind}_pause") is None:
                for name in names:
                    del out[name]
            else:
                for name in names[:2]:
                    out[name] = None if out[name] is None else list(out[name])
        return out


PACED_RUNS = ("demo", "robot")
"""The runs a :class:`TaskConfig` paces: the scripted demonstrator's and the closed-loop
robot's (options ``<run>_speed``, ``<run>_pause``, ``<run>_pause_probability``)."""
PACING_RANGES = tuple(f"{run}_{option}" for run in PACED_RUNS for option in ("speed", "pause"))
"""The pacing options given as ``[min, max]``."""


def as_task_config(cfg: TaskConfig | Mapping[str, OptionValue] | None) -> TaskConfig:
    """``cfg`` as a :class:`TaskConfig`: itself, built from a mapping, or the defaults for None."""
    return cfg if isinstance(cfg, TaskConfig) else TaskConfig.from_dict(cfg)
