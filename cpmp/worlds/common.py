"""What the synthetic worlds share: checked counts, seeded episodes, scripted and closed-loop runs.

The relay and repetition worlds step the same way (:class:`SteppedTask`): a scripted demonstrator
records a demonstration (:func:`record_script`) and a policy runs closed-loop
(:func:`run_policy`) in one loop each, the world's features passed in as a function of the state.
:func:`run_policies` runs many episodes of one policy, all at once where the policy batches
(a fitted sequencer's ``batched(n)``: one predictor call per tick for every running episode),
with the same results as :func:`run_policy` one episode at a time.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Generic, Protocol, TypeVar

import numpy as np

from cpmp.data import DemonstrationLog
from cpmp.errors import ConfigError
from cpmp.records import PendingSwitch, Policy, episode_cause

State = TypeVar("State")
Episode = TypeVar("Episode")
Strategy = TypeVar("Strategy")

Features = Callable[[State], np.ndarray]
"""The world's feature vector ``(d,)`` of a state."""
EpisodeFeatures = Callable[[State, Episode], np.ndarray]
"""The world's feature vector ``(d,)`` of a state of an episode."""
ExpectedSequences = Callable[[Episode], Mapping[str, Sequence[str]]]
"""The demonstrator's MP sequences (variable -> MPs in order) of an episode."""


class SteppedTask(Protocol[State, Episode]):
    """A world that advances its state one control tick ``dt`` at a time.

    Attributes:
        dt: control period [s].
        max_time: episode time limit [s].
    """

    dt: float
    max_time: float

    def initial_state(self, episode: Episode) -> State:
        """The state at ``t = 0``."""
        ...

    def initial_mps(self, episode: Episode) -> dict[str, str]:
        """The demonstrator's initial MP per variable."""
        ...

    def advance(self, state: State, episode: Episode, active: dict[str, str]) -> None:
        """Advance ``state`` in place by one ``dt`` under the ``active`` MPs."""
        ...

    def at_goal(self, state: State, episode: Episode) -> bool:
        """Whether ``state`` is the goal state."""
        ...


Script = Callable[[object, np.ndarray, object, dict[str, str]], dict[str, str]]
"""A world's demonstrator: ``script(task, x, episode, active)`` -> the active MPs after its
switches at features ``x (d,)``."""


class ScriptPolicy(Generic[Episode]):
    """A world's demonstrator (its :data:`Script`) as a :class:`~cpmp.records.Policy`.

    A world subclasses it and sets ``script``.

    It knows the episode, as the demonstrator does.

    Args:
        task: the world's task options.
        episode: the episode it runs.
    """

    script: Script

    def __init__(self, task: SteppedTask[object, Episode], episode: Episode) -> None:
        self.task = task
        self.episode = episode
        self.active: dict[str, str] = {}

    def reset(self, t: float, x: np.ndarray) -> dict[str, str]:
        """The demonstrator's initial MPs for the episode (``t`` [s] and ``x`` unused)."""
        self.active = self.task.initial_mps(self.episode)
        return dict(self.active)

    def step(self, t: float, x: np.ndarray) -> dict[str, str]:
        """The demonstrator's switches at features ``x (d,)``; the active MPs after them."""
        self.active = type(self).script(self.task, np.asarray(x, float), self.episode, self.active)
        return dict(self.active)


def positive_count(n: object, name: str) -> int:
    """``n`` checked to be a positive integer (``bool`` is not one).

    Args:
        n: the count.
        name: its name in the error message.

    Returns:
        ``n``.

    Raises:
        ConfigError: ``n`` is not a positive integer.
    """
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise ConfigError(f"{name} must be a positive integer, got {n!r}")
    return n


def seeded_episodes(
    sample: Callable[[np.random.Generator, Strategy], Episode],
    strategies: Sequence[Strategy],
    n: int,
    seed: int,
) -> list[Episode]:
    """``n`` episodes cycling ``strategies`` (the first is ``strategies[0]``), drawn from ``seed``.

    Args:
        sample: draws one episode of a strategy from the generator (a task's
            ``sample_episode``).
        strategies: the strategies, in the order they cycle.
        n: the number of episodes.
        seed: seeds the one generator all episodes are drawn from, in order.

    Returns:
        The episodes.
    """
    rng = np.random.default_rng(seed)
    return [sample(rng, strategies[i % len(strategies)]) for i in range(n)]


def note_switches(sequences: dict[str, list[str]], active: Mapping[str, str]) -> None:
    """Append each variable's active MP to its sequence where it differs from the last one."""
    for v, seq in sequences.items():
        if active[v] != seq[-1]:
            seq.append(active[v])


@dataclass
class ScriptedRun(Generic[State]):
    """A scripted demonstrator's run (:func:`record_script`).

    Attributes:
        log: the samples, one every ``dt`` from ``t = 0``.
        state: the state at the end.
    """

    log: DemonstrationLog
    state: State


def record_script(
    task: SteppedTask[State, Episode],
    episode: Episode,
    features: Features[State],
    script: Callable[[np.ndarray, dict[str, str]], dict[str, str]],
    variables: Sequence[str],
) -> ScriptedRun[State]:
    """Record a scripted demonstrator every ``dt`` from ``t = 0`` until the goal or ``max_time``.

    Args:
        task: the world.
        episode: the episode.
        features: the world's features ``(d,)`` of a state.
        script: the demonstrator's MPs after a tick from that tick's features and the MPs
            before it.
        variables: the control variables, in the labels' order.

    Returns:
        The samples and the final state.
    """
    state = task.initial_state(episode)
    active = task.initial_mps(episode)
    log = DemonstrationLog(variables)
    t = 0.0
    while True:
        x = features(state)
        log.append(t, x, active)
        if task.at_goal(state, episode) or t >= task.max_time:
            break
        active = script(x, active)
        task.advance(state, episode, active)
        t = round(t + task.dt, 10)
    return ScriptedRun(log, state)


