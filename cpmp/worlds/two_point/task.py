"""A small synthetic concurrent task, for examples, tests and quick experiments.

Two control variables move two points ``a`` and ``b`` on a line with first-order attractors
``ṗ = K (g - p)``; a context feature ``c`` in [0, 1] selects one of two strategies:

* ``c < 0.5`` (sequential): ``a`` moves out while ``b`` waits at 0; then ``a`` holds while
  ``b`` moves out; once ``b`` arrived both return to 0.
* ``c >= 0.5`` (parallel): ``a`` and ``b`` move out at once (``b`` is faster and holds at its
  goal); once both arrived both return to 0.

Features are ``x = [p_a, p_b, c]``. Variable ``a`` runs ``a_go -> a_wait -> a_back``
(sequential) or ``a_go -> a_back`` (parallel); ``b`` runs ``b_wait -> b_go -> b_back`` or
``b_go -> b_back``. So ``a``'s graph branches, ``b``'s has two initial nodes, and the graphs
synchronise through the shared features only.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from cpmp.data import Demonstration, DemonstrationLog
from cpmp.errors import ConfigError
from cpmp.records import Policy
from cpmp.worlds.common import note_switches, positive_count
from cpmp.worlds.outcomes import Outcome, count_outcomes, episode_outcome

FEATURE_NAMES = ["p_a", "p_b", "context"]
VARIABLES = ["a", "b"]


@dataclass(frozen=True, eq=False)
class TwoPointEpisode:
    """The random parameters of one episode.

    Attributes:
        start: ``(2,)`` start positions of ``a`` and ``b``.
        goal: ``(2,)`` goals of their "out" MPs.
        context: ``c`` in [0, 1]; ``< 0.5`` sequential, ``>= 0.5`` parallel.
    """

    start: np.ndarray
    goal: np.ndarray
    context: float

    @property
    def parallel(self) -> bool:
        """Whether the episode's strategy is the parallel one (``context >= 0.5``)."""
        return self.context >= 0.5


class TwoPointRollout(NamedTuple):
    """One closed-loop run of a policy (:meth:`SyntheticTask.rollout`).

    Attributes:
        sequences: variable -> the MPs it ran, in order.
        done: whether both points returned home within ``max_time``.
    """

    sequences: dict[str, list[str]]
    done: bool


