"""The relay task with paced MPs: varied speeds and holds mid-MP (issue #23).

The world of :mod:`cpmp.worlds.relay.world` with every activation paced by a
:class:`~cpmp.worlds.pacing.Pacer`: the demonstrator's MPs at a speed factor drawn per
activation (log-uniform in ``demo.speed``, x0.5-2 by default) and, with probability
``demo.pause_probability`` (0.5), one hold of ``demo.pause`` seconds (0.3-1 s) once the
activation has covered 20-80 % of its initial goal distance. The demonstrator's guards are those
of :mod:`cpmp.worlds.relay.demonstrator`; the episodes (homes, goals, contexts) of a seed are
those of :func:`cpmp.worlds.relay.make_demonstrations` and :func:`cpmp.worlds.relay.evaluate`.

**The closed-loop robot** runs its MPs at a speed factor drawn per activation as the
demonstrator did (``robot.speed``, x0.5-2), and does not hold (``robot.pause`` unset). It
varies because the world is one where an MP's duration says little about its progress, whoever
runs it; the predictors read features, not clocks, so its speed reaches them only through the
switching rule's timing, alike for every label. It does not hold by default because, in the
features, a hold mid-MP is the state of an arrival for *every* feature-based progress (φ stops
rising, and the paper's rule fires once ``p`` passes the threshold): closed-loop holds test the
switching rule, not the labels. ``robot=Pacing(speed=..., pause=...)`` turns them on for that
test.

**Why time-based progress is wrong here, not a strawman**: a hold of ``h`` seconds at a fraction
``u`` of an activation of length ``T`` gives every later state the time label ``(t + h) / (T +
h)``, so after the typical hold point the time labels crowd towards 1 and before it towards 0;
the speed factor changes ``T`` and the share of the activation the final approach takes. A
predictor trained on elapsed time learns, at a state, the average of those labels, so its φ
is high before the MP has arrived; eq. 1 gives the same state the same label in every
demonstration. Whether that costs completions is what the comparison measures.

The face for comparisons (:class:`~cpmp.worlds.pacing.PacedWorld`)::

    world = paced_relay(seed, n_demos, demo=DEMO_PACING, robot=ROBOT_PACING, relay=None)
    world.demonstrations                        # list[Demonstration], n_demos of them
    world.evaluate(policy, n_episodes, seed)    # list[EpisodeScore], one per episode

Held-out demonstrations for a progress MAE: ``paced_relay(other_seed, n).demonstrations``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from cpmp.config.task import Pacing
from cpmp.data import Demonstration
from cpmp.data.demonstration import mp_sequences
from cpmp.records import Policy
from cpmp.worlds.common import (
    ScriptPolicy,
    positive_count,
    record_script,
    run_policies,
    seeded_episodes,
)
from cpmp.worlds.outcomes import episode_outcome
from cpmp.worlds.pacing import EpisodeScore, PacedWorld, Pacer
from cpmp.worlds.relay.demonstrator import script
from cpmp.worlds.relay.world import (
    FEATURE_NAMES,
    STRATEGIES,
    VARIABLES,
    RelayEpisode,
    RelayState,
    RelayTask,
)

DEMO_PACING = Pacing(speed=(0.5, 2.0), pause=(0.3, 1.0), pause_probability=0.5)
"""The demonstrator's pacing of :func:`paced_relay` (issue #23's x0.5-2 and 0.3-1 s)."""
ROBOT_PACING = Pacing(speed=(0.5, 2.0))
"""The closed-loop robot's pacing of :func:`paced_relay`: varied speeds, no holds."""
MAX_TIME = 30.0
"""Episode limit [s] of :func:`paced_relay`'s relay task: the slowest demonstration (x0.5 and a
1 s hold in every activation) takes about 12 s, three times the nominal one."""
DEMO_STREAM = 0
ROBOT_STREAM = 1
"""The second word of a run's pacing seed ``(seed, stream, index)``: demonstrations and
closed-loop episodes of one seed draw from different streams."""


@dataclass(frozen=True, eq=False)
class PacedEpisode:
    """A relay episode and its run's pacing seed.

    Attributes:
        relay: the relay episode (homes, goals, context).
        seed: seeds the run's :class:`~cpmp.worlds.pacing.Pacer`.
    """

    relay: RelayEpisode
    seed: tuple[int, ...]

    @property
    def strategy(self) -> str:
        """``meet`` or ``fetch``."""
        return self.relay.strategy


