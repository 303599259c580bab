"""MPs that run at varied speeds and pause mid-MP: the pacer, and the face of a paced world.

Why (issue #23): when every demonstration runs an MP at one speed without pauses, the paper's
progress label (eq. 1, the normalised L1 path length in feature space) and normalised elapsed
time agree up to a fixed warp, and predictors trained on either complete alike. A demonstrator
that goes faster or slower from one activation to the next, and holds still for a moment
mid-MP, makes them disagree: while a variable holds, its features stand still, so eq. 1 stays
put while time runs on, and the time an MP takes no longer says how far along its path it is.

:class:`Pacer` applies a :class:`~cpmp.config.task.Pacing` to one run (a demonstration or a
closed-loop episode): every tick it is told the active MP and the remaining goal distance of
each control variable, and returns each variable's speed factor for the next tick (0 while it
holds). Each new activation draws, from the run's own generator and in a fixed order, a speed
factor (log-uniform in ``pacing.speed``), whether it holds (``pacing.pause_probability``),
where (a fraction uniform in :data:`~cpmp.config.task.PAUSE_AT` of the activation's initial
goal distance covered) and for how long (uniform in ``pacing.pause`` seconds, rounded to whole
ticks). A run's pacing therefore depends only on its seed and on the MPs it runs: the same seed
gives the same demonstrations.

:class:`PacedWorld` is what a paced world hands a comparison: its demonstrations and a
closed-loop evaluation, ``evaluate(policy, n_episodes, seed) -> list[EpisodeScore]``, one score
per episode (for bootstrap intervals over episodes). :func:`cpmp.worlds.relay.varied.paced_relay`
builds the synthetic one, :func:`cpmp.sim.paced.paced_sim` the simulated one.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from cpmp.config.task import PAUSE_AT, Pacing
from cpmp.data import Demonstration
from cpmp.errors import ConfigError
from cpmp.records import PendingSwitch, Policy
from cpmp.worlds.outcomes import Outcome


@dataclass(frozen=True)
class ActivationPace:
    """The pace one activation drew.

    Attributes:
        speed: its speed factor.
        pause_at: the fraction of its initial goal distance covered when it holds, or
            ``None`` (no hold).
        pause_ticks: the hold's length in control ticks (0 without a hold).
    """

    speed: float
    pause_at: float | None
    pause_ticks: int


@dataclass(frozen=True)
class Hold:
    """A hold that happened (:attr:`Pacer.holds`).

    Attributes:
        variable: the control variable that held.
        mp: its active MP.
        start: the index of the first tick of the run that was held (0: the first ``advance``).
        ticks: the hold's length in ticks.
    """

    variable: str
    mp: str
    start: int
    ticks: int


class Pacer:
    """One run's pacing: each control variable's speed factor, tick by tick.

    Args:
        pacing: the speed and pause ranges.
        seed: seeds the run's generator (an int or a sequence of ints, as
            :func:`numpy.random.default_rng` takes).
        dt: the control period [s] (pauses are whole ticks of it).
        no_pause: MPs (``"variable/mp"``) that never hold, e.g. one whose hold would tear a
            jointly held object apart.
        min_distance: an activation that starts closer than this to its goal (in the
            distances' units) never holds: it has no path to hold on.
    """

    def __init__(
        self,
        pacing: Pacing,
        seed: int | Sequence[int],
        dt: float,
        no_pause: Collection[str] = (),
        min_distance: float = 1e-9,
    ) -> None:
        if not dt > 0:
            raise ConfigError(f"the control period dt must be > 0 s, got {dt!r}")
        self.pacing = pacing
        self.dt = float(dt)
        self.no_pause = frozenset(no_pause)
        self.min_distance = float(min_distance)
        self.rng = np.random.default_rng(seed)
        self.tick = 0
        self.holds: list[Hold] = []
        self.paces: list[tuple[str, str, ActivationPace]] = []
        self._mp: dict[str, str] = {}
        self._pace: dict[str, ActivationPace] = {}
        self._start_distance: dict[str, float] = {}
        self._held: dict[str, int] = {}
        """Per variable: ticks left of its running hold (absent: not holding now)."""
        self._done: set[str] = set()
        """Variables whose current activation has held already (or never will)."""

    def draw(self) -> ActivationPace:
        """The next activation's pace (always four draws, so the stream stays aligned)."""
        p = self.pacing
        u_speed, u_hold, u_where, u_long = self.rng.random(4)
        speed = 1.0
        if p.speed is not None:
            lo, hi = p.speed
            speed = float(math.exp(math.log(lo) + u_speed * (math.log(hi) - math.log(lo))))
        if p.pause is None or not u_hold < p.pause_probability:
            return ActivationPace(speed, None, 0)
        where = PAUSE_AT[0] + u_where * (PAUSE_AT[1] - PAUSE_AT[0])
        seconds = p.pause[0] + u_long * (p.pause[1] - p.pause[0])
        return ActivationPace(speed, float(where), round(seconds / self.dt))

    def speeds(self, active: Mapping[str, str], distance: Mapping[str, float]) -> dict[str, float]:
        """Each variable's speed factor for the next tick (0: it holds).

        Call once per tick, before the world advances, with that tick's MPs.

        Args:
            active: variable -> its active MP.
            distance: variable -> the remaining distance to its active MP's goal, in any unit
                of the variable (the fraction covered is what counts).

        Returns:
            Variable -> speed factor.
        """
        out: dict[str, float] = {}
        for variable, mp in active.items():
            if self._mp.get(variable) != mp:
                self._start(variable, mp, float(distance[variable]))
            out[variable] = self._factor(variable, mp, float(distance[variable]))
        self.tick += 1
        return out

    def _start(self, variable: str, mp: str, distance: float) -> None:
        """A new activation of ``mp``: draw its pace, note where it starts."""
        pace = self.draw() if self.pacing.varied else ActivationPace(1.0, None, 0)
        self._mp[variable] = mp
        self._pace[variable] = pace
        self._start_distance[variable] = distance
        self._held.pop(variable, None)
        never = (
            pace.pause_at is None
            or pace.pause_ticks == 0
            or f"{variable}/{mp}" in self.no_pause
            or not distance > self.min_distance
        )
        if never:
            self._done.add(variable)
        else:
            self._done.discard(variable)
        self.paces.append((variable, mp, pace))

    def _factor(self, variable: str, mp: str, distance: float) -> float:
        """The speed factor of ``variable`` this tick, starting or ending its hold."""
        pace = self._pace[variable]
        if variable in self._held:
            self._held[variable] -= 1
            if self._held[variable] == 0:
                del self._held[variable]
            return 0.0
        if variable not in self._done:
            assert pace.pause_at is not None  # _start marks activations without a hold done
            if distance <= (1.0 - pace.pause_at) * self._start_distance[variable]:
                self._done.add(variable)
                self.holds.append(Hold(variable, mp, self.tick, pace.pause_ticks))
                if pace.pause_ticks > 1:
                    self._held[variable] = pace.pause_ticks - 1
                return 0.0
        return pace.speed


@dataclass(frozen=True)
class EpisodeScore:
    """One closed-loop episode of a paced world.

    Attributes:
        outcome: ``complete``, ``wrong_start`` or ``incomplete`` (the simulator's
            ``diverged`` counts as ``incomplete``).
        strategy: the episode's strategy.
        time: when it ended [s].
        reason: why, in words (empty where the world gives none).
        cause: an ``incomplete`` episode's missing switch (:class:`~cpmp.records.PendingSwitch`;
            ``None`` otherwise).
    """

    outcome: Outcome
    strategy: str
    time: float
    reason: str = ""
    cause: PendingSwitch | None = None


Evaluate = Callable[[Policy, int, int], list[EpisodeScore]]
"""``evaluate(policy, n_episodes, seed)``: one :class:`EpisodeScore` per episode, the episodes
drawn from ``seed`` (use another seed than the demonstrations'); ``policy`` is a fitted
:class:`~cpmp.sequencer.ConcurrentSequencer` or any :class:`~cpmp.records.Policy` (the simulator
also takes a batched one)."""


@dataclass(frozen=True)
class PacedWorld:
    """A paced world as a comparison uses it.

    Attributes:
        demonstrations: the labelled demonstrations, reproducible from the seed they were
            drawn with.
        evaluate: the closed loop (:data:`Evaluate`).
    """

    demonstrations: list[Demonstration]
    evaluate: Evaluate
