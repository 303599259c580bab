"""The peg task: a reactive peg-in-hole insertion retrying after jams, a helper holding the base.

Two control variables, first-order attractors ``ṗ = K (g - p)`` in the vertical x-z plane
(metres; z is the height above the table), stepped with Euler steps:

* ``inserter`` (an arm with a gripper holding the peg): ``align`` (to the *align pose*
  ``align_clearance`` above the hole's mouth at the hole estimate), ``insert`` (down into the
  hole: to the full hole depth when the hole is shallow, to half of it when it is deep),
  ``retract`` (straight back up to the align height after a jam), ``release`` (open the gripper
  and lift ``LIFT`` off the peg), ``push`` (press the released peg home with the open hand;
  deep holes only) and ``home``. The gripper's opening follows the MP: closed for ``align``,
  ``insert`` and ``retract``, open for ``release``, ``push`` and ``home``.
* ``holder`` (the other arm): ``hold`` (press a light base down, across every try) then
  ``retreat`` (home) once the peg is home; on a heavy base it stays home (``rest``).

Hidden event (the reactive part): an insertion *attempt* starts when the gripped peg reaches
the hole's mouth. The context pre-draws the number of jams ``n_jams`` (0, 1 or 2): the k-th
well-aligned attempt jams iff ``k <= n_jams``, so every run of a context jams identically,
whatever policy drives it. A jam is visible only in the force feature: the peg stops at the
mouth and the axial force rises towards ``jam_force``. When the jammed peg leaves the mouth the
robot's hole estimate (a feature) moves by a few mm (the context's ``shifts``), so the re-align
has a new goal: a re-align starts where the previous align ended, except for that shift. An
attempt that reaches the mouth more than ``mouth_tolerance`` beside the current estimate is
caught by the mouth and jams too (it does not count as an attempt: the estimate stays).

Failures nothing undoes (the run is then done and incomplete):

* the base slides: the peg presses on a light base while the holder's clamp force is below
  ``hold_force`` (inserting before the holder holds, or after it left);
* the peg breaks: a jammed peg pressed for ``break_time``;
* the peg drops: released outside the hole.

The goal state: the peg home (at most ``home_tolerance`` short of the hole's depth), released,
the gripper open, both arms within ``goal_tolerance`` of their homes.

The context (:class:`PegContext`): the base mass decides the start (light: the holder goes to
hold it; heavy: it rests), the hole depth decides the end (deep: half-insert, release, push;
shallow: full insert, release), the hidden jam count decides the retries; the hole estimate's
start value, the homes, a noisy table-height estimate and a light level vary and decide
nothing.

Features (:data:`FEATURE_NAMES`, 13, all within about [-0.1, 2]): positions [m], the gripper
opening [0, 1], the insertion force and the holder's clamp force [normalised, 0 to about 1.5],
the peg's depth in the hole [m], the hole estimate [m], the hole depth [m], the base mass [kg],
the table-height estimate [m] and the light level [normalised].
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Literal, get_args

import numpy as np

from cpmp.config.validation import finite_number
from cpmp.errors import ConfigError, UnknownMPError

Strategy = Literal["light_shallow", "light_deep", "heavy_shallow", "heavy_deep"]
"""The base (light: held; heavy: not) and the hole (shallow: full insert; deep: half and push)."""
STRATEGIES: tuple[Strategy, ...] = get_args(Strategy)
VARIABLES: tuple[str, ...] = ("holder", "inserter")
MPS: dict[str, tuple[str, ...]] = {
    "holder": ("hold", "retreat", "rest"),
    "inserter": ("align", "insert", "retract", "release", "push", "home"),
}
"""The MPs of each variable."""
FEATURE_NAMES: tuple[str, ...] = (
    "inserter_x",
    "inserter_z",
    "grip_opening",
    "insert_force",
    "peg_depth",
    "hole_x_estimate",
    "hole_depth",
    "holder_x",
    "holder_z",
    "clamp_force",
    "base_mass",
    "table_height_estimate",
    "light_level",
)
# feature indices
INSERTER_X, INSERTER_Z, GRIP, FORCE, PEG_DEPTH, HOLE_X, HOLE_DEPTH = range(7)
HOLDER_X, HOLDER_Z, CLAMP, BASE_MASS, TABLE_HEIGHT, LIGHT = range(7, 13)

MOUTH_Z = 0.6
"""Height of the hole's mouth (the base's top) above the table [m]."""
LIFT = 0.05
"""``release`` lifts the hand this far above the peg [m]."""
INSERTER_HOME = (0.3, 1.2)
HOLDER_HOME = (1.7, 1.0)
HOLE_X_MEAN = 1.0
"""Mean x of the hole [m] (the start estimate varies by ``hole_jitter``)."""
PRESS_OFFSET = 0.25
"""The holder presses the base this far beside the hole [m]."""
PRESS_DEPTH = 0.02
"""``hold`` aims this far below the base's top (the base stops it: it presses) [m]."""
BASE_HALF_WIDTH = 0.15
"""The holder touches the base's top within this x-distance of the press point [m]."""
GRIPPED_BELOW = 0.3
"""The gripper holds the peg while its opening is below this (it never grips it again)."""
CLAMP_MAX = 1.0
"""The clamp force a pressing holder settles at."""
MASS_THRESHOLD = 1.0
"""Bases lighter than this [kg] slide unless held (light masses in [0.3, 0.8], heavy [1.2, 1.8])."""
LIGHT_MASS = (0.3, 0.8)
HEAVY_MASS = (1.2, 1.8)
DEEP_THRESHOLD = 0.25
"""Holes deeper than this [m] are half-inserted and pushed (shallow: [0.12, 0.2], deep: [0.3,
0.44])."""
SHALLOW_DEPTH = (0.12, 0.2)
DEEP_DEPTH = (0.3, 0.44)
TABLE_HEIGHT_MEAN = 0.75
"""Mean true table height [m]; the estimate feature wobbles around a per-context value."""
MAX_JAMS = 2