@dataclass
class SyntheticTask:
    """The two-point concurrent task.

    Attributes:
        dt: control period [s].
        max_time: episode time limit [s].
        gain: attractor gains K of ``a`` and ``b`` [1/s].
        tolerance: the demonstrator switches when a point is this close to its goal.
        start_jitter: half-width of the uniform jitter of the start positions around 0.
        goal_jitter: half-width of the uniform jitter of the "out" goals around 1 (goals are not
            features, so a jitter makes the end of an MP unobservable; 0 by default).
    """

    # the world
    dt: float = 0.01
    max_time: float = 8.0
    gain: tuple[float, float] = (2.5, 4.0)
    # the demonstrator
    tolerance: float = 0.02
    # the episodes
    start_jitter: float = 0.05
    goal_jitter: float = 0.0

    def __post_init__(self) -> None:
        if min(self.gain) <= 0 or self.dt <= 0 or self.tolerance <= 0 or self.max_time <= 0:
            raise ConfigError("gain, dt, tolerance and max_time must all be > 0")

    def sample_episode(
        self, rng: np.random.Generator, context: float | None = None
    ) -> TwoPointEpisode:
        """Random start positions, goals and context for one episode.

        Args:
            rng: the random generator (draws the starts, the goals, then the context).
            context: the context; ``None`` draws it uniformly in [0, 1].

        Returns:
            The episode.
        """
        return TwoPointEpisode(
            start=rng.uniform(-self.start_jitter, self.start_jitter, size=2),
            goal=1.0 + rng.uniform(-self.goal_jitter, self.goal_jitter, size=2),
            context=float(rng.uniform(0.0, 1.0) if context is None else context),
        )

    def goals(self, episode: TwoPointEpisode, active: dict[str, str]) -> np.ndarray:
        """Attractor goals ``(2,)`` of the active MPs."""
        out = np.zeros(2)
        for i, v in enumerate(VARIABLES):
            mp = active[v]
            if mp.endswith("_go") or mp == "a_wait":
                out[i] = episode.goal[i]
        return out

    def initial_mps(self, episode: TwoPointEpisode) -> dict[str, str]:
        """The demonstrator's initial MP per variable for ``episode``."""
        return {"a": "a_go", "b": "b_go" if episode.parallel else "b_wait"}

    def _demo_switch(self, p: np.ndarray, g: np.ndarray, active: dict[str, str]) -> dict[str, str]:
        """The demonstrator's switches at positions ``p (2,)`` with goals ``g (2,)``."""
        near = np.abs(g - p) < self.tolerance
        a, b = active["a"], active["b"]
        new = dict(active)
        if a == "a_go" and b == "b_wait" and near[0]:
            new["a"] = "a_wait"
        if b == "b_wait" and a == "a_wait":
            new["b"] = "b_go"
        if b == "b_go" and near[1] and a in ("a_go", "a_wait") and near[0]:
            new["a"], new["b"] = "a_back", "b_back"
        return new

    def demonstrate(self, episode: TwoPointEpisode, name: str | None = None) -> Demonstration:
        """The scripted demonstrator's labelled demonstration of ``episode``."""
        active = self.initial_mps(episode)
        p = np.array(episode.start, dtype=float)
        log = DemonstrationLog(VARIABLES)
        t = 0.0
        while t <= self.max_time:
            log.append(t, [p[0], p[1], episode.context], active)
            if active["a"] == "a_back" and active["b"] == "b_back" and np.all(np.abs(p) < 0.01):
                break
            g = self.goals(episode, active)
            active = self._demo_switch(p, g, active)
            p = p + self.dt * np.asarray(self.gain) * (self.goals(episode, active) - p)
            t = round(t + self.dt, 10)
        metadata = {
            "context": episode.context,
            "strategy": "parallel" if episode.parallel else "sequential",
        }
        return log.to_demonstration(FEATURE_NAMES, name, metadata)

    def rollout(self, episode: TwoPointEpisode, policy: Policy) -> TwoPointRollout:
        """Run ``policy`` closed-loop on ``episode``.

        Args:
            episode: the episode.
            policy: what decides the MPs, reset at ``t = 0`` then stepped every ``dt``.

        Returns:
            The executed MP sequence per variable and whether both points returned home.
        """
        p = np.array(episode.start, dtype=float)
        x = np.array([p[0], p[1], episode.context])
        active = policy.reset(0.0, x)
        seqs = {v: [active[v]] for v in VARIABLES}
        t = 0.0
        while t < self.max_time:
            p = p + self.dt * np.asarray(self.gain) * (self.goals(episode, active) - p)
            t = round(t + self.dt, 10)
            x = np.array([p[0], p[1], episode.context])
            active = policy.step(t, x)
            note_switches(seqs, active)
            if active["a"] == "a_back" and active["b"] == "b_back" and np.all(np.abs(p) < 0.01):
                return TwoPointRollout(seqs, True)
        return TwoPointRollout(seqs, False)

    def rollouts(
        self, episodes: Sequence[TwoPointEpisode], policy: Policy
    ) -> list[TwoPointRollout]:
        """Run ``policy`` closed-loop on every one of ``episodes``, as :meth:`rollout` does.

        A policy with ``batched(n)`` (a fitted :class:`~cpmp.sequencer.ConcurrentSequencer`)
        runs them all at once, one ``step`` per tick over the episodes still running, with the
        results :meth:`rollout` gives each; any other policy runs them one after another.

        Args:
            episodes: the episodes.
            policy: the policy.

        Returns:
            One rollout per episode, in order.
        """
        make_batch = getattr(policy, "batched", None)
        if make_batch is None or not episodes:
            return [self.rollout(e, policy) for e in episodes]
        n = len(episodes)
        batch = make_batch(n)
        p = np.array([e.start for e in episodes], dtype=float)  # (N, 2)
        context = np.array([[e.context] for e in episodes])  # (N, 1)
        active = [dict(a) for a in batch.reset(0.0, np.hstack([p, context]))]
        seqs = [{v: [a[v]] for v in VARIABLES} for a in active]
        done = np.zeros(n, dtype=bool)
        gain = np.asarray(self.gain)
        t = 0.0
        while t < self.max_time and not done.all():
            live = ~done
            rows = np.flatnonzero(live).tolist()
            goals = np.array([self.goals(episodes[i], active[i]) for i in rows])
            p[rows] = p[rows] + self.dt * gain * (goals - p[rows])
            t = round(t + self.dt, 10)
            stepped = batch.step(t, np.hstack([p, context]), live=live)
            for i in rows:
                active[i] = dict(stepped[i])
                note_switches(seqs[i], active[i])
                home = active[i]["a"] == "a_back" and active[i]["b"] == "b_back"
                done[i] = home and bool(np.all(np.abs(p[i]) < 0.01))
        return [TwoPointRollout(seqs[i], bool(done[i])) for i in range(n)]

    def outcome(self, episode: TwoPointEpisode, run: TwoPointRollout) -> Outcome:
        """The outcome of ``run``, a closed-loop run of ``episode`` (:func:`evaluate`)."""
        started_right = {v: s[0] for v, s in run.sequences.items()} == self.initial_mps(episode)
        return episode_outcome(started_right, run.done)


