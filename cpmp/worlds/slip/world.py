"""The slip task: pick an object that may slip out of the gripper, and drawer it away.

An arm with a gripper picks an object from a table, lifts it to a carry height and places it in
a drawer of a cabinet, which the other hand (the ``drawer`` variable) pulls open, holds open
through every try and pushes shut once the object lies inside and the arm is out. While the arm
lifts, the object may *slip*: the grip fails at a hidden height, the object falls back onto the
table, and the arm must ``lower`` again, the gripper ``open`` and close again. How often that
happens (``n_slips``, 0 to ``max_slips``) is hidden in the context and decided *during* ``lift``:
nothing at the start tells it, so the loop ``lift -> lower -> lift`` and its count are reactive.
Every run of the same context slips identically (try ``k`` slips iff ``k <= n_slips``, at the
height ``slip_z[k - 1]``).

Three control variables, first-order attractors ``ṗ = K (g - p)`` stepped with Euler:

* ``arm`` (the gripper's fingertip centre ``(x, z)`` [m]): ``reach`` (down to the object on the
  table), ``lift`` (straight up to ``CARRY_Z``), ``lower`` (back down to the object after a
  slip), ``place`` (to ``PLACE_CLEARANCE`` above the drawer's floor, at the shelf's height) and
  ``retreat`` (home). ``lift`` has two successors: ``lower`` (slip) and ``place`` (carry height
  reached holding the object).
* ``gripper`` (the opening, a fraction of the full stroke): ``open`` (to 1), ``close`` (to 0,
  stopped by the object when it is between the fingers), ``release`` (to 1). After a slip it
  goes ``close -> open`` and closes again: ``open -> close -> open -> ...``.
* ``drawer`` (the other hand; the drawer's extension [m]): ``pull_open`` (to ``OPEN_EXT``),
  ``hold_open`` (keep it there) and ``push_shut`` (to 0). It starts with ``pull_open`` when the
  drawer is shut at the start and with ``hold_open`` when it is already open: the one start
  decision, read from the ``drawer_ext`` feature.

The object is held while it is between the fingers and they press on it (opening at its hidden
width); it follows the arm. When it leaves the hand (a slip, or the fingers opening past its
width) it falls straight down: into the drawer when the arm is in the drawer's mouth and the
drawer is open, onto the table (at the arm's ``x``; ``object_x`` then reads there) when over the
table and at most ``drop_limit`` above it; else it breaks (a fall from higher onto the table) or
is lost (on the floor). The arm in the drawer's mouth while the drawer is less than half open
hits the cabinet front (or is pinched by the closing drawer). Broken, lost and hit are failures
nothing can undo.

Features ``x (10,)`` in :data:`FEATURE_NAMES` order, all in about [0, 2]: ``arm_x, arm_z`` [m];
``grip`` the opening in [0, 1] of the stroke; ``contact`` 1 while the fingers hold the object,
else 0 (it drops at a slip, and the opening closes on past the object's width); ``object_x``
[m] where the overhead camera last saw the object on the table; ``drawer_ext`` [m];
``shelf_z`` [m] the drawer's height (low or high shelf: where ``place`` ends and the gripper
releases); ``drawer_load`` [kg] a scale in the drawer (the object's mass once inside);
``width_est`` a noisy estimate of the object's width [fraction of the stroke] and ``clutter_x``
[m] another object on the table: both vary between episodes and decide nothing.

The goal state: the object in the drawer, the drawer shut (``drawer_ext < tolerance``), the
gripper open (``grip >= OPEN_READY``) and the arm within ``goal_tolerance`` of home, held by
MPs that keep it (``retreat``, ``open``/``release``, ``push_shut``).

The scripted demonstrator is :mod:`cpmp.worlds.slip.demonstrator`; the World face is
:class:`cpmp.worlds.slip.registered.SlipWorld`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from typing import Literal

import numpy as np

from cpmp.config.validation import finite_number
from cpmp.errors import ConfigError, UnknownMPError
from cpmp.worlds.protocol import failure_text, substeps

FEATURE_NAMES: tuple[str, ...] = (
    "arm_x",
    "arm_z",
    "grip",
    "contact",
    "object_x",
    "drawer_ext",
    "shelf_z",
    "drawer_load",
    "width_est",
    "clutter_x",
)
VARIABLES: tuple[str, ...] = ("arm", "gripper", "drawer")
STRATEGIES: tuple[str, ...] = ("shut_low", "open_high", "open_low", "shut_high")
"""The strategies: the drawer shut or open at the start, the shelf low or high (any three in a
row cover both drawer states and both shelves)."""
MPS: dict[str, tuple[str, ...]] = {
    "arm": ("reach", "lift", "lower", "place", "retreat"),
    "gripper": ("open", "close", "release"),
    "drawer": ("pull_open", "hold_open", "push_shut"),
}
"""Every variable's MPs."""

