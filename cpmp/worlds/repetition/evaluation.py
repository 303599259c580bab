"""Closed-loop runs of the repetition task (:mod:`cpmp.worlds.repetition.world`).

One episode under a policy (:func:`rollout`), its outcome against the demonstrator's MP
sequences, and the outcome counts over seeded random episodes (:func:`evaluate`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from cpmp.records import JsonValue, Policy
from cpmp.worlds.common import positive_count, run_policy, seeded_episodes
from cpmp.worlds.outcomes import OUTCOMES, Outcome, count_outcomes, episode_outcome
from cpmp.worlds.repetition.world import (
    STRATEGIES,
    VARIABLES,
    RepetitionEpisode,
    RepetitionTask,
)

__all__ = ["OUTCOMES", "RolloutResult", "evaluate", "outcome_counts", "rollout"]


@dataclass
class RolloutResult:
    """One closed-loop execution.

    Attributes:
        outcome: ``wrong_start`` (initial MPs differ from the demonstrator's), ``complete``
            (every variable ran exactly the demonstrator's MP sequence and the goal state was
            reached within ``max_time``) or ``incomplete``.
        sequences: variable -> executed MPs in order.
        expected: variable -> the demonstrator's MPs in order for this episode.
        time: time [s] the goal state was reached, or the time the episode stopped.
        initial: the policy's initial MPs.
        reached_goal: whether the goal state was reached (also after a wrong start or with
            other sequences).
        strategy: the episode's strategy.
        need: the episode's amount [l].
        spilled: soup poured beside the bowl [l].
    """

    outcome: Outcome
    sequences: dict[str, list[str]]
    expected: dict[str, list[str]]
    time: float
    initial: dict[str, str]
    reached_goal: bool
    strategy: str
    need: float
    spilled: float


def rollout(
    task: RepetitionTask,
    episode: RepetitionEpisode,
    policy: Policy,
    observe: Callable[[np.ndarray], np.ndarray] | None = None,
) -> RolloutResult:
    """Run ``policy`` closed-loop on ``episode``, one tick every ``task.dt``.

    Args:
        task: the task.
        episode: the episode.
        policy: ``reset(t, x)`` / ``step(t, x)`` -> variable -> MP.
        observe: maps the true features ``(7,)`` to what the policy sees (e.g. observation
            noise); default: the true features.

    Returns:
        The result; the episode runs until the goal state or ``max_time``.
    """
    expected = task.expected_sequences(episode)
    run = run_policy(task, episode, policy, task.features, VARIABLES, observe)
    started_right = run.initial == {v: s[0] for v, s in expected.items()}
    outcome = episode_outcome(started_right, run.reached_goal and run.sequences == expected)
    return RolloutResult(
        outcome,
        run.sequences,
        expected,
        run.time,
        run.initial,
        run.reached_goal,
        episode.strategy,
        episode.need,
        run.state.spilled,
    )


def evaluate(
    seq: Policy,
    task: RepetitionTask | None = None,
    n_episodes: int = 30,
    seed: int = 0,
    observe: Callable[[np.ndarray], np.ndarray] | None = None,
) -> dict[str, JsonValue]:
    """Closed-loop outcomes of a sequencer (or any policy) on random episodes.

    Args:
        seq: the policy.
        task: the task (default options if ``None``).
        n_episodes: episodes, cycling the strategies (``once``, ``twice``, ``thrice``, ...).
        seed: the episodes' random numbers (use a seed other than the demonstrations' for
            held-out episodes).
        observe: as in :func:`rollout`.

    Returns:
        ``{"complete", "wrong_start", "incomplete": int, "n_episodes": int, "by_strategy":
        {strategy: {outcome: int}}, "per_episode": [{"strategy", "need", "outcome", "time",
        "sequences", "spilled"}, ...]}``.

    Raises:
        ConfigError: ``n_episodes`` is not a positive integer.
    """
    positive_count(n_episodes, "n_episodes")
    task = task or RepetitionTask()
    episodes = seeded_episodes(task.sample_episode, STRATEGIES, n_episodes, seed)
    results = [rollout(task, episode, seq, observe) for episode in episodes]
    rows = [
        {
            "strategy": r.strategy,
            "need": r.need,
            "outcome": r.outcome,
            "time": r.time,
            "sequences": r.sequences,
            "spilled": r.spilled,
        }
        for r in results
    ]
    by_strategy = {
        s: outcome_counts([r for r in results if r.strategy == s])
        for s in STRATEGIES
        if any(r.strategy == s for r in results)
    }
    return {
        **outcome_counts(results),
        "n_episodes": n_episodes,
        "by_strategy": by_strategy,
        "per_episode": rows,
    }


def outcome_counts(results: Sequence[RolloutResult]) -> dict[Outcome, int]:
    """Number of results per outcome (every outcome present)."""
    return count_outcomes(r.outcome for r in results)
