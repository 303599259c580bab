"""A second synthetic concurrent task: a hand-over ("relay") in the plane.

Independent of :mod:`cpmp.synthetic` (two points on a line), to check the sequencer on a task it
was not tuned for. A *carrier* brings an object, a *receiver* takes it with its *gripper* and
delivers it. Three control variables, all first-order attractors ``ṗ = K (g - p)``:

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

The scripted demonstrator (a finite state machine) switches as soon as a guard holds, with no
settle time:

* gripper ``open -> close``: carrier within ``tolerance`` of its goal and receiver within
  ``tolerance`` of the object; ``close -> hold``: grip force >= ``contact_force`` (``close``
  would settle at ``light_force``); ``hold -> release``: receiver within ``tolerance`` of the
  destination.
* carrier ``carry/present -> retreat`` and receiver ``approach -> withdraw/stow``: the gripper
  was holding at the previous tick (they feel the receiver take the object); carrier ``retreat
  -> rest``: within ``tolerance`` of home.

The synchronisation the features alone leave ambiguous: once the gripper starts closing, its
fingers travel for about 0.3 s before they touch the object, and no feature moves meanwhile.
That state lies far along ``carry``/``present`` and ``approach`` in feature space (both hands
have arrived; only a small rise of the force is left) and close to where ``retreat`` and
``withdraw``/``stow`` start, so graphs coupled only through the features (sequencer option
``coupling="none"``) fire them during the pause: the object leaves with the carrier, or the
receiver leaves without it, and the task cannot complete. The labels tell the difference: those
switches were only demonstrated while the gripper was in ``hold``, which the learned coupling
(``coupling="context"``) requires.

The object moves with its holder: the carrier until the receiver grips it (force >=
``grip_force``), then the receiver until the force drops again (it is released where it is).
Fingers that are already closed cannot get around the object. The goal state: the object
released within ``goal_tolerance`` of its strategy's destination, the gripper open (``a >=
0.9``) and the carrier within ``goal_tolerance`` of home.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from cpmp.data import Demonstration, DemonstrationLog
from cpmp.errors import ConfigError, UnknownMPError
from cpmp.records import Policy

FEATURE_NAMES = ["carrier_x", "carrier_y", "receiver_x", "receiver_y", "grip_force", "context"]
VARIABLES = ["carrier", "gripper", "receiver"]
STRATEGIES = ("meet", "fetch")
OUTCOMES = ("complete", "wrong_start", "incomplete")

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

_CARRIER_OUT = ("carry", "present")
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
    def strategy(self) -> str:
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
    holder: str = "carrier"
    between: bool = False
    force: float = 0.0


@dataclass
class RolloutResult:
    """One closed-loop execution.

    Attributes:
        outcome: ``wrong_start`` (initial MPs differ from the demonstrator's), ``incomplete``
            (goal state not reached within ``max_time``) or ``complete``.
        sequences: variable -> executed MPs in order.
        time: time [s] the goal state was reached, or the time the episode stopped.
        initial: the policy's initial MPs; ``expected_initial``: the demonstrator's.
        reached_goal: whether the goal state was reached (also after a wrong start).
        strategy: the episode's strategy.
    """

    outcome: str
    sequences: dict[str, list[str]]
    time: float
    initial: dict[str, str]
    expected_initial: dict[str, str]
    reached_goal: bool
    strategy: str


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
        for name in (
            "gain_carrier",
            "gain_receiver",
            "gain_gripper",
            "dt",
            "tolerance",
            "object_width",
            "grip_force",
            "contact_force",
            "light_force",
            "contact_radius",
            "start_jitter",
            "goal_jitter",
            "context_gap",
            "goal_tolerance",
            "max_time",
        ):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise ConfigError(f"RelayTask.{name} must be a number, got {value!r}")
            if not math.isfinite(value):
                raise ConfigError(f"RelayTask.{name} must be finite, got {value}")
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
        strategy: str | None = None,
        context: float | None = None,
    ) -> RelayEpisode:
        """Random homes, goals and context for one episode.

        ``strategy`` (``meet``/``fetch``, default: either with probability 1/2) draws the
        context uniformly from its half of [0, 1] minus the gap; ``context`` fixes it instead.
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
    def goals(
        self, state: RelayState, episode: RelayEpisode, active: dict[str, str]
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

    def advance(self, state: RelayState, episode: RelayEpisode, active: dict[str, str]) -> None:
        """One Euler step of ``dt`` under the ``active`` MPs (modifies ``state``)."""
        gc, gr, ga = self.goals(state, episode, active)
        before = {"carrier": state.carrier.copy(), "receiver": state.receiver.copy()}
        state.carrier = state.carrier + self.dt * self.gain_carrier * (gc - state.carrier)
        state.receiver = state.receiver + self.dt * self.gain_receiver * (gr - state.receiver)
        state.aperture += self.dt * self.gain_gripper * (ga - state.aperture)
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

    def at_goal(self, state: RelayState, episode: RelayEpisode) -> bool:
        """Object released at its destination, gripper open, carrier home."""
        tol = self.goal_tolerance
        return bool(
            state.holder == "none"
            and np.linalg.norm(state.obj - episode.destination) < tol
            and state.aperture >= OPEN_APERTURE
            and np.linalg.norm(state.carrier - episode.carrier_home) < tol
        )

    # ----------------------------------------------------------------------------- demonstrator
    def script(
        self, x: np.ndarray, episode: RelayEpisode, active: dict[str, str]
    ) -> dict[str, str]:
        """The demonstrator's switches from features ``x (6,)`` and the current MPs ``active``.

        Guards on other variables' MPs read ``active`` (this tick's labels), so such a switch
        comes one tick after the one it waits for.
        """
        carrier, receiver, force = x[0:2], x[2:4], x[4]
        tol = self.tolerance
        new = dict(active)
        if active["gripper"] == "open" and active["carrier"] in _CARRIER_OUT:
            goal = episode.meeting_point if active["carrier"] == "carry" else episode.present_point
            if np.linalg.norm(carrier - goal) < tol and np.linalg.norm(receiver - carrier) < tol:
                new["gripper"] = "close"
        if active["gripper"] == "close" and force >= self.contact_force:
            new["gripper"] = "hold"
        if active["carrier"] == "retreat" and np.linalg.norm(carrier - episode.carrier_home) < tol:
            new["carrier"] = "rest"
        if active["gripper"] == "hold":
            if active["carrier"] in _CARRIER_OUT:
                new["carrier"] = "retreat"
            if active["receiver"] == "approach":
                new["receiver"] = "withdraw" if episode.strategy == "meet" else "stow"
            if (
                active["receiver"] in ("withdraw", "stow")
                and np.linalg.norm(receiver - episode.destination) < tol
            ):
                new["gripper"] = "release"
        return new

    def demonstrate(self, episode: RelayEpisode, name: str | None = None) -> Demonstration:
        """The scripted demonstrator's labelled demonstration of ``episode``, recorded every
        ``dt`` from ``t = 0`` until the goal state is reached (or ``max_time``)."""
        state = self.initial_state(episode)
        active = self.initial_mps(episode)
        log = DemonstrationLog(VARIABLES)
        t = 0.0
        while True:
            x = self.features(state, episode)
            log.append(t, x, active)
            if self.at_goal(state, episode) or t >= self.max_time:
                break
            active = self.script(x, episode, active)
            self.advance(state, episode, active)
            t = round(t + self.dt, 10)
        metadata = {
            "task": "relay",
            "context": episode.context,
            "strategy": episode.strategy,
            "reached_goal": self.at_goal(state, episode),
        }
        return log.to_demonstration(FEATURE_NAMES, name, metadata)

    def scripted_policy(self, episode: RelayEpisode) -> ScriptedPolicy:
        """The demonstrator as a closed-loop policy for ``episode``."""
        return ScriptedPolicy(self, episode)

    # ----------------------------------------------------------------------------- closed loop
    def rollout(
        self,
        episode: RelayEpisode,
        policy: Policy,
        observe: Callable[[np.ndarray], np.ndarray] | None = None,
    ) -> RolloutResult:
        """Run ``policy`` closed-loop on ``episode`` until the goal state or ``max_time``.

        ``observe`` maps the true features ``(6,)`` to what the policy sees (e.g. observation
        noise with :func:`cpmp.augment.noisy_features`); default: the true features.
        """
        see = observe or (lambda x: x)
        state = self.initial_state(episode)
        expected = self.initial_mps(episode)
        active = dict(policy.reset(0.0, see(self.features(state, episode))))
        initial = dict(active)
        seqs = {v: [active[v]] for v in VARIABLES}
        t = 0.0
        reached = self.at_goal(state, episode)
        while not reached and t < self.max_time - 1e-9:
            self.advance(state, episode, active)
            t = round(t + self.dt, 10)
            active = dict(policy.step(t, see(self.features(state, episode))))
            for v in VARIABLES:
                if active[v] != seqs[v][-1]:
                    seqs[v].append(active[v])
            reached = self.at_goal(state, episode)
        if initial != expected:
            outcome = "wrong_start"
        else:
            outcome = "complete" if reached else "incomplete"
        return RolloutResult(outcome, seqs, t, initial, expected, reached, episode.strategy)


class ScriptedPolicy:
    """The demonstrator's finite state machine behind the :class:`~cpmp.records.Policy`
    interface (it knows the episode's goals, as the demonstrator does)."""

    def __init__(self, task: RelayTask, episode: RelayEpisode) -> None:
        self.task = task
        self.episode = episode
        self.active: dict[str, str] = {}

    def reset(self, t: float, x: np.ndarray) -> dict[str, str]:
        self.active = self.task.initial_mps(self.episode)
        return dict(self.active)

    def step(self, t: float, x: np.ndarray) -> dict[str, str]:
        self.active = self.task.script(np.asarray(x, float), self.episode, self.active)
        return dict(self.active)


def make_demonstrations(
    n: int, seed: int = 0, task: RelayTask | None = None
) -> list[Demonstration]:
    """``n`` demonstrations alternating meet and fetch (``demo_0`` meet), reproducible from
    ``seed``."""
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise ConfigError(f"n must be a positive integer, got {n!r}")
    task = task or RelayTask()
    rng = np.random.default_rng(seed)
    return [
        task.demonstrate(task.sample_episode(rng, STRATEGIES[i % 2]), name=f"demo_{i}")
        for i in range(n)
    ]


def evaluate(
    seq: Policy,
    task: RelayTask | None = None,
    n_episodes: int = 20,
    seed: int = 0,
    observe: Callable[[np.ndarray], np.ndarray] | None = None,
) -> dict[str, Any]:
    """Closed-loop outcomes of a sequencer (or any policy) ``seq`` on ``n_episodes`` random
    episodes alternating the strategies, reproducible from ``seed`` (use a seed other than the
    demonstrations' for held-out episodes; ``observe`` as in :meth:`RelayTask.rollout`).

    Returns ``{"complete": int, "wrong_start": int, "incomplete": int, "n_episodes": int,
    "per_episode": [{"strategy", "context", "outcome", "time", "sequences"}, ...]}``.
    """
    if isinstance(n_episodes, bool) or not isinstance(n_episodes, int) or n_episodes < 1:
        raise ConfigError(f"n_episodes must be a positive integer, got {n_episodes!r}")
    task = task or RelayTask()
    rng = np.random.default_rng(seed)
    episodes = [task.sample_episode(rng, STRATEGIES[i % 2]) for i in range(n_episodes)]
    results = [task.rollout(episode, seq, observe) for episode in episodes]
    rows = [
        {
            "strategy": r.strategy,
            "context": e.context,
            "outcome": r.outcome,
            "time": r.time,
            "sequences": r.sequences,
        }
        for e, r in zip(episodes, results, strict=True)
    ]
    return {**outcome_counts(results), "n_episodes": n_episodes, "per_episode": rows}


def outcome_counts(results: Sequence[RolloutResult]) -> dict[str, int]:
    """Number of results per outcome (every outcome present)."""
    counts = dict.fromkeys(OUTCOMES, 0)
    for r in results:
        counts[r.outcome] += 1
    return counts


__all__ = [
    "FEATURE_NAMES",
    "OUTCOMES",
    "STRATEGIES",
    "VARIABLES",
    "RelayEpisode",
    "RelayState",
    "RelayTask",
    "RolloutResult",
    "ScriptedPolicy",
    "evaluate",
    "make_demonstrations",
    "outcome_counts",
]
