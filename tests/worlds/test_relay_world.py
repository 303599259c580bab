"""The relay task's world (cpmp.worlds.relay.world): episodes, options, features."""

import numpy as np
import pytest

from cpmp.errors import ConfigError
from cpmp.worlds.relay.world import CONTEXT_SCALE, STRATEGIES, RelayTask


def test_sample_episode_contexts():
    task = RelayTask()
    rng = np.random.default_rng(0)
    for strategy in STRATEGIES:
        for _ in range(20):
            episode = task.sample_episode(rng, strategy)
            assert episode.strategy == strategy and abs(episode.context - 0.5) >= 0.05
    assert task.sample_episode(rng, context=0.7).strategy == "fetch"


@pytest.mark.parametrize(
    "options",
    [
        {"dt": 0.0},
        {"gain_carrier": -1.0},
        {"dt": 0.5},  # unstable Euler step
        {"max_time": float("nan")},
        {"tolerance": 0.2},  # wider than the contact radius
        {"contact_force": 0.5},  # above the force `close` settles at
        {"start_jitter": -0.1},
        {"context_gap": 1.0},
        {"object_width": "wide"},
    ],
)
def test_bad_task_options_raise(options):
    with pytest.raises(ConfigError):
        RelayTask(**options)


def test_bad_episode_arguments_raise():
    task = RelayTask()
    rng = np.random.default_rng(0)
    with pytest.raises(ConfigError, match="strategy"):
        task.sample_episode(rng, "juggle")
    with pytest.raises(ConfigError, match="context"):
        task.sample_episode(rng, context=1.5)


def test_initial_features_are_the_homes_and_the_scaled_context():
    task = RelayTask()
    episode = task.sample_episode(np.random.default_rng(5), "fetch")
    state = task.initial_state(episode)
    want = [*episode.carrier_home, *episode.receiver_home, 0.0, CONTEXT_SCALE * episode.context]
    np.testing.assert_array_equal(task.features(state, episode), want)
    assert np.array_equal(state.obj, episode.carrier_home) and state.holder == "carrier"
    assert not task.at_goal(state, episode)


def test_shortfall_names_each_goal_condition_not_met():
    """At the goal the shortfall is empty; each condition of ``at_goal`` broken names itself
    (who holds the object, how far it is from its destination, the gripper, the carrier's
    distance from home), in that order; a run's ``failure()`` is the task's shortfall."""
    from cpmp.worlds.protocol import SteppedRun, run_failure

    task = RelayTask()
    episode = task.sample_episode(np.random.default_rng(3), "fetch")
    run = SteppedRun(task, episode)
    at_goal = run.state
    at_goal.holder, at_goal.aperture = "none", 1.0
    at_goal.obj = episode.destination.astype(float).copy()
    at_goal.carrier = episode.carrier_home.astype(float).copy()
    assert task.at_goal(at_goal, episode) and task.shortfall(at_goal, episode) == ""
    assert run.failure() == run_failure(run) == ""

    at_goal.obj = at_goal.obj + np.array([0.1, 0.0])  # released 100 mm short
    assert not task.at_goal(at_goal, episode)
    assert run.failure() == "the object is 100 mm from its destination"

    at_goal.holder, at_goal.aperture = "receiver", 0.2
    at_goal.carrier = at_goal.carrier + np.array([0.0, 0.25])
    assert task.shortfall(at_goal, episode) == (
        "the receiver still holds the object; the object is 100 mm from its destination; "
        "the gripper is not open; the carrier is 250 mm from home"
    )


def test_the_paced_relay_says_what_the_relay_says():
    """A paced relay run's ``failure()`` is the relay task's shortfall of its relay state."""
    from cpmp.worlds.registry import make_world

    world = make_world("paced_relay")
    run = world.start(world.contexts(1, 0)[0])
    relay = world.robot_task.relay
    text = relay.shortfall(run.state.relay, run.episode.relay)
    assert text.startswith("the carrier still holds the object; the object is ")
    assert run.failure() == text
