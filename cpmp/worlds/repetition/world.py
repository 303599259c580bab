"""A synthetic task with state-decided repetition: ladling soup into a bowl a helper holds out.

A *ladle* scoops soup from a pot and pours it into a bowl; a *helper* (the waiting variable)
presents the bowl at the pouring spot, holds it there across every pour, and serves it once the
last pour is done. How much soup is needed (``need``, in litres, at most three ladlefuls) is a
continuous quantity of the state and decides how often the ``scoop -> pour`` cycle repeats.
Two control variables, both first-order attractors ``ṗ = K (g - p)`` in the plane:

* ``ladle``: ``scoop`` (to the pot; within ``flow_radius`` of it the ladle fills at
  ``fill_rate`` up to ``min(capacity, remaining)``), ``pour`` (to the spot; within
  ``flow_radius`` of it the ladle empties at ``pour_rate``, into the bowl when the bowl is within
  ``flow_radius`` of the spot too, else onto the floor), again ``scoop`` while soup remains, and
  ``rest`` (home) after the last pour. The cycle ``scoop -> pour -> scoop -> ...`` runs once,
  twice or three times.
* ``bowl`` (the helper's hands): ``present`` (to the pouring spot), ``hold`` (keep it there,
  across every pour), then ``serve`` (to the hatch). It may move on only after the last pour.

The context is the amount: ``need`` in ``[k - 1 + need_margin, k - need_margin] * capacity``
for ``k`` repetitions, the strategies ``once``, ``twice`` and ``thrice``.

Features ``x = [ladle_x, ladle_y, ladle_fill, bowl_x, bowl_y, bowl_level, remaining]``:
positions in metres on a table about 2 m wide; the soup in the ladle, in the bowl (a scale
under it) and still to pour into the bowl (the order less the bowl's level: ``need`` at the
start, 0 when the bowl is full), in litres (the ladle holds ``capacity`` = 1 l by default, so
they share the positions' range). Without ``bowl_level`` the state of the last scoop of three
(ladle full at the pot, bowl in place) would equal the state of a single scoop when the bowl
arrives: the level tells how far the waiting ``hold`` has come.

The goal state: nothing left to pour (``remaining <= AMOUNT_EPS``), the bowl within
``goal_tolerance`` of the hatch and the ladle within ``goal_tolerance`` of its home. Soup spilt
(poured while the bowl was not under the ladle) must be scooped again, so the demonstrated MP
sequences are then not followed.

The scripted demonstrator is :mod:`cpmp.worlds.repetition.demonstrator`; closed-loop runs and
their outcomes are :mod:`cpmp.worlds.repetition.evaluation`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from cpmp.config.validation import finite_number
from cpmp.errors import ConfigError, UnknownMPError

FEATURE_NAMES = ["ladle_x", "ladle_y", "ladle_fill", "bowl_x", "bowl_y", "bowl_level", "remaining"]
VARIABLES = ["bowl", "ladle"]
STRATEGIES = ("once", "twice", "thrice")
"""The strategies, by the number of ``scoop -> pour`` repetitions (1, 2, 3)."""
REPETITIONS = {"once": 1, "twice": 2, "thrice": 3}

LADLE_HOME = (0.0, 0.0)
POT = (0.2, 1.0)
SPOT = (1.0, 0.5)
"""Where the bowl is held out and the ladle pours [m]."""
BOWL_HOME = (2.0, 0.0)
HATCH = (2.0, 1.4)
"""Where the bowl is served [m]."""
AMOUNT_EPS = 1e-9
"""Amounts [l] at or below this count as nothing (floating-point slack)."""
_MPS = {"ladle": ("scoop", "pour", "rest"), "bowl": ("present", "hold", "serve")}


@dataclass(eq=False)
class RepetitionEpisode:
    """The random parameters of one episode (positions in m, amounts in l).

    Attributes:
        need: soup to pour into the bowl [l]; decides the repetitions.
        strategy: ``once``, ``twice`` or ``thrice`` (the repetitions ``need`` asks for).
        ladle_home, bowl_home: (2,) start positions.
        pot, spot, hatch: (2,) goals of ``scoop``, ``pour``/``present``/``hold`` and
            ``serve``.
    """

    need: float
    strategy: str
    ladle_home: np.ndarray
    bowl_home: np.ndarray
    pot: np.ndarray
    spot: np.ndarray
    hatch: np.ndarray

    @property
    def repetitions(self) -> int:
        """Number of ``scoop -> pour`` cycles the demonstrator runs."""
        return REPETITIONS[self.strategy]


@dataclass
class RepetitionState:
    """The simulated world.

    Attributes:
        ladle, bowl: (2,) positions [m].
        fill: soup in the ladle [l].
        need: soup the bowl must hold at the end [l].
        remaining: soup still to pour into the bowl [l].
        spilled: soup poured while the bowl was not under the ladle [l] (not a feature).
    """

    ladle: np.ndarray
    bowl: np.ndarray
    fill: float
    need: float
    remaining: float
    spilled: float = 0.0


@dataclass
class RepetitionTask:
    """The ladling task (see module doc).

    Attributes:
        gain_ladle, gain_bowl: attractor gains K [1/s].
        dt: control period [s] of the demonstrations and of :func:`rollout`
            (:meth:`advance` also takes any other step).
        capacity: what the ladle holds [l].
        fill_rate, pour_rate: how fast the ladle fills at the pot and empties at the spot [l/s].
        flow_radius: the ladle fills or pours within this distance of the pot or spot, into the
            bowl when the bowl is within this distance of the spot too [m].
        tolerance: the demonstrator's guard on the bowl being at the spot [m]; below
            ``flow_radius``.
        need_margin: needs are drawn at least ``need_margin * capacity`` from a whole number
            of ladlefuls, in (0, 0.5).
        start_jitter: half-width of the uniform jitter of both homes per axis [m].
        goal_jitter: half-width of the uniform jitter of pot, spot and hatch per axis [m].
        goal_tolerance: the goal state's position tolerance [m].
        max_time: episode time limit [s].
    """

    gain_ladle: float = 3.0
    gain_bowl: float = 1.5
    dt: float = 0.01
    capacity: float = 1.0
    fill_rate: float = 1.5
    pour_rate: float = 1.5
    flow_radius: float = 0.05
    tolerance: float = 0.03
    need_margin: float = 0.2
    start_jitter: float = 0.1
    goal_jitter: float = 0.1
    goal_tolerance: float = 0.1
    max_time: float = 20.0

    def __post_init__(self) -> None:
        for option in fields(self):
            finite_number(getattr(self, option.name), f"RepetitionTask.{option.name}")
        positive = (
            "gain_ladle gain_bowl dt capacity fill_rate pour_rate flow_radius tolerance "
            "goal_tolerance max_time"
        ).split()
        for name in positive:
            if getattr(self, name) <= 0:
                raise ConfigError(f"RepetitionTask.{name} must be > 0, got {getattr(self, name)}")
        self.check_step(self.dt)
        if not self.tolerance < self.flow_radius:
            raise ConfigError(
                f"RepetitionTask: tolerance ({self.tolerance}) must be < flow_radius "
                f"({self.flow_radius}), or the demonstrator pours before the bowl is in place"
            )
        if not 0.0 < self.need_margin < 0.5:
            raise ConfigError(
                f"RepetitionTask.need_margin must be in (0, 0.5), got {self.need_margin}"
            )
        for name in ("start_jitter", "goal_jitter"):
            if not 0.0 <= getattr(self, name) <= 0.2:
                raise ConfigError(
                    f"RepetitionTask.{name} must be in [0, 0.2], got {getattr(self, name)}"
                )
        if self.max_time < 10 * self.dt:
            raise ConfigError(f"RepetitionTask.max_time must be >= 10 dt, got {self.max_time}")

    def check_step(self, dt: float) -> float:
        """``dt`` [s] as a float if it is a stable Euler step of this task.

        Raises:
            ConfigError: ``dt`` is not a positive number with ``dt * gain < 1`` for both gains.
        """
        h = finite_number(dt, "RepetitionTask step dt")
        gain = max(self.gain_ladle, self.gain_bowl)
        if h <= 0 or h * gain >= 1.0:
            raise ConfigError(
                f"RepetitionTask: a step dt must be > 0 with dt * gain < 1 for stable Euler "
                f"steps, got dt={h} with the largest gain {gain}"
            )
        return h

    # ----------------------------------------------------------------------------- episodes
    def sample_episode(
        self,
        rng: np.random.Generator,
        strategy: str | None = None,
        need: float | None = None,
    ) -> RepetitionEpisode:
        """Random homes, goals and amount for one episode.

        Args:
            rng: the episode's random numbers.
            strategy: ``once``/``twice``/``thrice`` (default: any of them, uniformly) draws
                ``need`` uniformly from its range.
            need: fixes the amount [l] instead, in (0, 3 capacity]; the strategy follows.

        Returns:
            The episode.

        Raises:
            ConfigError: an unknown strategy or an amount out of range.
        """
        cap, margin = self.capacity, self.need_margin
        if need is not None:
            amount = finite_number(need, "need")
            if not 0.0 < amount <= len(STRATEGIES) * cap:
                raise ConfigError(f"need must be in (0, {len(STRATEGIES) * cap:g}] l, got {need!r}")
            strategy = STRATEGIES[math.ceil(amount / cap - AMOUNT_EPS) - 1]
        else:
            if strategy is None:
                strategy = STRATEGIES[int(rng.integers(len(STRATEGIES)))]
            if strategy not in STRATEGIES:
                raise ConfigError(f"strategy must be one of {STRATEGIES}, got {strategy!r}")
            k = REPETITIONS[strategy]
            amount = float(rng.uniform(k - 1 + margin, k - margin)) * cap
        sj, gj = self.start_jitter, self.goal_jitter
        return RepetitionEpisode(
            need=amount,
            strategy=strategy,
            ladle_home=np.asarray(LADLE_HOME) + rng.uniform(-sj, sj, 2),
            bowl_home=np.asarray(BOWL_HOME) + rng.uniform(-sj, sj, 2),
            pot=np.asarray(POT) + rng.uniform(-gj, gj, 2),
            spot=np.asarray(SPOT) + rng.uniform(-gj, gj, 2),
            hatch=np.asarray(HATCH) + rng.uniform(-gj, gj, 2),
        )

    def initial_mps(self, episode: RepetitionEpisode) -> dict[str, str]:
        """The demonstrator's initial MP per variable (the same for every strategy)."""
        return {"bowl": "present", "ladle": "scoop"}

    def expected_sequences(self, episode: RepetitionEpisode) -> dict[str, list[str]]:
        """The MPs the demonstrator runs in ``episode``, per variable, in order."""
        return {
            "bowl": ["present", "hold", "serve"],
            "ladle": ["scoop", "pour"] * episode.repetitions + ["rest"],
        }

    def initial_state(self, episode: RepetitionEpisode) -> RepetitionState:
        """Both at home, the ladle empty, the whole amount still to pour."""
        return RepetitionState(
            ladle=episode.ladle_home.astype(float).copy(),
            bowl=episode.bowl_home.astype(float).copy(),
            fill=0.0,
            need=float(episode.need),
            remaining=float(episode.need),
        )

    def features(
        self, state: RepetitionState, episode: RepetitionEpisode | None = None
    ) -> np.ndarray:
        """Feature vector ``(7,)`` in :data:`FEATURE_NAMES` order (``episode`` is not needed)."""
        level = state.need - state.remaining
        return np.array([*state.ladle, state.fill, *state.bowl, level, state.remaining])

    # ----------------------------------------------------------------------------- dynamics
    def goals(
        self, episode: RepetitionEpisode, active: dict[str, str]
    ) -> tuple[np.ndarray, np.ndarray]:
        """Attractor goals ``(2,)`` of the ladle and the bowl under the ``active`` MPs.

        Raises:
            UnknownMPError: an MP this task does not know.
        """
        for v in VARIABLES:
            if active.get(v) not in _MPS[v]:
                raise UnknownMPError(
                    f"{v}: unknown MP {active.get(v)!r}; the repetition task knows {_MPS[v]}"
                )
        ladle = {"scoop": episode.pot, "pour": episode.spot, "rest": episode.ladle_home}
        bowl = {"present": episode.spot, "hold": episode.spot, "serve": episode.hatch}
        return (
            np.asarray(ladle[active["ladle"]], float),
            np.asarray(bowl[active["bowl"]], float),
        )

    def advance(
        self,
        state: RepetitionState,
        episode: RepetitionEpisode,
        active: dict[str, str],
        dt: float | None = None,
    ) -> None:
        """One Euler step under the ``active`` MPs (modifies ``state``).

        Args:
            state: the world, advanced in place.
            episode: the episode's goals.
            active: variable -> MP during the step.
            dt: the step [s]; default the task's ``dt`` (another step is checked for
                stability).
        """
        h = self.dt if dt is None else self.check_step(dt)
        g_ladle, g_bowl = self.goals(episode, active)
        state.ladle = state.ladle + h * self.gain_ladle * (g_ladle - state.ladle)
        state.bowl = state.bowl + h * self.gain_bowl * (g_bowl - state.bowl)
        mp = active["ladle"]
        if mp == "scoop" and np.linalg.norm(state.ladle - episode.pot) < self.flow_radius:
            target = min(self.capacity, state.remaining)
            if state.fill < target:
                state.fill = min(target, state.fill + h * self.fill_rate)
        elif mp == "pour" and np.linalg.norm(state.ladle - episode.spot) < self.flow_radius:
            out = min(state.fill, h * self.pour_rate)
            state.fill -= out
            if np.linalg.norm(state.bowl - episode.spot) < self.flow_radius:
                state.remaining = max(0.0, state.remaining - out)
            else:
                state.spilled += out

    def shortfall(self, state: RepetitionState, episode: RepetitionEpisode) -> str:
        """Why ``state`` is not the goal state, in words (``""`` at the goal).

        Each goal condition of :meth:`at_goal` not met; soup poured beside the bowl is said
        with the soup left.
        """
        tol = self.goal_tolerance
        unmet = []
        if state.remaining > AMOUNT_EPS:
            spilled = f" ({state.spilled:.2f} l spilled)" if state.spilled > AMOUNT_EPS else ""
            unmet.append(f"{state.remaining:.2f} l of soup left to pour{spilled}")
        bowl = float(np.linalg.norm(state.bowl - episode.hatch))
        if bowl >= tol:
            unmet.append(f"the bowl is {1000 * bowl:.0f} mm from the hatch")
        ladle = float(np.linalg.norm(state.ladle - episode.ladle_home))
        if ladle >= tol:
            unmet.append(f"the ladle is {1000 * ladle:.0f} mm from home")
        return "; ".join(unmet)

    def at_goal(self, state: RepetitionState, episode: RepetitionEpisode) -> bool:
        """Nothing left to pour, the bowl at the hatch and the ladle home."""
        tol = self.goal_tolerance
        return bool(
            state.remaining <= AMOUNT_EPS
            and np.linalg.norm(state.bowl - episode.hatch) < tol
            and np.linalg.norm(state.ladle - episode.ladle_home) < tol
        )
