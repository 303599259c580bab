"""The runner's policies (cpmp.sim.policies): label replay and batching of single policies."""

from __future__ import annotations

import numpy as np
import pytest

from cpmp.data.demonstration import Demonstration
from cpmp.errors import ConfigError
from cpmp.sim.policies import PolicyList, ReplayPolicy, as_batched, per_episode


def _demo() -> Demonstration:
    return Demonstration(
        time=np.array([0.0, 0.01, 0.02, 0.03]),
        features=np.zeros((4, 1)),
        labels={"v": np.array(["a", "a", "b", "c"])},
        feature_names=["x"],
    )


def test_replay_returns_the_labels_of_the_sample_at_or_before_t():
    policy = ReplayPolicy(_demo())
    assert policy.reset(0.0, np.zeros(1)) == {"v": "a"}
    assert [policy.step(t, np.zeros(1))["v"] for t in (0.015, 0.02, 0.029, 0.5)] == [
        "a",
        "b",
        "b",
        "c",
    ]


class Echo:
    """A single policy answering with the first feature it is given."""

    def reset(self, t, x):
        return {"v": f"reset {x[0]:g}"}

    def step(self, t, x):
        return {"v": f"step {x[0]:g} at {t:g}"}


def test_policy_list_calls_each_live_policy_with_its_row():
    batch = PolicyList([Echo(), Echo(), Echo()])
    x = np.array([[1.0], [2.0], [3.0]])
    assert batch.reset(0.0, x) == [{"v": "reset 1"}, {"v": "reset 2"}, {"v": "reset 3"}]
    live = np.array([True, False, True])
    assert batch.step(0.5, x, live=live) == [{"v": "step 1 at 0.5"}, {}, {"v": "step 3 at 0.5"}]


def test_as_batched_wraps_single_policies_and_checks_the_count():
    policies = [Echo(), Echo()]
    assert as_batched(policies, 2).policies == policies
    one = Echo()
    assert as_batched(one, 1).policies == [one]
    with pytest.raises(ConfigError, match="one policy per box"):
        as_batched(one, 2)
    with pytest.raises(ConfigError, match="runs 2 episodes, there are 3 boxes"):
        as_batched(policies, 3)


def test_per_episode_fills_none_and_checks_the_length():
    assert per_episode(None, 3, "names") == [None, None, None]
    assert per_episode(("a", "b"), 2, "names") == ["a", "b"]
    with pytest.raises(ConfigError, match="names must hold one entry per box"):
        per_episode(["a"], 2, "names")