HOME = (0.2, 0.8)
"""The arm's home ``(x, z)`` [m] before its jitter."""
GRASP_Z = 0.05
"""Fingertip height [m] at which the fingers grasp the object on the table (table top at 0)."""
CARRY_Z = 0.7
"""Goal height [m] of ``lift``."""
PICK_X = (0.4, 0.9)
"""Range [m] of the object's ``x`` on the table."""
TABLE_EDGE = 1.1
"""The table ends at this ``x`` [m]; beyond it an object falls to the floor."""
DRAWER_X = 1.5
"""``x`` [m] of the drawer's mouth (the ``place`` goal's ``x``)."""
MOUTH_HALF_X = 0.15
"""Half-width [m] of the drawer's mouth in ``x``."""
MOUTH_Z = (-0.05, 0.3)
"""The drawer's mouth spans these heights [m] relative to ``shelf_z``."""
PLACE_CLEARANCE = 0.1
"""``place`` ends this high [m] above the drawer's floor (``shelf_z``)."""
OPEN_EXT = 0.4
"""The drawer's extension [m] when open."""
SHELF_Z = {"low": (0.3, 0.5), "high": (1.0, 1.3)}
"""Ranges [m] of the drawer's height per shelf."""
WIDTH = (0.4, 0.7)
"""Range of the object's width [fraction of the stroke]."""
MASS = (0.3, 1.2)
"""Range of the object's mass [kg]."""
CLUTTER_X = (0.1, 1.0)
"""Range [m] of the other object's ``x`` on the table."""
OPEN_READY = 0.95
"""The gripper counts as open from this opening on."""
CONTACT_RADIUS = 0.05
"""The object is between the open fingers when the fingertips are this close to it [m]."""
LOAD_MIN = 0.1
"""The drawer's scale reads something [kg] from this load on."""

Holder = Literal["table", "hand", "drawer", "broken", "lost"]
"""Where the object is (``broken`` and ``lost`` are failures)."""
Failure = Literal["", "broken", "lost", "hit"]
"""What went wrong for good (``""``: nothing)."""


@dataclass(frozen=True, eq=False)
class SlipContext:
    """The random parameters of one episode (positions in m).

    Attributes:
        strategy: one of :data:`STRATEGIES`.
        drawer_open: whether the drawer is open at the start (the start decision).
        shelf_z: the drawer's height [m] (the release height).
        pick_x: the object's ``x`` on the table [m].
        home: ``(2,)`` the arm's home ``(x, z)`` [m].
        width: the object's width [fraction of the stroke] (hidden).
        width_est: its noisy estimate (a feature that decides nothing).
        mass: the object's mass [kg] (read by the drawer's scale once inside).
        clutter_x: the other object's ``x`` [m] (a feature that decides nothing).
        n_slips: how many tries slip (hidden), in ``[0, max_slips]``.
        slip_z: ``(max_slips,)`` the heights [m] at which try ``k`` slips (``k <= n_slips``;
            hidden).
    """

    strategy: str
    drawer_open: bool
    shelf_z: float
    pick_x: float
    home: tuple[float, float]
    width: float
    width_est: float
    mass: float
    clutter_x: float
    n_slips: int
    slip_z: tuple[float, ...]