@dataclass(frozen=True)
class PegContext:
    """The random parameters of one episode (positions in m).

    Attributes:
        strategy: one of :data:`STRATEGIES` (the base and the hole drawn for it).
        n_jams: hidden: how many well-aligned attempts jam (0, 1 or 2); not a feature.
        base_mass: [kg]; below :data:`MASS_THRESHOLD` the base is light.
        hole_depth: [m]; above :data:`DEEP_THRESHOLD` the hole is deep.
        hole_x: the hole estimate at the start [m].
        shifts: (2,) how the estimate moves after the first and the second jam [m].
        inserter_home, holder_home: (2,) start (and end) positions (x, z).
        table_height: the table-height estimate's mean [m] (a distractor).
        light_level: the light level's mean (a distractor).
        phase: the distractors' wobble phase [rad].
    """

    strategy: Strategy
    n_jams: int
    base_mass: float
    hole_depth: float
    hole_x: float
    shifts: tuple[float, float]
    inserter_home: tuple[float, float]
    holder_home: tuple[float, float]
    table_height: float
    light_level: float
    phase: float

    @property
    def light(self) -> bool:
        """Whether the base is light (the holder must hold it)."""
        return self.base_mass < MASS_THRESHOLD

    @property
    def deep(self) -> bool:
        """Whether the hole is deep (half-insert, release, push)."""
        return self.hole_depth > DEEP_THRESHOLD

    @property
    def insert_depth(self) -> float:
        """How deep ``insert`` takes the peg [m]: the hole's depth, or half of a deep one."""
        return self.hole_depth / 2 if self.deep else self.hole_depth

    @property
    def press_x(self) -> float:
        """Where the holder presses the base [m]."""
        return self.hole_x + PRESS_OFFSET