@dataclass
class PacedState:
    """The relay state and the run's pacer.

    Attributes:
        relay: the relay world's state.
        pacer: the run's pacing so far (its holds and drawn paces).
    """

    relay: RelayState
    pacer: Pacer


@dataclass
class PacedRelayTask:
    """The relay task with paced MPs (a :class:`~cpmp.worlds.common.SteppedTask`).

    Attributes:
        relay: the relay task (gains, tolerances, time step, episode limit).
        pacing: how the MPs of a run are paced.
    """

    relay: RelayTask = field(default_factory=lambda: RelayTask(max_time=MAX_TIME))
    pacing: Pacing = field(default_factory=Pacing)

    @property
    def dt(self) -> float:
        """Control period [s]."""
        return self.relay.dt

    @property
    def max_time(self) -> float:
        """Episode limit [s]."""
        return self.relay.max_time

    def initial_state(self, episode: PacedEpisode) -> PacedState:
        """The relay's initial state and a fresh pacer seeded by the episode."""
        pacer = Pacer(self.pacing, episode.seed, self.relay.dt)
        return PacedState(self.relay.initial_state(episode.relay), pacer)

    def initial_mps(self, episode: PacedEpisode) -> dict[str, str]:
        """The demonstrator's initial MP per variable."""
        return self.relay.initial_mps(episode.relay)

    def distances(
        self, state: PacedState, episode: PacedEpisode, active: dict[str, str]
    ) -> dict[str, float]:
        """Each variable's distance to its active MP's goal: positions [m], the aperture."""
        gc, gr, ga = self.relay.goals(state.relay, episode.relay, active)
        s = state.relay
        return {
            "carrier": float(np.linalg.norm(gc - s.carrier)),
            "gripper": abs(ga - s.aperture),
            "receiver": float(np.linalg.norm(gr - s.receiver)),
        }

    def advance(
        self,
        state: PacedState,
        episode: PacedEpisode,
        active: dict[str, str],
        dt: float | None = None,
    ) -> None:
        """One step (of ``dt`` [s], default the task's) with each variable's gain times its pace.

        A pace is 0 while its variable holds; the pacer counts one tick per step.
        """
        speed = state.pacer.speeds(active, self.distances(state, episode, active))
        self.relay.advance(state.relay, episode.relay, active, speed=speed, dt=dt)

    def at_goal(self, state: PacedState, episode: PacedEpisode) -> bool:
        """The relay's goal state."""
        return self.relay.at_goal(state.relay, episode.relay)

    def shortfall(self, state: PacedState, episode: PacedEpisode) -> str:
        """Why ``state`` is not the relay's goal state, in words (:meth:`RelayTask.shortfall`)."""
        return self.relay.shortfall(state.relay, episode.relay)

    def features(self, state: PacedState, episode: PacedEpisode) -> np.ndarray:
        """The relay's features ``(6,)``."""
        return self.relay.features(state.relay, episode.relay)

    def episodes(self, n: int, seed: int, stream: int) -> list[PacedEpisode]:
        """``n`` episodes of ``seed`` (the relay's, strategies alternating) with pacing seeds.

        Args:
            n: the number of episodes.
            seed: seeds the episodes and, with ``stream`` and the index, their pacing.
            stream: :data:`DEMO_STREAM` or :data:`ROBOT_STREAM`.

        Returns:
            The episodes.
        """
        relay_episodes = seeded_episodes(self.relay.sample_episode, STRATEGIES, n, seed)
        return [PacedEpisode(e, (seed, stream, i)) for i, e in enumerate(relay_episodes)]


def demonstrate(
    task: PacedRelayTask, episode: PacedEpisode, name: str | None = None
) -> Demonstration:
    """The relay demonstrator's labelled demonstration of ``episode``, paced.

    Its metadata adds ``holds`` (how many holds the run made) to the relay's.
    """
    relay = task.relay
    run = record_script(
        task,
        episode,
        lambda state: task.features(state, episode),
        lambda x, active: script(relay, x, episode.relay, active),
        VARIABLES,
    )
    metadata = {
        "task": "relay_paced",
        "context": episode.relay.context,
        "strategy": episode.strategy,
        "reached_goal": task.at_goal(run.state, episode),
        "holds": len(run.state.pacer.holds),
    }
    return run.log.to_demonstration(FEATURE_NAMES, name, metadata)