@dataclass
class SlipState:
    """The simulated world (hidden state included).

    Attributes:
        arm_x, arm_z: the fingertips [m].
        grip: the gripper's opening [fraction of the stroke].
        ext: the drawer's extension [m].
        obj_x, obj_z: the object's centre [m].
        holder: where the object is.
        between: the object is between the fingers.
        tries: grasps so far (try ``k`` slips iff ``k <= n_slips``).
        object_x: where the object was last seen on the table [m] (a feature).
        failure: what went wrong for good, ``""`` if nothing.
        slips: the fingertip heights [m] at which the object slipped, in order.
    """

    arm_x: float
    arm_z: float
    grip: float
    ext: float
    obj_x: float
    obj_z: float
    holder: Holder = "table"
    between: bool = False
    tries: int = 0
    object_x: float = 0.0
    failure: Failure = ""
    slips: list[float] = field(default_factory=list)


@dataclass
class SlipTask:
    """The slip task's options (see the module doc); every field is a task option.

    Attributes:
        dt: control period [s] and the demonstrations' sample period.
        max_time: episode time limit [s].
        gain_arm, gain_gripper, gain_drawer: attractor gains K [1/s].
        tolerance: the demonstrator's arrival guards [m]; also how shut the drawer must be.
        goal_tolerance: how close to home [m] the arm must be at the goal.
        max_slips: most tries that slip in one episode (0 to 3).
        slip_low, slip_high: range [m] of the hidden slip heights (fingertip ``z``).
        drop_limit: an object survives a fall of at most this height [m].
        width_noise: std of ``width_est`` around the width [fraction of the stroke].
        start_jitter: half-width [m] of the uniform jitter of the arm's home per axis.
    """

    dt: float = 0.01
    max_time: float = 30.0
    gain_arm: float = 3.0
    gain_gripper: float = 6.0
    gain_drawer: float = 2.5
    tolerance: float = 0.02
    goal_tolerance: float = 0.05
    max_slips: int = 2
    slip_low: float = 0.15
    slip_high: float = 0.35
    drop_limit: float = 0.45
    width_noise: float = 0.05
    start_jitter: float = 0.05

    def __post_init__(self) -> None:
        cls = type(self).__name__
        for option in fields(SlipTask):
            finite_number(getattr(self, option.name), f"{cls}.{option.name}")
        positive = "dt max_time gain_arm gain_gripper gain_drawer tolerance goal_tolerance"
        for name in positive.split():
            if getattr(self, name) <= 0:
                raise ConfigError(f"{cls}.{name} must be > 0, got {getattr(self, name)}")
        gain = max(self.gain_arm, self.gain_gripper, self.gain_drawer)
        if self.dt * gain >= 1.0:
            raise ConfigError(
                f"{cls}: dt * gain must be < 1 for stable Euler steps, got dt={self.dt} with "
                f"the largest gain {gain}; lower dt or the gains"
            )
        if self.max_time < 10 * self.dt:
            raise ConfigError(f"{cls}.max_time must be >= 10 dt, got {self.max_time}")
        if not self.tolerance < min(self.goal_tolerance, CONTACT_RADIUS):
            raise ConfigError(
                f"{cls}.tolerance ({self.tolerance}) must be < goal_tolerance "
                f"({self.goal_tolerance}) and < {CONTACT_RADIUS} (the fingers reach around the "
                "object only that close)"
            )
        if not isinstance(self.max_slips, int) or not 0 <= self.max_slips <= 3:
            raise ConfigError(f"{cls}.max_slips must be an integer in [0, 3], got {self.max_slips}")
        if not GRASP_Z + self.tolerance < self.slip_low <= self.slip_high < CARRY_Z - 0.1:
            raise ConfigError(
                f"{cls} needs {GRASP_Z + self.tolerance:g} < slip_low <= slip_high < "
                f"{CARRY_Z - 0.1:g} (slips happen during lift, below the carry height), got "
                f"slip_low={self.slip_low}, slip_high={self.slip_high}"
            )
        if not PLACE_CLEARANCE + self.tolerance < self.drop_limit < CARRY_Z - GRASP_Z:
            raise ConfigError(
                f"{cls}.drop_limit must be in ({PLACE_CLEARANCE + self.tolerance:g}, "
                f"{CARRY_Z - GRASP_Z:g}) m (a placed object survives its fall, one let go at "
                f"the carry height does not), got {self.drop_limit}"
            )
        if self.slip_high - GRASP_Z >= self.drop_limit:
            raise ConfigError(
                f"{cls}: a slip from slip_high ({self.slip_high}) must fall less than "
                f"drop_limit ({self.drop_limit}), or a slipped object breaks"
            )
        if not 0.0 <= self.width_noise <= 0.2:
            raise ConfigError(f"{cls}.width_noise must be in [0, 0.2], got {self.width_noise}")
        if not 0.0 <= self.start_jitter <= 0.1:
            raise ConfigError(f"{cls}.start_jitter must be in [0, 0.1] m, got {self.start_jitter}")

    # ----------------------------------------------------------------------------- contexts
    def sample_context(
        self, rng: np.random.Generator, strategy: str, n_slips: int | None = None
    ) -> SlipContext:
        """One random context of ``strategy``.

        The draws are the same whatever ``n_slips`` is (the geometry does not depend on it).

        Args:
            rng: the random numbers.
            strategy: one of :data:`STRATEGIES`.
            n_slips: fixes the slip count in ``[0, max_slips]`` (default: uniform).

        Returns:
            The context.

        Raises:
            ConfigError: an unknown strategy or a slip count out of range.
        """
        if strategy not in STRATEGIES:
            raise ConfigError(f"strategy must be one of {STRATEGIES}, got {strategy!r}")
        drawn = int(rng.integers(self.max_slips + 1))
        if n_slips is None:
            n_slips = drawn
        if isinstance(n_slips, bool) or not isinstance(n_slips, int):
            raise ConfigError(f"n_slips must be an integer, got {n_slips!r}")
        if not 0 <= n_slips <= self.max_slips:
            raise ConfigError(f"n_slips must be in [0, max_slips={self.max_slips}], got {n_slips}")
        shelf = "high" if strategy.endswith("high") else "low"
        j = self.start_jitter
        width = float(rng.uniform(*WIDTH))
        return SlipContext(
            strategy=strategy,
            drawer_open=strategy.startswith("open"),
            shelf_z=float(rng.uniform(*SHELF_Z[shelf])),
            pick_x=float(rng.uniform(*PICK_X)),
            home=(HOME[0] + float(rng.uniform(-j, j)), HOME[1] + float(rng.uniform(-j, j))),
            width=width,
            width_est=width + self.width_noise * float(rng.standard_normal()),
            mass=float(rng.uniform(*MASS)),
            clutter_x=float(rng.uniform(*CLUTTER_X)),
            n_slips=n_slips,
            slip_z=tuple(float(z) for z in rng.uniform(self.slip_low, self.slip_high, 3))[
                : self.max_slips
            ],
        )

    def initial_mps(self, context: SlipContext) -> dict[str, str]:
        """The demonstrator's initial MP per variable: the drawer's follows its start state."""
        drawer = "hold_open" if context.drawer_open else "pull_open"
        return {"arm": "reach", "gripper": "open", "drawer": drawer}

    def expected_sequences(self, context: SlipContext) -> dict[str, list[str]]:
        """The MPs the demonstrator runs for ``context``, per variable, in order."""
        k = context.n_slips
        drawer = ["hold_open"] if context.drawer_open else ["pull_open", "hold_open"]
        return {
            "arm": ["reach", *(["lift", "lower"] * k), "lift", "place", "retreat"],
            "gripper": [*(["open", "close"] * (k + 1)), "release"],
            "drawer": [*drawer, "push_shut"],
        }

    def initial_state(self, context: SlipContext) -> SlipState:
        """The arm home, the gripper open, the object on the table, the drawer as the context."""
        return SlipState(
            arm_x=context.home[0],
            arm_z=context.home[1],
            grip=1.0,
            ext=OPEN_EXT if context.drawer_open else 0.0,
            obj_x=context.pick_x,
            obj_z=GRASP_Z,
            object_x=context.pick_x,
        )

    def features(self, state: SlipState, context: SlipContext) -> np.ndarray:
        """Feature vector ``(10,)`` in :data:`FEATURE_NAMES` order."""
        return np.array(
            [
                state.arm_x,
                state.arm_z,
                state.grip,
                1.0 if state.holder == "hand" else 0.0,
                state.object_x,
                state.ext,
                context.shelf_z,
                context.mass if state.holder == "drawer" else 0.0,
                context.width_est,
                context.clutter_x,
            ]
        )

    # ----------------------------------------------------------------------------- dynamics
    def goals(
        self, state: SlipState, context: SlipContext, active: Mapping[str, str]
    ) -> tuple[float, float, float, float]:
        """Attractor goals of the active MPs: arm ``x``, arm ``z`` [m], opening, extension [m].

        Raises:
            UnknownMPError: a variable's MP is not one of :data:`MPS`.
        """
        for v in VARIABLES:
            if active.get(v) not in MPS[v]:
                raise UnknownMPError(
                    f"{v}: unknown MP {active.get(v)!r}; the slip task knows {MPS[v]}"
                )
        arm = active["arm"]
        if arm in ("reach", "lower"):
            gx, gz = state.object_x, GRASP_Z
        elif arm == "lift":
            gx, gz = state.object_x, CARRY_Z
        elif arm == "place":
            gx, gz = DRAWER_X, context.shelf_z + PLACE_CLEARANCE
        else:
            gx, gz = context.home
        grip = 0.0 if active["gripper"] == "close" else 1.0
        ext = 0.0 if active["drawer"] == "push_shut" else OPEN_EXT
        return gx, gz, grip, ext

    def check_step(self, h: float) -> float:
        """``h`` [s] as a float if it is a stable Euler step of this task.

        Raises:
            ConfigError: ``h`` is not positive, or ``h * gain >= 1`` for some gain.
        """
        step = finite_number(h, "SlipTask step h")
        gain = max(self.gain_arm, self.gain_gripper, self.gain_drawer)
        if step <= 0 or step * gain >= 1.0:
            raise ConfigError(
                f"SlipTask: a step must be > 0 with h * gain < 1 for stable Euler steps, got "
                f"h={step} with the largest gain {gain}"
            )
        return step

    def advance(
        self,
        state: SlipState,
        context: SlipContext,
        active: Mapping[str, str],
        dt: float | None = None,
    ) -> None:
        """One Euler step under the ``active`` MPs (modifies ``state``).

        Args:
            state: the world, advanced in place.
            context: the episode.
            active: variable -> MP during the step.
            dt: the step [s]; default the task's ``dt`` (another is checked for stability).
        """
        h = self.dt if dt is None else self.check_step(dt)
        gx, gz, gg, ge = self.goals(state, context, active)
        state.arm_x += h * self.gain_arm * (gx - state.arm_x)
        state.arm_z += h * self.gain_arm * (gz - state.arm_z)
        state.ext += h * self.gain_drawer * (ge - state.ext)
        grip = state.grip + h * self.gain_gripper * (gg - state.grip)
        if state.failure:
            state.grip = grip
            return
        if state.holder == "hand":
            state.obj_x, state.obj_z = state.arm_x, state.arm_z
            if grip > context.width:  # the fingers open past the object: it falls
                state.grip = grip
                self._drop(state, context)
            else:
                state.grip = max(grip, context.width)  # the object stops the fingers
                if (
                    state.tries <= context.n_slips
                    and state.arm_z >= context.slip_z[state.tries - 1]
                ):
                    state.slips.append(state.arm_z)
                    state.grip = grip  # the grip fails: the fingers close on past the width
                    self._drop(state, context)
        else:
            near = math.hypot(state.arm_x - state.obj_x, state.arm_z - state.obj_z)
            if state.holder != "table" or near >= CONTACT_RADIUS:
                state.between = False
            elif state.grip >= context.width:
                state.between = True
            if state.between and grip <= context.width:
                grip = context.width
                state.holder = "hand"
                state.tries += 1
                state.obj_x, state.obj_z = state.arm_x, state.arm_z
            state.grip = grip
        if self.in_mouth(state.arm_x, state.arm_z, context) and state.ext < OPEN_EXT / 2:
            state.failure = "hit"

    @staticmethod
    def in_mouth(x: float, z: float, context: SlipContext) -> bool:
        """Whether the point ``(x, z)`` [m] is in the drawer's mouth."""
        dz = z - context.shelf_z
        return abs(x - DRAWER_X) < MOUTH_HALF_X and MOUTH_Z[0] <= dz <= MOUTH_Z[1]

    def _drop(self, state: SlipState, context: SlipContext) -> None:
        """The object leaves the hand at the fingertips and falls straight down."""
        x, z = state.arm_x, state.arm_z
        state.between = False
        if self.in_mouth(x, z, context) and state.ext >= OPEN_EXT / 2:
            state.holder = "drawer"
            state.obj_x, state.obj_z = x, context.shelf_z + GRASP_Z
        elif x <= TABLE_EDGE and z - GRASP_Z <= self.drop_limit:
            state.holder = "table"
            state.obj_x, state.obj_z = x, GRASP_Z
            state.object_x = x
        else:
            state.holder = "broken" if x <= TABLE_EDGE else "lost"
            state.failure = state.holder

    def shortfall(self, state: SlipState, context: SlipContext) -> str:
        """Why ``state`` is not the goal state, in words (``""`` at the goal).

        The failure nothing undoes if one happened, else each goal condition not met.
        """
        failures = {
            "broken": "the object fell from too high onto the table and broke",
            "lost": "the object fell beside the table and is lost",
            "hit": "the arm hit the cabinet front (in the drawer's mouth, the drawer not open)",
        }
        if state.failure:
            return failures[state.failure]
        unmet = []
        if state.holder != "drawer":
            unmet.append(f"the object is not in the drawer (it is {_WHERE[state.holder]})")
        if state.ext >= self.tolerance:
            unmet.append("the drawer is not shut")
        if state.grip < OPEN_READY:
            unmet.append("the gripper is not open")
        away = math.hypot(state.arm_x - context.home[0], state.arm_z - context.home[1])
        if away >= self.goal_tolerance:
            unmet.append("the arm is not home")
        return "; ".join(unmet)

    def at_goal(self, state: SlipState, context: SlipContext) -> bool:
        """Object in the shut drawer, gripper open, arm home (see the module doc)."""
        return (
            not state.failure
            and state.holder == "drawer"
            and state.ext < self.tolerance
            and state.grip >= OPEN_READY
            and math.hypot(state.arm_x - context.home[0], state.arm_z - context.home[1])
            < self.goal_tolerance
        )


