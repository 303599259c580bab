"""Closed-loop runs of the relay task: one episode, its outcome, and the counts over many.

One episode of :mod:`cpmp.worlds.relay.world` under a policy (:func:`rollout`), its outcome
(:mod:`cpmp.worlds.outcomes`), and the outcome counts over seeded random episodes
(:func:`evaluate`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from cpmp.errors import ConfigError
from cpmp.records import Policy
from cpmp.worlds.outcomes import OUTCOMES, Outcome, count_outcomes, episode_outcome
from cpmp.worlds.relay.world import STRATEGIES, VARIABLES, RelayEpisode, RelayTask, Strategy

__all__ = ["OUTCOMES", "RolloutResult", "evaluate", "outcome_counts", "rollout"]


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

    outcome: Outcome
    sequences: dict[str, list[str]]
    time: float
    initial: dict[str, str]
    expected_initial: dict[str, str]
    reached_goal: bool
    strategy: Strategy


def rollout(
    task: RelayTask,
    episode: RelayEpisode,
    policy: Policy,
    observe: Callable[[np.ndarray], np.ndarray] | None = None,
) -> RolloutResult:
    """Run ``policy`` closed-loop on ``episode`` until the goal state or ``max_time``.

    ``observe`` maps the true features ``(6,)`` to what the policy sees (e.g. observation
    noise with :func:`cpmp.data.augment.noisy_features`); default: the true features.
    """
    see = observe or (lambda x: x)
    state = task.initial_state(episode)
    expected = task.initial_mps(episode)
    active = dict(policy.reset(0.0, see(task.features(state, episode))))
    initial = dict(active)
    seqs = {v: [active[v]] for v in VARIABLES}
    t = 0.0
    reached = task.at_goal(state, episode)
    while not reached and t < task.max_time - 1e-9:
        task.advance(state, episode, active)
        t = round(t + task.dt, 10)
        active = dict(policy.step(t, see(task.features(state, episode))))
        for v in VARIABLES:
            if active[v] != seqs[v][-1]:
                seqs[v].append(active[v])
        reached = task.at_goal(state, episode)
    outcome = episode_outcome(initial == expected, reached)
    return RolloutResult(outcome, seqs, t, initial, expected, reached, episode.strategy)


def evaluate(
    seq: Policy,
    task: RelayTask | None = None,
    n_episodes: int = 20,
    seed: int = 0,
    observe: Callable[[np.ndarray], np.ndarray] | None = None,
) -> dict[str, Any]:
    """Closed-loop outcomes of a sequencer (or any policy) on random episodes.

    The episodes alternate the strategies and are reproducible from ``seed``.

    Args:
        seq: the policy.
        task: the task (default: :class:`~cpmp.worlds.relay.RelayTask`'s defaults).
        n_episodes: the number of episodes.
        seed: seeds the episodes (use another than the demonstrations' for held-out ones).
        observe: as in :func:`rollout`.

    Returns:
        ``{"complete": int, "wrong_start": int, "incomplete": int, "n_episodes": int,
        "per_episode": [{"strategy", "context", "outcome", "time", "sequences"}, ...]}``.

    Raises:
        ConfigError: ``n_episodes`` is not a positive integer.
    """
    if isinstance(n_episodes, bool) or not isinstance(n_episodes, int) or n_episodes < 1:
        raise ConfigError(f"n_episodes must be a positive integer, got {n_episodes!r}")
    task = task or RelayTask()
    rng = np.random.default_rng(seed)
    episodes = [task.sample_episode(rng, STRATEGIES[i % 2]) for i in range(n_episodes)]
    results = [rollout(task, episode, seq, observe) for episode in episodes]
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


def outcome_counts(results: Sequence[RolloutResult]) -> dict[Outcome, int]:
    """Number of results per outcome (every outcome present)."""
    return count_outcomes(r.outcome for r in results)
