"""The comparison's synthetic worlds: each registered world's runs agree with the world's own
evaluation, demonstrations are reproducible, bad options and names are refused."""

from __future__ import annotations

import pytest
import torch

from cpmp.compare.worlds import SYNTHETIC_WORLDS, World, synthetic_run
from cpmp.errors import ConfigError
from cpmp.sequencer import ConcurrentSequencer
from cpmp.worlds import relay, two_point
from cpmp.worlds.registry import entry, make_world

torch.set_num_threads(1)


@pytest.fixture(scope="module")
def two_point_seq() -> ConcurrentSequencer:
    return ConcurrentSequencer.fit(two_point.make_demonstrations(4, seed=0), seed=0, logger=None)


@pytest.fixture(scope="module")
def relay_seq() -> ConcurrentSequencer:
    return ConcurrentSequencer.fit(relay.make_demonstrations(4, seed=0), seed=0, logger=None)


def test_two_point_episodes_are_the_worlds_own_evaluation(two_point_seq):
    """The per-episode outcomes count up to ``two_point.evaluate``'s on the same seed (the
    comparison redraws the episodes to see each one), and the strategies follow the
    contexts."""
    run = synthetic_run("two_point", {}, seed=0, n_demos=4)
    episodes = run.evaluate(two_point_seq, 12, 7)
    counts = two_point.evaluate(two_point_seq, n_episodes=12, seed=7)
    assert {o: sum(e.outcome == o for e in episodes) for o in counts} == counts
    assert {e.strategy for e in episodes} == {"parallel", "sequential"}
    assert sum(e.outcome == "complete" for e in episodes) >= 6  # a fitted policy completes


def test_relay_episodes_are_the_worlds_own_evaluation(relay_seq):
    run = synthetic_run("relay", {}, seed=0, n_demos=4)
    episodes = run.evaluate(relay_seq, 6, 3)
    expected = relay.evaluate(relay_seq, n_episodes=6, seed=3)["per_episode"]
    assert [(e.outcome, e.strategy) for e in episodes] == [
        (e["outcome"], e["strategy"]) for e in expected
    ]


@pytest.mark.parametrize("name", sorted(SYNTHETIC_WORLDS))
def test_demonstrations_are_reproducible_and_options_reach_the_task(name):
    a = synthetic_run(name, {}, seed=1, n_demos=3).demonstrations
    b = synthetic_run(name, {}, seed=1, n_demos=3).demonstrations
    other = synthetic_run(name, {}, seed=2, n_demos=3).demonstrations
    assert len(a) == 3
    for x, y in zip(a, b, strict=True):
        assert (x.features == y.features).all()
    assert any(x.features.shape != y.features.shape for x, y in zip(a, other, strict=True)) or any(
        (x.features != y.features).any() for x, y in zip(a, other, strict=True)
    )


def test_world_options_change_the_demonstrations():
    slow = synthetic_run("two_point", {"gain": [1.5, 2.0]}, seed=0, n_demos=1).demonstrations[0]
    base = synthetic_run("two_point", {}, seed=0, n_demos=1).demonstrations[0]
    assert len(slow.time) > len(base.time)  # lower gains: a longer demonstration
    paced = synthetic_run(
        "paced_relay", {"demo": {"speed": [0.5, 0.5], "pause": None}}, seed=0, n_demos=1
    ).demonstrations[0]
    nominal = synthetic_run(
        "paced_relay", {"demo": {"speed": [1.0, 1.0], "pause": None}}, seed=0, n_demos=1
    ).demonstrations[0]
    assert len(paced.time) > len(nominal.time)  # half speed: longer


@pytest.mark.parametrize(
    ("name", "options", "message"),
    [
        ("nope", {}, "unknown synthetic world 'nope'"),
        ("two_point", {"gian": 2.0}, "bad task option for the two_point world"),
        ("relay", {"dt": -1.0}, "dt must be > 0"),
        ("paced_relay", {"speed": [1, 2]}, "bad task option for the paced_relay world"),
        ("paced_relay", {"demo": {"speed": [0.0, 2.0]}}, "speed"),
    ],
)
def test_bad_worlds_and_options_are_refused(name, options, message):
    with pytest.raises(ConfigError, match=message):
        synthetic_run(name, options, seed=0, n_demos=1)


def test_world_label_names_what_differs():
    world = World(
        name="noisy",
        kind="sim",
        world=None,
        options={"settle_time": 0.0},
        feature_noise=0.05,
        seeds=(0,),
        train_sizes=(3,),
        episodes=20,
        test_demos=6,
        predictors="all",
        baselines=(),
    )
    assert world.label() == "noisy (simulator: settle_time=0.0, feature_noise=0.05)"


@pytest.mark.parametrize("name", SYNTHETIC_WORLDS)
def test_every_registered_world_can_be_compared(name):
    """The comparison's synthetic worlds are the registry's: each one runs with no code here
    (a family's member chosen by its ``task`` option)."""
    options = {"task": 1} if entry(name).family else {}
    run = synthetic_run(name, options, seed=0, n_demos=2)
    assert len(run.demonstrations) == 2
    scored = run.evaluate(ScriptedOnly(name, options), 3, 1000)
    assert [e.outcome for e in scored] == ["complete"] * 3  # the world's own fair policy


class ScriptedOnly:
    """The world's feature-only scripted policy, made fresh as the comparison makes a policy."""

    def __init__(self, name, options):
        self.policy = make_world(name, options).scripted_policy()

    def reset(self, t, x):
        return self.policy.reset(t, x)

    def step(self, t, x):
        return self.policy.step(t, x)
