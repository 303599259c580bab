"""The repetition task's scripted demonstrator (cpmp.worlds.repetition.demonstrator)."""

import math

import numpy as np
import pytest

from cpmp.errors import ConfigError
from cpmp.graph import build_graphs
from cpmp.worlds.repetition.demonstrator import ScriptedPolicy, demonstrate, make_demonstrations
from cpmp.worlds.repetition.evaluation import rollout
from cpmp.worlds.repetition.world import (
    AMOUNT_EPS,
    FEATURE_NAMES,
    STRATEGIES,
    VARIABLES,
    RepetitionTask,
)

FILL = FEATURE_NAMES.index("ladle_fill")
LEVEL = FEATURE_NAMES.index("bowl_level")
REMAINING = FEATURE_NAMES.index("remaining")


@pytest.fixture(scope="module")
def episodes_and_demos():
    """Three episodes per strategy and their demonstrations."""
    task = RepetitionTask()
    rng = np.random.default_rng(7)
    episodes = [task.sample_episode(rng, STRATEGIES[i % 3]) for i in range(9)]
    return [(e, demonstrate(task, e)) for e in episodes]


def test_demonstrations_are_reproducible():
    demos, again, other = (make_demonstrations(6, seed=s) for s in (0, 0, 1))
    for a, b, c in zip(demos, again, other, strict=True):
        assert np.array_equal(a.features, b.features) and np.array_equal(a.time, b.time)
        assert all(np.array_equal(a.labels[v], b.labels[v]) for v in VARIABLES)
        assert a.metadata == b.metadata
        assert a.metadata["need"] != c.metadata["need"]


def test_demonstrations_labelled_as_designed():
    demos = make_demonstrations(6, seed=0)
    for i, demo in enumerate(demos):
        k = i % 3 + 1
        assert demo.feature_names == FEATURE_NAMES and demo.variables == VARIABLES
        assert demo.name == f"demo_{i}" and demo.metadata["reached_goal"] is True
        assert demo.metadata["strategy"] == STRATEGIES[i % 3]
        assert demo.metadata["repetitions"] == k
        sequences = {v: [s.mp for s in demo.segments(v)] for v in VARIABLES}
        assert sequences == {
            "bowl": ["present", "hold", "serve"],
            "ladle": ["scoop", "pour"] * k + ["rest"],
        }
        np.testing.assert_allclose(np.diff(demo.time), 0.01)
    graphs = build_graphs(demos)
    assert graphs["ladle"].edges == {("scoop", "pour"), ("pour", "scoop"), ("pour", "rest")}
    assert graphs["bowl"].edges == {("present", "hold"), ("hold", "serve")}


def test_repetitions_follow_the_amount_in_the_state(episodes_and_demos):
    task = RepetitionTask()
    for episode, demo in episodes_and_demos:
        x = demo.features
        np.testing.assert_allclose(x[:, LEVEL] + x[:, REMAINING], episode.need)
        pours = [s for s in demo.segments("ladle") if s.mp == "pour"]
        assert len(pours) == math.ceil(episode.need / task.capacity) == episode.repetitions
        labels = demo.labels["ladle"]
        for i in demo.switch_indices("ladle"):
            if labels[i - 1] == "pour":
                # the cycle exit: again while soup remains, on after the last pour
                again = x[i - 1, REMAINING] > AMOUNT_EPS
                assert labels[i] == ("scoop" if again else "rest")
        assert x[-1, REMAINING] <= AMOUNT_EPS and x[-1, LEVEL] == pytest.approx(episode.need)


def test_guards_hold_at_the_tick_of_each_switch(episodes_and_demos):
    task = RepetitionTask()
    for episode, demo in episodes_and_demos:
        x, bowl, ladle = demo.features, demo.labels["bowl"], demo.labels["ladle"]
        at_spot = np.linalg.norm(x[:, 3:5] - episode.spot, axis=1) < task.tolerance
        full = x[:, FILL] >= np.minimum(task.capacity, x[:, REMAINING])
        (hold, serve) = demo.switch_indices("bowl")
        assert at_spot[hold - 1] and not at_spot[hold - 2]
        for i in demo.switch_indices("ladle"):
            if ladle[i] == "pour":  # the ladle is full and the bowl held out
                assert full[i - 1] and bowl[i - 1] == "hold"
                assert not (full[i - 2] and bowl[i - 2] == "hold")
            else:  # the ladle has just emptied
                assert x[i - 1, FILL] <= AMOUNT_EPS < x[i - 2, FILL]
        # the waiting variable holds across every repetition and moves on with the last pour
        first_pour, to_rest = demo.switch_indices("ladle")[0], demo.switch_indices("ladle")[-1]
        assert set(bowl[first_pour:to_rest]) == {"hold"}
        assert serve == to_rest and x[serve - 1, REMAINING] <= AMOUNT_EPS


@pytest.mark.parametrize("dt", [0.01, 1 / 30, 0.001])
def test_scripted_policy_completes_every_strategy_at_any_rate(dt):
    task = RepetitionTask(dt=dt)
    rng = np.random.default_rng(11)
    n = 6 if dt == 0.01 else 3
    for i in range(n):
        episode = task.sample_episode(rng, STRATEGIES[i % 3])
        result = rollout(task, episode, ScriptedPolicy(task, episode))
        assert result.outcome == "complete", result
        assert result.sequences == task.expected_sequences(episode)
        assert result.spilled == 0.0
        assert result.time == pytest.approx(demonstrate(task, episode).duration, abs=dt + 1e-9)


def test_make_demonstrations_rejects_a_bad_count():
    with pytest.raises(ConfigError, match="positive integer"):
        make_demonstrations(0)
