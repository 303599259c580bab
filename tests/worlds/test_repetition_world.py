"""The repetition task's world (cpmp.worlds.repetition.world): episodes, options, dynamics."""

import numpy as np
import pytest

from cpmp.errors import ConfigError, UnknownMPError
from cpmp.worlds.repetition.world import (
    FEATURE_NAMES,
    REPETITIONS,
    STRATEGIES,
    RepetitionTask,
)


def test_needs_follow_the_strategy_and_decide_it():
    task = RepetitionTask()
    rng = np.random.default_rng(0)
    for strategy in STRATEGIES:
        k = REPETITIONS[strategy]
        for _ in range(20):
            episode = task.sample_episode(rng, strategy)
            assert episode.strategy == strategy and episode.repetitions == k
            assert k - 1 + task.need_margin <= episode.need <= k - task.need_margin
    for need, strategy in [(0.3, "once"), (1.0, "once"), (1.01, "twice"), (2.9, "thrice")]:
        assert task.sample_episode(rng, need=need).strategy == strategy
    with pytest.raises(ConfigError, match="strategy"):
        task.sample_episode(rng, "four")
    with pytest.raises(ConfigError, match="need"):
        task.sample_episode(rng, need=3.5)


@pytest.mark.parametrize(
    "options",
    [
        {"dt": 0.0},
        {"gain_ladle": -1.0},
        {"dt": 0.5},  # unstable Euler step
        {"tolerance": 0.06},  # not below flow_radius
        {"need_margin": 0.5},
        {"start_jitter": 0.3},
        {"max_time": 0.05},
        {"capacity": float("nan")},
    ],
)
def test_bad_options_are_refused(options):
    with pytest.raises(ConfigError):
        RepetitionTask(**options)


def test_control_period_is_configurable():
    for dt in (1 / 30, 0.001):
        assert RepetitionTask(dt=dt).dt == dt
    task = RepetitionTask()
    episode = task.sample_episode(np.random.default_rng(1), "once")
    active = task.initial_mps(episode)
    slow, fast = task.initial_state(episode), task.initial_state(episode)
    task.advance(slow, episode, active)
    task.advance(fast, episode, active, dt=0.001)
    start = episode.ladle_home
    assert np.linalg.norm(fast.ladle - start) == pytest.approx(
        0.1 * np.linalg.norm(slow.ladle - start)
    )
    with pytest.raises(ConfigError, match="stable"):
        task.advance(slow, episode, active, dt=0.5)


def test_features_and_unknown_mps():
    task = RepetitionTask()
    episode = task.sample_episode(np.random.default_rng(2), "twice")
    state = task.initial_state(episode)
    x = task.features(state)
    assert x.shape == (len(FEATURE_NAMES),) == (7,)
    level, remaining = x[FEATURE_NAMES.index("bowl_level")], x[FEATURE_NAMES.index("remaining")]
    assert (level, remaining) == (0.0, episode.need)
    with pytest.raises(UnknownMPError, match="unknown MP"):
        task.advance(state, episode, {"ladle": "stir", "bowl": "hold"})


def test_soup_goes_into_the_bowl_only_when_it_is_in_place():
    task = RepetitionTask()
    episode = task.sample_episode(np.random.default_rng(3), "once")
    pouring = {"ladle": "pour", "bowl": "hold"}
    for bowl_at, into_bowl in [(episode.spot, True), (episode.bowl_home, False)]:
        state = task.initial_state(episode)
        state.ladle, state.bowl, state.fill = episode.spot.copy(), bowl_at.copy(), 0.5
        for _ in range(10):
            task.advance(state, episode, pouring)
        poured = 10 * task.dt * task.pour_rate
        assert state.fill == pytest.approx(0.5 - poured)
        if into_bowl:
            assert (state.remaining, state.spilled) == (pytest.approx(episode.need - poured), 0)
        else:
            assert (state.remaining, state.spilled) == (episode.need, pytest.approx(poured))


def test_the_ladle_fills_only_what_remains():
    task = RepetitionTask()
    episode = task.sample_episode(np.random.default_rng(4), "once")
    state = task.initial_state(episode)
    state.ladle = episode.pot.copy()
    for _ in range(200):
        task.advance(state, episode, {"ladle": "scoop", "bowl": "present"})
    assert state.fill == episode.need < task.capacity
