"""A second synthetic concurrent task: a hand-over ("relay") in the plane.

Independent of :mod:`cpmp.worlds.two_point` (two points on a line), to check the sequencer on a
task it was not tuned for. A *carrier* brings an object, a *receiver* takes it with its *gripper*
and delivers it. Three control variables, all first-order attractors ``ṗ = K (g - p)``:

* ``carrier`` (a point in the plane): ``carry`` (to the meeting point) or ``present`` (to a
  point near its home), then ``retreat`` (back home), then ``rest`` (stay home). Two initial
  nodes that merge into ``retreat``.
* ``receiver`` (a point in the plane): ``approach`` (reach for the object, wherever it is), then
  ``withdraw`` (to the shelf) or ``stow`` (to the bin). A branch, decided by the context.
* ``gripper`` (the receiver's aperture ``a``, 1 = open; not a feature): ``open`` (a -> 1) ->
  ``close`` (to a light grip) -> ``hold`` (squeeze, a -> 0) -> ``release`` (a -> 1).

A context ``c`` in [0, 1] selects the strategy: ``c < 0.5`` *meet* (the carrier carries the
object to the meeting point, the receiver delivers it to the shelf), ``c >= 0.5`` *fetch* (the
carrier only presents it near its home, the receiver fetches it and stows it in the bin).

Features ``x = [carrier_x, carrier_y, receiver_x, receiver_y, grip_force, context]``: positions
in metres on a table about 2 m wide; the grip force in [0, 1] as a force sensor between the
receiver's fingers reads it (0 until the closing fingers touch the object, ``a <
object_width``, then rising as they squeeze); the context feature is ``CONTEXT_SCALE * c``, in
[0, 2] like the positions (the paper scales its features to similar ranges).

The object moves with its holder: the carrier until the receiver grips it (force >=
``grip_force``), then the receiver until the force drops again (it is released where it is).
Fingers that are already closed cannot get around the object. The goal state: the object
released within ``goal_tolerance`` of its strategy's destination, the gripper open (``a >=
0.9``) and the carrier within ``goal_tolerance`` of home.

The scripted demonstrator is :mod:`cpmp.worlds.relay.demonstrator`; closed-loop runs and
their outcomes are :mod:`cpmp.worlds.relay.evaluation`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from typing import Literal, get_args

import numpy as np

from cpmp.config.validation import finite_number
from cpmp.errors import ConfigError, UnknownMPError

FEATURE_NAMES = ["carrier_x", "carrier_y", "receiver_x", "receiver_y", "grip_force", "context"]
VARIABLES = ["carrier", "gripper", "receiver"]
Strategy = Literal["meet", "fetch"]
"""The two strategies: the carrier meets the receiver, or the receiver fetches the object."""
STRATEGIES: tuple[Strategy, ...] = get_args(Strategy)
Holder = Literal["carrier", "receiver", "none"]
"""What moves the object: the carrier, the receiver's gripper, or nothing (released)."""

CARRIER_HOME = (0.0, 0.0)
RECEIVER_HOME = (2.0, 0.0)
MEETING_POINT = (1.0, 0.9)
PRESENT_OFFSET = (0.3, -0.35)
"""Present point relative to the carrier's home."""
SHELF = (2.0, 1.4)
BIN = (1.2, -0.6)
OPEN_APERTURE = 0.9
"""The gripper counts as open at the goal from this aperture on."""
CONTEXT_SCALE = 2.0
"""The context feature is ``CONTEXT_SCALE * c`` (the positions' range)."""
_MPS = {
    "carrier": ("carry", "present", "retreat", "rest"),
    "gripper": ("open", "close", "hold", "release"),
    "receiver": ("approach", "withdraw", "stow"),
}


@dataclass(eq=False)
class RelayEpisode:
    """The random parameters of one episode (positions in m).

    Attributes:
        context: ``c`` in [0, 1]; ``< 0.5`` meet, ``>= 0.5`` fetch (the feature is
            ``CONTEXT_SCALE * c``).
        carrier_home, receiver_home: (2,) start positions.
        meeting_point: (2,) goal of ``carry``.
        shelf, bin: (2,) goals of ``withdraw`` and ``stow``.
    """

    context: float
    carrier_home: np.ndarray
    receiver_home: np.ndarray
    meeting_point: np.ndarray
    shelf: np.ndarray
    bin: np.ndarray

    @property
    def strategy(self) -> Strategy:
        """``meet`` or ``fetch``."""
        return "meet" if self.context < 0.5 else "fetch"

    @property
    def present_point(self) -> np.ndarray:
        """(2,) goal of ``present``: near the carrier's home."""
        return self.carrier_home + np.asarray(PRESENT_OFFSET)

    @property
    def destination(self) -> np.ndarray:
        """(2,) where the object must end up: the shelf (meet) or the bin (fetch)."""
        return self.shelf if self.strategy == "meet" else self.bin