@dataclass
class PegState:
    """The simulated world, hidden state included (positions in m).

    Attributes:
        t: time [s].
        ins_x, ins_z: the inserter's hand (the peg's tip while gripped).
        grip: the gripper's opening in [0, 1] (0 closed).
        gripped: the gripper holds the peg.
        peg_x, peg_z: the peg's tip.
        force: the axial insertion force.
        hole_x: the hole estimate.
        holder_x, holder_z: the holder's hand.
        clamp: the holder's clamp force on the base.
        attempts: well-aligned attempts so far.
        in_hole: the peg is in the hole, below its mouth.
        jammed: the peg is stuck at the mouth.
        pending_shift: the jam moves the estimate when the peg leaves the mouth.
        press_time: how long the jammed peg has been pressed [s].
        slid, broken, dropped: the failures (see the module doc).
    """

    t: float
    ins_x: float
    ins_z: float
    grip: float
    gripped: bool
    peg_x: float
    peg_z: float
    force: float
    hole_x: float
    holder_x: float
    holder_z: float
    clamp: float = 0.0
    attempts: int = 0
    in_hole: bool = False
    jammed: bool = False
    pending_shift: bool = False
    press_time: float = 0.0
    slid: bool = False
    broken: bool = False
    dropped: bool = False

    @property
    def failed(self) -> bool:
        """Whether a failure nothing undoes happened."""
        return self.slid or self.broken or self.dropped