_WHERE = {"table": "on the table", "hand": "in the hand", "drawer": "in the drawer"}
"""Where the object is, in words (the failures have their own text)."""

_KEEPS_GOAL = {"arm": ("retreat",), "gripper": ("open", "release"), "drawer": ("push_shut",)}
"""The MPs that hold the goal state."""


class SlipRun:
    """One episode of the slip task in progress (a :class:`~cpmp.worlds.protocol.WorldRun`).

    Its ``t`` is the time run so far and ``failed_at`` when the object broke or was lost or
    the arm hit the drawer [s] (``None``: nothing failed).

    Args:
        task: the task's options.
        context: the episode.
    """

    def __init__(self, task: SlipTask, context: SlipContext) -> None:
        self.task = task
        self.context = context
        self.state = task.initial_state(context)
        self.t = 0.0
        self.failed_at: float | None = None

    def features(self) -> np.ndarray:
        """The features ``(10,)`` now."""
        return self.task.features(self.state, self.context)

    def advance(self, active: Mapping[str, str], h: float) -> None:
        """Run the ``active`` MPs for ``h`` [s], in sub-steps of at most ``dt``."""
        n, step = substeps(h, self.task.dt)
        for _ in range(n):
            self.task.advance(self.state, self.context, active, step)
            self.t = round(self.t + step, 10)
            if self.failed_at is None and self.state.failure:
                self.failed_at = self.t

    def failure(self) -> str:
        """Why the run is not complete, in words (:meth:`SlipTask.shortfall`, with the time)."""
        return failure_text(self.task.shortfall(self.state, self.context), self.failed_at)

    def done(self, active: Mapping[str, str]) -> bool:
        """The goal reached, or a failure (object broken or lost, arm hit the drawer)."""
        return bool(self.state.failure) or self.complete(active)

    def complete(self, active: Mapping[str, str]) -> bool:
        """The goal state reached, held by the ``active`` MPs."""
        keeps = all(active.get(v) in mps for v, mps in _KEEPS_GOAL.items())
        return keeps and self.task.at_goal(self.state, self.context)