@dataclass
class RelayState:
    """The simulated world (hidden state included).

    Attributes:
        carrier, receiver: (2,) positions.
        aperture: gripper opening (1 = open, 0 = closed; not a feature).
        obj: (2,) object position.
        holder: ``carrier``, ``receiver`` or ``none``.
        between: the object is between the receiver's fingers.
        force: grip force in [0, 1] (a feature).
    """

    carrier: np.ndarray
    receiver: np.ndarray
    aperture: float = 1.0
    obj: np.ndarray = field(default_factory=lambda: np.zeros(2))
    holder: Holder = "carrier"
    between: bool = False
    force: float = 0.0


@dataclass
class RelayTask:
    """The hand-over task (see module doc).

    Attributes:
        gain_carrier, gain_receiver, gain_gripper: attractor gains K [1/s].
        dt: control period [s].
        tolerance: the demonstrator's position guards [m].
        object_width: aperture at which the fingers touch the object, in (0, 1).
        grip_force: force in (0, 1) from which the receiver holds the object.
        contact_force: force of the demonstrator's ``close -> hold`` guard, in [grip_force,
            light_force).
        light_force: the force ``close`` settles at (its aperture goal), below 1; ``hold``
            squeezes on to 1.
        contact_radius: the object is between the fingers when the receiver is this close [m].
        start_jitter: half-width of the uniform jitter of both homes per axis [m].
        goal_jitter: half-width of the uniform jitter of meeting point, shelf and bin [m].
        context_gap: contexts are drawn at least ``context_gap / 2`` from the 0.5 boundary.
        goal_tolerance: the goal state's position tolerance [m].
        max_time: episode time limit [s].
    """

    gain_carrier: float = 4.0
    gain_receiver: float = 3.0
    gain_gripper: float = 4.0
    dt: float = 0.01
    tolerance: float = 0.03
    object_width: float = 0.4
    grip_force: float = 0.25
    contact_force: float = 0.3
    light_force: float = 0.35
    contact_radius: float = 0.1
    start_jitter: float = 0.1
    goal_jitter: float = 0.1
    context_gap: float = 0.1
    goal_tolerance: float = 0.1
    max_time: float = 10.0

    def __post_init__(self) -> None:
        for option in fields(self):
            finite_number(getattr(self, option.name), f"RelayTask.{option.name}")
        for name in ("gain_carrier", "gain_receiver", "gain_gripper", "dt", "tolerance"):
            if getattr(self, name) <= 0:
                raise ConfigError(f"RelayTask.{name} must be > 0, got {getattr(self, name)}")
        if self.dt * max(self.gain_carrier, self.gain_receiver, self.gain_gripper) >= 1.0:
            raise ConfigError(
                f"RelayTask: dt * gain must be < 1 for stable Euler steps, got dt={self.dt} "
                "with the largest gain "
                f"{max(self.gain_carrier, self.gain_receiver, self.gain_gripper)}"
            )
        for name in ("object_width", "grip_force"):
            if not 0.0 < getattr(self, name) < 1.0:
                raise ConfigError(f"RelayTask.{name} must be in (0, 1), got {getattr(self, name)}")
        if not self.grip_force <= self.contact_force < self.light_force < 1.0:
            raise ConfigError(
                "RelayTask needs grip_force <= contact_force < light_force < 1, got "
                f"{self.grip_force}, {self.contact_force}, {self.light_force}"
            )
        if not self.tolerance < self.contact_radius:
            raise ConfigError(
                f"RelayTask: tolerance ({self.tolerance}) must be < contact_radius "
                f"({self.contact_radius}), or the demonstrator closes before the object is "
                "between the fingers"
            )
        if not self.tolerance < self.goal_tolerance:
            raise ConfigError(
                f"RelayTask: tolerance ({self.tolerance}) must be < goal_tolerance "
                f"({self.goal_tolerance}), or the demonstrator may miss the goal state"
            )
        for name in ("start_jitter", "goal_jitter"):
            if not 0.0 <= getattr(self, name) <= 0.2:
                raise ConfigError(
                    f"RelayTask.{name} must be in [0, 0.2], got {getattr(self, name)}"
                )
        if not 0.0 <= self.context_gap < 1.0:
            raise ConfigError(f"RelayTask.context_gap must be in [0, 1), got {self.context_gap}")
        if self.max_time < 10 * self.dt:
            raise ConfigError(f"RelayTask.max_time must be >= 10 dt, got {self.max_time}")

    # ----------------------------------------------------------------------------- episodes
    def sample_episode(
        self,
        rng: np.random.Generator,
        strategy: Strategy | None = None,
        context: float | None = None,
    ) -> RelayEpisode:
        """Random homes, goals and context for one episode.

        Args:
            rng: the random generator.
            strategy: ``meet`` or ``fetch`` (default: either with probability 1/2); the
                context is drawn uniformly from its half of [0, 1] minus the gap.
            context: fixes the context in [0, 1] instead.

        Returns:
            The episode.

        Raises:
            ConfigError: an unknown strategy or a context outside [0, 1].
        """
        half = 0.5 - self.context_gap / 2
        if context is not None:
            if isinstance(context, bool) or not isinstance(context, (int, float, np.floating)):
                raise ConfigError(f"context must be a number in [0, 1], got {context!r}")
            c = float(context)
            if not 0.0 <= c <= 1.0:
                raise ConfigError(f"context must be a number in [0, 1], got {context!r}")
        else:
            if strategy is None:
                strategy = STRATEGIES[int(rng.integers(2))]
            if strategy not in STRATEGIES:
                raise ConfigError(f"strategy must be one of {STRATEGIES}, got {strategy!r}")
            u = float(rng.uniform(0.0, half))
            c = u if strategy == "meet" else 1.0 - u
        sj, gj = self.start_jitter, self.goal_jitter
        return RelayEpisode(
            context=c,
            carrier_home=np.asarray(CARRIER_HOME) + rng.uniform(-sj, sj, 2),
            receiver_home=np.asarray(RECEIVER_HOME) + rng.uniform(-sj, sj, 2),
            meeting_point=np.asarray(MEETING_POINT) + rng.uniform(-gj, gj, 2),
            shelf=np.asarray(SHELF) + rng.uniform(-gj, gj, 2),
            bin=np.asarray(BIN) + rng.uniform(-gj, gj, 2),
        )

    def initial_mps(self, episode: RelayEpisode) -> dict[str, str]:
        """The demonstrator's initial MP per variable for ``episode``."""
        carrier = "carry" if episode.strategy == "meet" else "present"
        return {"carrier": carrier, "gripper": "open", "receiver": "approach"}

    def initial_state(self, episode: RelayEpisode) -> RelayState:
        """Both at home, gripper open, the object on the carrier."""
        return RelayState(
            carrier=episode.carrier_home.astype(float).copy(),
            receiver=episode.receiver_home.astype(float).copy(),
            obj=episode.carrier_home.astype(float).copy(),
        )

    def features(self, state: RelayState, episode: RelayEpisode) -> np.ndarray:
        """Feature vector ``(6,)`` in :data:`FEATURE_NAMES` order."""
        context = CONTEXT_SCALE * episode.context
        return np.array([*state.carrier, *state.receiver, state.force, context])

    # ----------------------------------------------------------------------------- dynamics
    def check_step(self, dt: float) -> float:
        """``dt`` [s] as a float if it is a stable Euler step of this task.

        Raises:
            ConfigError: ``dt`` is not a positive number with ``dt * gain < 1`` for every gain.
        """
        h = finite_number(dt, "RelayTask step dt")
        gain = max(self.gain_carrier, self.gain_receiver, self.gain_gripper)
        if h <= 0 or h * gain >= 1.0:
            raise ConfigError(
                f"RelayTask: a step dt must be > 0 with dt * gain < 1 for stable Euler steps, "
                f"got dt={h} with the largest gain {gain}"
            )
        return h

    def goals(
        self, state: RelayState, episode: RelayEpisode, active: Mapping[str, str]
    ) -> tuple[np.ndarray, np.ndarray, float]:
        """Attractor goals of the active MPs: carrier (2,), receiver (2,), aperture."""
        for v in VARIABLES:
            if active.get(v) not in _MPS[v]:
                raise UnknownMPError(
                    f"{v}: unknown MP {active.get(v)!r}; the relay task knows {_MPS[v]}"
                )
        carrier = {
            "carry": episode.meeting_point,
            "present": episode.present_point,
            "retreat": episode.carrier_home,
            "rest": episode.carrier_home,
        }[active["carrier"]]
        receiver = {"approach": state.obj, "withdraw": episode.shelf, "stow": episode.bin}[
            active["receiver"]
        ]
        aperture = {
            "open": 1.0,
            "close": self.object_width * (1.0 - self.light_force),
            "hold": 0.0,
            "release": 1.0,
        }[active["gripper"]]
        return np.asarray(carrier, float), np.asarray(receiver, float), aperture

    def advance(
        self,
        state: RelayState,
        episode: RelayEpisode,
        active: Mapping[str, str],
        speed: Mapping[str, float] | None = None,
        dt: float | None = None,
    ) -> None:
        """One Euler step under the ``active`` MPs (modifies ``state``).

        Args:
            state: the state, advanced in place.
            episode: the episode.
            active: variable -> active MP.
            speed: variable -> factor on its attractor gain this step (0: it holds; a variable
                not named, or ``None``: 1); see :mod:`cpmp.worlds.relay.varied`.
            dt: the step [s]; default the task's ``dt`` (another must keep ``dt * gain < 1``).

        Raises:
            ConfigError: a step that is not a stable Euler step of this task.
        """
        h = self.dt if dt is None else self.check_step(dt)
        gc, gr, ga = self.goals(state, episode, active)
        k_carrier, k_receiver, k_gripper = self.gain_carrier, self.gain_receiver, self.gain_gripper
        if speed is not None:
            k_carrier *= speed.get("carrier", 1.0)
            k_receiver *= speed.get("receiver", 1.0)
            k_gripper *= speed.get("gripper", 1.0)
        before = {"carrier": state.carrier.copy(), "receiver": state.receiver.copy()}
        state.carrier = state.carrier + h * k_carrier * (gc - state.carrier)
        state.receiver = state.receiver + h * k_receiver * (gr - state.receiver)
        state.aperture += h * k_gripper * (ga - state.aperture)
        if state.holder in before:
            now = state.carrier if state.holder == "carrier" else state.receiver
            state.obj = state.obj + (now - before[state.holder])
        if np.linalg.norm(state.receiver - state.obj) >= self.contact_radius:
            state.between = False
        elif state.aperture >= self.object_width:
            state.between = True
        w = self.object_width
        state.force = float(np.clip((w - state.aperture) / w, 0.0, 1.0)) if state.between else 0.0
        if state.between and state.force >= self.grip_force:
            if state.holder != "receiver":
                state.obj = state.receiver.copy()  # the fingers centre the object
            state.holder = "receiver"
        elif state.holder == "receiver":
            state.holder = "none"

    def shortfall(self, state: RelayState, episode: RelayEpisode) -> str:
        """Why ``state`` is not the goal state, in words (``""`` at the goal).

        Each goal condition of :meth:`at_goal` not met.
        """
        tol = self.goal_tolerance
        unmet = []
        if state.holder != "none":
            unmet.append(f"the {state.holder} still holds the object")
        off = float(np.linalg.norm(state.obj - episode.destination))
        if off >= tol:
            unmet.append(f"the object is {1000 * off:.0f} mm from its destination")
        if state.aperture < OPEN_APERTURE:
            unmet.append("the gripper is not open")
        away = float(np.linalg.norm(state.carrier - episode.carrier_home))
        if away >= tol:
            unmet.append(f"the carrier is {1000 * away:.0f} mm from home")
        return "; ".join(unmet)

    def at_goal(self, state: RelayState, episode: RelayEpisode) -> bool:
        """Object released at its destination, gripper open, carrier home."""
        tol = self.goal_tolerance
        return bool(
            state.holder == "none"
            and np.linalg.norm(state.obj - episode.destination) < tol
            and state.aperture >= OPEN_APERTURE
            and np.linalg.norm(state.carrier - episode.carrier_home) < tol
        )