@dataclass
class PegTask:
    """The peg task's options (see the module doc).

    Attributes:
        dt: control period and the demonstrations' sample period [s].
        max_time: episode time limit [s].
        gain_inserter, gain_holder, gain_grip: attractor gains K [1/s].
        gain_force: how fast the insertion and clamp forces follow their targets [1/s].
        tolerance: the demonstrator's position guards [m].
        mouth_tolerance: an attempt this far or farther beside the estimate jams [m];
            above ``tolerance``.
        shift_min, shift_max: range of the estimate's shift after a jam [m]; ``shift_min``
            above ``mouth_tolerance`` (a re-align really moves).
        align_clearance: the align pose's height above the mouth [m].
        jam_force: the force a pressed jam rises to.
        friction_force: the force of a peg sliding in the hole; below ``force_threshold``.
        force_threshold: the demonstrator's jam guard, in (friction_force, jam_force).
        hold_force: the clamp force from which the base is held, in (0, 1).
        break_time: a jammed peg pressed this long breaks [s].
        open_level: the gripper counts as open from this opening on, in (GRIPPED_BELOW, 1).
        home_tolerance: the peg is home at most this short of the hole's depth [m];
            above ``tolerance``.
        goal_tolerance: the arms' goal tolerance around their homes [m]; above ``tolerance``.
        start_jitter: half-width of the uniform jitter of both homes per axis [m], in [0, 0.1].
        hole_jitter: half-width of the uniform jitter of the start hole estimate [m], in
            [0, 0.1].
    """

    dt: float = 0.01
    max_time: float = 25.0
    gain_inserter: float = 4.0
    gain_holder: float = 1.5
    gain_grip: float = 5.0
    gain_force: float = 10.0
    tolerance: float = 0.0015
    mouth_tolerance: float = 0.0025
    shift_min: float = 0.005
    shift_max: float = 0.009
    align_clearance: float = 0.05
    jam_force: float = 1.5
    friction_force: float = 0.2
    force_threshold: float = 1.0
    hold_force: float = 0.5
    break_time: float = 1.0
    open_level: float = 0.9
    home_tolerance: float = 0.005
    goal_tolerance: float = 0.03
    start_jitter: float = 0.05
    hole_jitter: float = 0.1

    def __post_init__(self) -> None:
        cls = type(self).__name__
        for option in fields(self):
            finite_number(getattr(self, option.name), f"{cls}.{option.name}")
        for option in fields(self):
            if (
                option.name not in ("start_jitter", "hole_jitter")
                and getattr(self, option.name) <= 0
            ):
                raise ConfigError(
                    f"{cls}.{option.name} must be > 0, got {getattr(self, option.name)}"
                )
        gain = max(self.gain_inserter, self.gain_holder, self.gain_grip, self.gain_force)
        if self.dt * gain >= 1.0:
            raise ConfigError(
                f"{cls}: dt * gain must be < 1 for stable Euler steps, got dt={self.dt} with "
                f"the largest gain {gain}; lower dt or the gains"
            )
        if self.max_time < 10 * self.dt:
            raise ConfigError(f"{cls}.max_time must be >= 10 dt, got {self.max_time}")
        if not self.tolerance < self.mouth_tolerance < self.shift_min <= self.shift_max <= 0.02:
            raise ConfigError(
                f"{cls} needs tolerance < mouth_tolerance < shift_min <= shift_max <= 0.02 m "
                f"(an aligned peg enters, a re-align moves), got {self.tolerance}, "
                f"{self.mouth_tolerance}, {self.shift_min}, {self.shift_max}"
            )
        if not self.friction_force < self.force_threshold < self.jam_force:
            raise ConfigError(
                f"{cls} needs friction_force < force_threshold < jam_force, got "
                f"{self.friction_force}, {self.force_threshold}, {self.jam_force}"
            )
        if not self.hold_force < CLAMP_MAX:
            raise ConfigError(
                f"{cls}.hold_force must be in (0, {CLAMP_MAX}), got {self.hold_force}"
            )
        if not GRIPPED_BELOW < self.open_level < 1.0:
            raise ConfigError(
                f"{cls}.open_level must be in ({GRIPPED_BELOW}, 1), got {self.open_level}"
            )
        for name in ("home_tolerance", "goal_tolerance"):
            if not self.tolerance < getattr(self, name):
                raise ConfigError(
                    f"{cls}: tolerance ({self.tolerance}) must be < {name} "
                    f"({getattr(self, name)}), or the demonstrator may miss the goal"
                )
        if not self.align_clearance <= 0.2:
            raise ConfigError(
                f"{cls}.align_clearance must be in (0, 0.2] m, got {self.align_clearance}"
            )
        for name in ("start_jitter", "hole_jitter"):
            if not 0.0 <= getattr(self, name) <= 0.1:
                raise ConfigError(f"{cls}.{name} must be in [0, 0.1] m, got {getattr(self, name)}")

    # ----------------------------------------------------------------------------- contexts
    def sample_context(
        self, rng: np.random.Generator, strategy: Strategy, n_jams: int
    ) -> PegContext:
        """One context of ``strategy`` with ``n_jams`` jams, its geometry drawn from ``rng``.

        Raises:
            ConfigError: an unknown strategy or a jam count outside 0..2.
        """
        if strategy not in STRATEGIES:
            raise ConfigError(f"strategy must be one of {STRATEGIES}, got {strategy!r}")
        if isinstance(n_jams, bool) or not isinstance(n_jams, int) or not 0 <= n_jams <= MAX_JAMS:
            raise ConfigError(f"n_jams must be an integer in [0, {MAX_JAMS}], got {n_jams!r}")
        light, deep = strategy.startswith("light"), strategy.endswith("deep")
        mass = float(rng.uniform(*(LIGHT_MASS if light else HEAVY_MASS)))
        depth = float(rng.uniform(*(DEEP_DEPTH if deep else SHALLOW_DEPTH)))
        hole_x = HOLE_X_MEAN + float(rng.uniform(-self.hole_jitter, self.hole_jitter))
        signs = rng.choice([-1.0, 1.0], 2)
        shifts = rng.uniform(self.shift_min, self.shift_max, 2) * signs
        sj = self.start_jitter
        ins = np.asarray(INSERTER_HOME) + rng.uniform(-sj, sj, 2)
        hol = np.asarray(HOLDER_HOME) + rng.uniform(-sj, sj, 2)
        return PegContext(
            strategy=strategy,
            n_jams=n_jams,
            base_mass=mass,
            hole_depth=depth,
            hole_x=hole_x,
            shifts=(float(shifts[0]), float(shifts[1])),
            inserter_home=(float(ins[0]), float(ins[1])),
            holder_home=(float(hol[0]), float(hol[1])),
            table_height=TABLE_HEIGHT_MEAN + float(rng.uniform(-0.03, 0.03)),
            light_level=float(rng.uniform(0.4, 1.6)),
            phase=float(rng.uniform(0.0, 2 * math.pi)),
        )

    def contexts(self, n: int, seed: int) -> list[PegContext]:
        """``n`` contexts drawn from ``seed``, cycling the strategies and the jam counts.

        Context ``i`` has strategy ``i % 4`` and ``(i // 4 + i) % 3`` jams (the first three 0,
        1 and 2; every strategy sees every count within 12 contexts); its geometry, masses and
        distractors are drawn from one generator seeded by ``seed``, in order.
        """
        rng = np.random.default_rng(seed)
        k = len(STRATEGIES)
        return [
            self.sample_context(rng, STRATEGIES[i % k], (i // k + i) % (MAX_JAMS + 1))
            for i in range(n)
        ]

    def initial_mps(self, context: PegContext) -> dict[str, str]:
        """The demonstrator's initial MPs: the holder holds a light base, rests by a heavy one."""
        return {"holder": "hold" if context.light else "rest", "inserter": "align"}

    def initial_state(self, context: PegContext) -> PegState:
        """Both arms home, the peg gripped, nothing touching."""
        ix, iz = context.inserter_home
        hx, hz = context.holder_home
        return PegState(
            t=0.0,
            ins_x=ix,
            ins_z=iz,
            grip=0.0,
            gripped=True,
            peg_x=ix,
            peg_z=iz,
            force=0.0,
            hole_x=context.hole_x,
            holder_x=hx,
            holder_z=hz,
        )

    def features(self, state: PegState, context: PegContext) -> np.ndarray:
        """Feature vector ``(13,)`` in :data:`FEATURE_NAMES` order."""
        wobble = 2 * math.pi * state.t
        return np.array(
            [
                state.ins_x,
                state.ins_z,
                state.grip,
                state.force,
                max(0.0, MOUTH_Z - state.peg_z),
                state.hole_x,
                context.hole_depth,
                state.holder_x,
                state.holder_z,
                state.clamp,
                context.base_mass,
                context.table_height + 0.004 * math.sin(0.7 * wobble + context.phase),
                context.light_level + 0.05 * math.sin(0.3 * wobble + 2 * context.phase),
            ]
        )

    # ----------------------------------------------------------------------------- dynamics
    def check_mps(self, active: dict[str, str]) -> None:
        """Raise :class:`UnknownMPError` unless every variable runs one of its MPs."""
        for v in VARIABLES:
            if active.get(v) not in MPS[v]:
                raise UnknownMPError(
                    f"{v}: unknown MP {active.get(v)!r}; the peg task knows {MPS[v]}"
                )

    def inserter_goal(
        self, state: PegState, context: PegContext, mp: str
    ) -> tuple[float, float, float]:
        """The inserter's attractor goal under ``mp``: x, z [m] and the gripper opening."""
        align_z = MOUTH_Z + self.align_clearance
        if mp == "align":
            return state.hole_x, align_z, 0.0
        if mp == "insert":
            return state.hole_x, MOUTH_Z - context.insert_depth, 0.0
        if mp == "retract":
            return state.ins_x, align_z, 0.0
        if mp == "release":  # the hand keeps still until the fingers let the peg go
            lift = 0.0 if state.gripped else LIFT
            return state.peg_x, state.peg_z + lift, 1.0
        if mp == "push":
            return state.peg_x, MOUTH_Z - context.hole_depth, 1.0
        return context.inserter_home[0], context.inserter_home[1], 1.0

    def advance(
        self, state: PegState, context: PegContext, active: dict[str, str], h: float | None = None
    ) -> None:
        """One Euler step of ``h`` [s] (default ``dt``) under the ``active`` MPs, in place.

        Raises:
            UnknownMPError: an MP the task does not know.
        """
        self.check_mps(active)
        h = self.dt if h is None else h
        mp = active["inserter"]
        bottom = MOUTH_Z - context.hole_depth
        gx, gz, gg = self.inserter_goal(state, context, mp)
        k = h * self.gain_inserter
        x = state.ins_x + k * (gx - state.ins_x)
        z = state.ins_z + k * (gz - state.ins_z)
        state.grip += h * self.gain_grip * (gg - state.grip)
        pressing = gz < MOUTH_Z
        if state.gripped:
            if state.jammed:
                z = max(z, MOUTH_Z)
            elif not state.in_hole and z <= MOUTH_Z:
                self._reach_mouth(state, context, x)
                if state.jammed:
                    z = MOUTH_Z
            if state.in_hole:
                z = max(z, bottom)
                x = state.ins_x  # the hole guides the peg
            state.peg_x, state.peg_z = x, z
            state.in_hole = not state.jammed and z < MOUTH_Z
        contact = False
        if not state.gripped and mp == "push" and z <= state.peg_z:
            state.peg_z = max(z, bottom)
            z, x, contact = state.peg_z, state.peg_x, True
        if state.jammed and z > MOUTH_Z:  # the jammed peg leaves the mouth
            state.jammed = False
            state.press_time = 0.0
            if state.pending_shift:
                state.hole_x += context.shifts[state.attempts - 1]
                state.pending_shift = False
        state.ins_x, state.ins_z = x, z
        if state.gripped and state.grip >= GRIPPED_BELOW:
            state.gripped = False
            if state.peg_z >= MOUTH_Z:
                state.dropped = True
        # forces
        if state.jammed and pressing:
            target = self.jam_force
            state.press_time += h
            if state.press_time >= self.break_time - 1e-9:
                state.broken = True
        elif state.in_hole and ((state.gripped and mp == "insert") or contact):
            target = self.friction_force
        else:
            target = 0.0
        state.force += h * self.gain_force * (target - state.force)
        # holder
        hmp = active["holder"]
        if hmp == "hold":
            hgx, hgz = context.press_x, MOUTH_Z - PRESS_DEPTH
        else:
            hgx, hgz = context.holder_home
        k = h * self.gain_holder
        state.holder_x += k * (hgx - state.holder_x)
        state.holder_z += k * (hgz - state.holder_z)
        touching = (
            abs(state.holder_x - context.press_x) < BASE_HALF_WIDTH and state.holder_z <= MOUTH_Z
        )
        if touching:
            state.holder_z = MOUTH_Z
        clamp_target = CLAMP_MAX if touching and hgz < MOUTH_Z else 0.0
        state.clamp += h * self.gain_force * (clamp_target - state.clamp)
        # a light base slides when the peg presses on it unheld
        on_base = (state.gripped and mp == "insert" and (state.jammed or state.in_hole)) or contact
        if (
            on_base
            and context.light
            and state.clamp < self.hold_force
            and not self.peg_home(state, context)
        ):
            state.slid = True
        state.t = round(state.t + h, 10)

    def _reach_mouth(self, state: PegState, context: PegContext, x: float) -> None:
        """The gripped peg reaches the mouth at ``x`` [m]: an attempt, which may jam."""
        if abs(x - state.hole_x) >= self.mouth_tolerance:
            state.jammed = True  # caught by the mouth's edge; not a counted attempt
            return
        state.attempts += 1
        if state.attempts <= context.n_jams:
            state.jammed = True
            state.pending_shift = True

    def peg_home(self, state: PegState, context: PegContext) -> bool:
        """Whether the peg is at most ``home_tolerance`` short of the hole's depth."""
        return MOUTH_Z - state.peg_z >= context.hole_depth - self.home_tolerance

    def shortfall(self, state: PegState, context: PegContext) -> str:
        """Why ``state`` is not the goal state, in words (``""`` at the goal).

        The failure nothing undoes if one happened, else each goal condition not met.
        """
        if state.slid:
            return (
                "the light base slid: the peg pressed on it while the holder's clamp force was "
                f"below {self.hold_force:g}"
            )
        if state.broken:
            return f"the jammed peg broke (pressed for {self.break_time:g} s)"
        if state.dropped:
            return "the peg dropped: released above the hole's mouth"
        unmet = []
        depth = MOUTH_Z - state.peg_z
        if depth <= 0:
            unmet.append("the peg is not in the hole")
        elif not self.peg_home(state, context):
            unmet.append(f"the peg is {1000 * (context.hole_depth - depth):.0f} mm short of home")
        if state.gripped or state.grip < self.open_level:
            unmet.append("the gripper is not open")
        tol = self.goal_tolerance
        if math.dist((state.ins_x, state.ins_z), context.inserter_home) >= tol:
            unmet.append("the inserter is not home")
        if math.dist((state.holder_x, state.holder_z), context.holder_home) >= tol:
            unmet.append("the holder is not home")
        return "; ".join(unmet)

    def at_goal(self, state: PegState, context: PegContext) -> bool:
        """The peg home and released, the gripper open, both arms home, no failure."""
        tol = self.goal_tolerance
        return bool(
            not state.failed
            and not state.gripped
            and self.peg_home(state, context)
            and state.grip >= self.open_level
            and math.dist((state.ins_x, state.ins_z), context.inserter_home) < tol
            and math.dist((state.holder_x, state.holder_z), context.holder_home) < tol
        )