def evaluate(
    seq: Policy, task: SyntheticTask | None = None, n_episodes: int = 20, seed: int = 0
) -> dict[Outcome, int]:
    """Closed-loop outcomes of a policy on random episodes.

    Args:
        seq: the policy (a fitted sequencer, or any :class:`~cpmp.records.Policy`).
        task: the task (default: :class:`SyntheticTask`'s defaults).
        n_episodes: the number of episodes.
        seed: seeds the episodes.

    Returns:
        The number of episodes per outcome: ``wrong_start`` (the initial MPs differ from the
        demonstrator's for the episode's context), ``incomplete`` (both points not home
        within ``max_time``) or ``complete``.

    Raises:
        ConfigError: ``n_episodes`` is not a positive integer.
    """
    positive_count(n_episodes, "n_episodes")
    task = task or SyntheticTask()
    rng = np.random.default_rng(seed)
    episodes = [task.sample_episode(rng) for _ in range(n_episodes)]
    return count_outcomes(
        task.outcome(e, r) for e, r in zip(episodes, task.rollouts(episodes, seq), strict=True)
    )


def make_demonstrations(
    n: int, seed: int = 0, task: SyntheticTask | None = None
) -> list[Demonstration]:
    """``n`` demonstrations alternating the two strategies, reproducible from ``seed``."""
    task = task or SyntheticTask()
    rng = np.random.default_rng(seed)
    demos = []
    for i in range(n):
        lo, hi = (0.0, 0.45) if i % 2 == 0 else (0.55, 1.0)
        context = float(rng.uniform(lo, hi))
        demos.append(task.demonstrate(task.sample_episode(rng, context), name=f"demo_{i}"))
    return demos


def curved_trajectories(n: int = 4, seed: int = 0, n_samples: int = 100) -> list[Demonstration]:
    """``n`` curved 2-D trajectories of one MP ``move`` (the setting of the paper's Fig. 3).

    Each runs from a start region near (0.1, 0.1) to an end region near (0.9, 0.9) in one
    activation.
    """
    rng = np.random.default_rng(seed)
    u = np.linspace(0.0, 1.0, n_samples)[:, None]
    demos = []
    for i in range(n):
        start = np.array([0.1, 0.1]) + rng.uniform(-0.06, 0.06, 2)
        end = np.array([0.9, 0.9]) + rng.uniform(-0.06, 0.06, 2)
        bend = np.array([0.5, 0.5]) + rng.uniform(-0.35, 0.35, 2)
        x = (1 - u) ** 2 * start + 2 * (1 - u) * u * bend + u**2 * end  # quadratic Bezier
        demos.append(
            Demonstration(
                time=u[:, 0] * 2.0,
                features=x,
                labels={"var": np.array(["move"] * n_samples)},
                feature_names=["x1", "x2"],
                name=f"demo_{i}",
            )
        )
    return demos
