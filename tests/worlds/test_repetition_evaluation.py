"""Closed-loop runs of the repetition task (cpmp.worlds.repetition.evaluation): outcomes against
the demonstrator's sequences, the observation hook and the counts of evaluate."""

import numpy as np
import pytest

from cpmp.errors import ConfigError, UnknownMPError
from cpmp.worlds.repetition.demonstrator import ScriptedPolicy, script
from cpmp.worlds.repetition.evaluation import OUTCOMES, evaluate, rollout
from cpmp.worlds.repetition.world import FEATURE_NAMES, STRATEGIES, RepetitionTask

REMAINING = FEATURE_NAMES.index("remaining")


class Fixed:
    """A policy that starts with ``start`` and never switches."""

    def __init__(self, start: dict[str, str]) -> None:
        self.start = dict(start)

    def reset(self, t, x):
        return dict(self.start)

    def step(self, t, x):
        return dict(self.start)


class MovesOnEarly(ScriptedPolicy):
    """The demonstrator, but both variables move on after the first pour."""

    def step(self, t, x):
        x = np.array(x, dtype=float)
        if self.active["ladle"] == "pour":
            x[REMAINING] = 0.0  # reads the amount as poured
        return super().step(t, x)


class ExtraCycle(ScriptedPolicy):
    """The demonstrator, but after the last pour the ladle scoops and pours once more (empty)."""

    def __init__(self, task, episode):
        super().__init__(task, episode)
        self.extra = "pending"

    def step(self, t, x):
        new = script(self.task, np.asarray(x, float), self.episode, self.active)
        if self.extra == "pending" and new["ladle"] == "rest":
            new["ladle"], self.extra = "scoop", "scoop"
        elif self.extra == "scoop" and np.linalg.norm(x[:2] - self.episode.pot) < 0.05:
            new["ladle"], self.extra = "pour", "pour"
        elif self.extra == "pour" and np.linalg.norm(x[:2] - self.episode.spot) < 0.05:
            new["ladle"], self.extra = "rest", "done"
        self.active = new
        return dict(new)


def test_wrong_start_and_incomplete_outcomes():
    task = RepetitionTask()
    episode = task.sample_episode(np.random.default_rng(3), "twice")
    start = task.initial_mps(episode)
    stuck = rollout(task, episode, Fixed(start))
    assert (stuck.outcome, stuck.reached_goal, stuck.time) == ("incomplete", False, task.max_time)
    assert stuck.sequences == {v: [mp] for v, mp in start.items()}
    wrong = rollout(task, episode, Fixed({**start, "ladle": "pour"}))
    assert wrong.outcome == "wrong_start" and wrong.initial["ladle"] == "pour"
    with pytest.raises(UnknownMPError, match="unknown MP"):
        rollout(task, episode, Fixed({**start, "bowl": "drop"}))


def test_moving_on_after_the_first_repetition_is_incomplete():
    task = RepetitionTask()
    episode = task.sample_episode(np.random.default_rng(4), "twice")
    result = rollout(task, episode, MovesOnEarly(task, episode))
    assert result.sequences == {
        "bowl": ["present", "hold", "serve"],
        "ladle": ["scoop", "pour", "rest"],
    }
    assert result.outcome == "incomplete" and not result.reached_goal


def test_complete_needs_the_demonstrated_sequence_not_only_the_goal():
    task = RepetitionTask()
    episode = task.sample_episode(np.random.default_rng(5), "once")
    result = rollout(task, episode, ExtraCycle(task, episode))
    assert result.sequences["ladle"] == ["scoop", "pour", "scoop", "pour", "rest"]
    assert result.reached_goal and result.outcome == "incomplete"
    assert result.expected["ladle"] == ["scoop", "pour", "rest"]


def test_observation_hook_sees_every_tick():
    task = RepetitionTask(max_time=0.5)
    episode = task.sample_episode(np.random.default_rng(0), "once")
    seen = []

    def observe(x):
        seen.append(x)
        return x + 1.0

    class Recorder(Fixed):
        def step(self, t, x):
            assert np.array_equal(x, seen[-1] + 1.0)
            return super().step(t, x)

    result = rollout(task, episode, Recorder(task.initial_mps(episode)), observe=observe)
    assert result.outcome == "incomplete"
    assert len(seen) == 51 and all(x.shape == (7,) for x in seen)  # reset + 50 ticks


def test_evaluate_counts_by_strategy():
    task = RepetitionTask(max_time=1.0)
    start = {"bowl": "present", "ladle": "scoop"}
    result = evaluate(Fixed(start), task, n_episodes=5, seed=0)
    assert {k: result[k] for k in OUTCOMES} == {"complete": 0, "wrong_start": 0, "incomplete": 5}
    assert [row["strategy"] for row in result["per_episode"]] == [*STRATEGIES, *STRATEGIES[:2]]
    assert {s: sum(c.values()) for s, c in result["by_strategy"].items()} == {
        "once": 2,
        "twice": 2,
        "thrice": 1,
    }
    with pytest.raises(ConfigError, match="positive integer"):
        evaluate(Fixed(start), task, n_episodes=0)