class PacedScriptedPolicy(ScriptPolicy):
    """The relay demonstrator as a closed-loop policy on :class:`PacedEpisode` episodes."""

    @staticmethod
    def script(
        task: PacedRelayTask, x: np.ndarray, episode: PacedEpisode, active: dict[str, str]
    ) -> dict[str, str]:
        """The relay demonstrator's switches (:func:`cpmp.worlds.relay.demonstrator.script`)."""
        return script(task.relay, x, episode.relay, active)


def make_demonstrations(
    n: int, seed: int = 0, task: PacedRelayTask | None = None
) -> list[Demonstration]:
    """``n`` paced demonstrations alternating meet and fetch (``demo_0`` meet), reproducible.

    Args:
        n: the number of demonstrations.
        seed: seeds the episodes (the relay's of the same seed) and the pacing.
        task: the paced task (default: the relay's defaults with :data:`MAX_TIME`, paced by
            :data:`DEMO_PACING`).

    Returns:
        The demonstrations, named ``demo_<i>``.

    Raises:
        ConfigError: ``n`` is not a positive integer.
    """
    positive_count(n, "n")
    task = task or PacedRelayTask(pacing=DEMO_PACING)
    episodes = task.episodes(n, seed, DEMO_STREAM)
    return [demonstrate(task, e, name=f"demo_{i}") for i, e in enumerate(episodes)]


def evaluate(
    policy: Policy, task: PacedRelayTask | None = None, n_episodes: int = 20, seed: int = 0
) -> list[EpisodeScore]:
    """Closed-loop scores of a policy on ``n_episodes`` paced episodes drawn from ``seed``.

    Args:
        policy: a fitted sequencer or any policy, reset at ``t = 0`` and stepped every tick.
        task: the paced task (default: the relay's defaults with :data:`MAX_TIME`, paced by
            :data:`ROBOT_PACING`).
        n_episodes: the number of episodes (strategies alternating).
        seed: seeds the episodes and their pacing (use another than the demonstrations').

    Returns:
        One score per episode, in order (a fitted sequencer runs them all at once,
        :func:`~cpmp.worlds.common.run_policies`).

    Raises:
        ConfigError: ``n_episodes`` is not a positive integer.
    """
    positive_count(n_episodes, "n_episodes")
    task = task or PacedRelayTask(pacing=ROBOT_PACING)
    episodes = task.episodes(n_episodes, seed, ROBOT_STREAM)
    scores = []
    runs = run_policies(task, episodes, policy, task.features, VARIABLES, expected_for(task))
    for episode, run in zip(episodes, runs, strict=True):
        outcome = episode_outcome(run.initial == task.initial_mps(episode), run.reached_goal)
        cause = run.cause if outcome == "incomplete" else None
        reason = cause.describe() if cause is not None else ""
        scores.append(EpisodeScore(outcome, episode.strategy, run.time, reason, cause))
    return scores


def expected_for(task: PacedRelayTask) -> Callable[[PacedEpisode], dict[str, list[str]]]:
    """The demonstrator's MP sequences of an episode of ``task`` (from its demonstration)."""

    def expected(episode: PacedEpisode) -> dict[str, list[str]]:
        return mp_sequences(demonstrate(task, episode))

    return expected


def paced_relay(
    seed: int,
    n_demos: int,
    demo: Pacing = DEMO_PACING,
    robot: Pacing = ROBOT_PACING,
    relay: RelayTask | None = None,
) -> PacedWorld:
    """The paced relay world of ``seed``: its demonstrations and its closed-loop evaluation.

    Args:
        seed: seeds the demonstrations' episodes and pacing.
        n_demos: the number of demonstrations.
        demo: the demonstrator's pacing.
        robot: the closed-loop robot's pacing.
        relay: the relay task (default: its defaults with :data:`MAX_TIME`).

    Returns:
        The world: ``demonstrations`` and ``evaluate(policy, n_episodes, seed)``.

    Raises:
        ConfigError: ``n_demos`` is not a positive integer.
    """
    relay = relay or RelayTask(max_time=MAX_TIME)
    demos = make_demonstrations(n_demos, seed, PacedRelayTask(relay, demo))
    closed_loop = PacedRelayTask(relay, robot)

    def evaluate_world(policy: Policy, n_episodes: int, seed: int) -> list[EpisodeScore]:
        return evaluate(policy, closed_loop, n_episodes, seed)

    return PacedWorld(demos, evaluate_world)
