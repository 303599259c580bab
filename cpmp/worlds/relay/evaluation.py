"""Closed-loop runs of the relay task: one episode, its outcome, and the counts over many.

One episode of :mod:`cpmp.worlds.relay.world` under a policy (:func:`rollout`), its outcome
(:mod:`cpmp.worlds.outcomes`), and the outcome counts over seeded random episodes
(:func:`evaluate`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from cpmp.records import JsonValue, Policy
from cpmp.worlds.common import PolicyRun, positive_count, run_policies, run_policy, seeded_episodes
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
    run = run_policy(
        task, episode, policy, lambda state: task.features(state, episode), VARIABLES, observe
    )
    return _result(task, episode, run)


def _result(task: RelayTask, episode: RelayEpisode, run: PolicyRun) -> RolloutResult:
    """The :class:`RolloutResult` of ``run``, a closed-loop run of ``episode``."""
    expected = task.initial_mps(episode)
    outcome = episode_outcome(run.initial == expected, run.reached_goal)
    return RolloutResult(
        outcome, run.sequences, run.time, run.initial, expected, run.reached_goal, episode.strategy
    )


def evaluate(
    seq: Policy,
    task: RelayTask | None = None,
    n_episodes: int = 20,
    seed: int = 0,
    observe: Callable[[np.ndarray], np.ndarray] | None = None,
) -> dict[str, JsonValue]:
    """Closed-loop outcomes of a sequencer (or any policy) on random episodes.

    The episodes alternate the strategies and are reproducible from ``seed``. Without
    ``observe``, a fitted sequencer runs them all at once (:func:`~cpmp.worlds.common.
    run_policies`: the same results, faster).

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
    positive_count(n_episodes, "n_episodes")
    task = task or RelayTask()
    episodes = seeded_episodes(task.sample_episode, STRATEGIES, n_episodes, seed)
    if observe is None:
        runs = run_policies(task, episodes, seq, task.features, VARIABLES)
        results = [_result(task, e, r) for e, r in zip(episodes, runs, strict=True)]
    else:  # one at a time: observe may draw noise, in episode order
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
