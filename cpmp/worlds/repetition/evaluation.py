"""Closed-loop runs of the repetition task (:mod:`cpmp.worlds.repetition.world`).

One episode under a policy (:func:`rollout`), its outcome against the demonstrator's MP
sequences, and the outcome counts over seeded random episodes (:func:`evaluate`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from cpmp.errors import ConfigError
from cpmp.records import Policy
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
    see = observe or (lambda x: x)
    state = task.initial_state(episode)
    expected = task.expected_sequences(episode)
    active = dict(policy.reset(0.0, see(task.features(state))))
    initial = dict(active)
    seqs = {v: [active[v]] for v in VARIABLES}
    t = 0.0
    reached = task.at_goal(state, episode)
    while not reached and t < task.max_time - 1e-9:
        task.advance(state, episode, active)
        t = round(t + task.dt, 10)
        active = dict(policy.step(t, see(task.features(state))))
        for v in VARIABLES:
            if active[v] != seqs[v][-1]:
                seqs[v].append(active[v])
        reached = task.at_goal(state, episode)
    started_right = initial == {v: s[0] for v, s in expected.items()}
    outcome = episode_outcome(started_right, reached and seqs == expected)
    return RolloutResult(
        outcome, seqs, expected, t, initial, reached, episode.strategy, episode.need, state.spilled
    )


def evaluate(
    seq: Policy,
    task: RepetitionTask | None = None,
    n_episodes: int = 30,
    seed: int = 0,
    observe: Callable[[np.ndarray], np.ndarray] | None = None,
) -> dict[str, Any]:
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
    if isinstance(n_episodes, bool) or not isinstance(n_episodes, int) or n_episodes < 1:
        raise ConfigError(f"n_episodes must be a positive integer, got {n_episodes!r}")
    task = task or RepetitionTask()
    rng = np.random.default_rng(seed)
    episodes = [
        task.sample_episode(rng, STRATEGIES[i % len(STRATEGIES)]) for i in range(n_episodes)
    ]
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