@dataclass
class PolicyRun(Generic[State]):
    """A policy's closed-loop run (:func:`run_policy`).

    Attributes:
        sequences: variable -> executed MPs in order.
        time: time [s] the goal state was reached, or the time the episode stopped.
        initial: the policy's initial MPs.
        reached_goal: whether the goal state was reached.
        state: the state at the end.
        cause: a run that did not reach the goal after the right start: its missing switch
            (:func:`~cpmp.records.episode_cause`), where the caller gave the demonstrator's
            sequences; ``None`` otherwise.
    """

    sequences: dict[str, list[str]]
    time: float
    initial: dict[str, str]
    reached_goal: bool
    state: State
    cause: PendingSwitch | None = None


def run_policy(
    task: SteppedTask[State, Episode],
    episode: Episode,
    policy: Policy,
    features: Features[State],
    variables: Sequence[str],
    observe: Callable[[np.ndarray], np.ndarray] | None = None,
    expected: ExpectedSequences[Episode] | None = None,
) -> PolicyRun[State]:
    """Run ``policy`` closed-loop on ``episode``, one tick every ``dt``, until the goal or time.

    Args:
        task: the world.
        episode: the episode.
        policy: reset at ``t = 0``, then stepped after every ``advance``.
        features: the world's features ``(d,)`` of a state.
        variables: the control variables.
        observe: maps the true features ``(d,)`` to what the policy sees; default: the true
            features.
        expected: the demonstrator's MP sequences of an episode: a run that misses the goal
            gets its ``cause``.

    Returns:
        The run; it stops at the goal state or at ``max_time``.
    """
    see = observe or (lambda x: x)
    state = task.initial_state(episode)
    active = dict(policy.reset(0.0, see(features(state))))
    initial = dict(active)
    seqs = {v: [active[v]] for v in variables}
    t = 0.0
    reached = task.at_goal(state, episode)
    while not reached and t < task.max_time - 1e-9:
        task.advance(state, episode, active)
        t = round(t + task.dt, 10)
        active = dict(policy.step(t, see(features(state))))
        note_switches(seqs, active)
        reached = task.at_goal(state, episode)
    cause = None
    if not reached and expected is not None:
        cause = episode_cause(policy, seqs, expected(episode))
    return PolicyRun(seqs, t, initial, reached, state, cause)


def run_policies(
    task: SteppedTask[State, Episode],
    episodes: Sequence[Episode],
    policy: Policy,
    features: EpisodeFeatures[State, Episode],
    variables: Sequence[str],
    expected: ExpectedSequences[Episode] | None = None,
) -> list[PolicyRun[State]]:
    """Run ``policy`` closed-loop on every one of ``episodes``, as :func:`run_policy` does.

    A policy with ``batched(n)`` (a fitted :class:`~cpmp.sequencer.ConcurrentSequencer`) runs
    every episode at once: one batched ``reset``, then one ``step`` per tick over the episodes
    still running (each stops at its goal state, all at ``max_time``); each episode's run is
    the one :func:`run_policy` gives it. Any other policy runs the episodes one after another.

    Args:
        task: the world.
        episodes: the episodes.
        policy: the policy (a fresh ``reset`` per episode, or one batch of them).
        features: the world's features ``(d,)`` of a state of an episode.
        variables: the control variables.
        expected: as in :func:`run_policy`.

    Returns:
        One run per episode, in order.
    """
    make_batch = getattr(policy, "batched", None)
    if make_batch is None or not episodes:
        return [
            run_policy(task, e, policy, lambda s, e=e: features(s, e), variables, None, expected)
            for e in episodes
        ]
    n = len(episodes)
    batch = make_batch(n)
    states = [task.initial_state(e) for e in episodes]
    x = np.stack([features(s, e) for s, e in zip(states, episodes, strict=True)])
    active = [dict(a) for a in batch.reset(0.0, x)]
    initial = [dict(a) for a in active]
    seqs = [{v: [a[v]] for v in variables} for a in active]
    reached = np.array([task.at_goal(s, e) for s, e in zip(states, episodes, strict=True)])
    times = [0.0] * n
    t = 0.0
    while not reached.all() and t < task.max_time - 1e-9:
        live = ~reached
        rows = np.flatnonzero(live).tolist()
        for i in rows:
            task.advance(states[i], episodes[i], active[i])
            x[i] = features(states[i], episodes[i])
        t = round(t + task.dt, 10)
        stepped = batch.step(t, x, live=live)
        for i in rows:
            active[i] = dict(stepped[i])
            note_switches(seqs[i], active[i])
            reached[i] = task.at_goal(states[i], episodes[i])
            times[i] = t
    causes = [
        episode_cause(batch, seqs[i], expected(episodes[i]), i)
        if expected is not None and not reached[i]
        else None
        for i in range(n)
    ]
    return [
        PolicyRun(seqs[i], times[i], initial[i], bool(reached[i]), states[i], causes[i])
        for i in range(n)
    ]
