"""The paced relay world (cpmp.worlds.relay.varied): varied speeds, holds, and its face."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from cpmp.config.task import Pacing
from cpmp.data.demonstration import mp_sequences
from cpmp.errors import ConfigError
from cpmp.sequencer import ConcurrentSequencer
from cpmp.worlds import relay
from cpmp.worlds.pacing import PacedWorld
from cpmp.worlds.relay.varied import (
    DEMO_PACING,
    MAX_TIME,
    PacedRelayTask,
    PacedScriptedPolicy,
    demonstrate,
    evaluate,
    make_demonstrations,
    paced_relay,
)
from cpmp.worlds.relay.world import VARIABLES, RelayTask


def fixed(speed: float) -> PacedRelayTask:
    """Every activation at ``speed``, no holds."""
    return PacedRelayTask(RelayTask(max_time=MAX_TIME), Pacing(speed=(speed, speed)))


def same(a, b) -> bool:
    return (
        np.array_equal(a.features, b.features)
        and np.array_equal(a.time, b.time)
        and all(np.array_equal(a.labels[v], b.labels[v]) for v in VARIABLES)
    )


def test_unpaced_demonstrations_are_the_relay_worlds():
    plain = relay.make_demonstrations(4, seed=3)
    unpaced = make_demonstrations(4, seed=3, task=PacedRelayTask(RelayTask(), Pacing()))
    assert all(same(a, b) for a, b in zip(plain, unpaced, strict=True))


def test_advance_without_speed_is_unchanged_and_zero_speed_holds():
    task = RelayTask()
    episode = task.sample_episode(np.random.default_rng(0), "meet")
    active = task.initial_mps(episode)
    a, b, c = (task.initial_state(episode) for _ in range(3))
    task.advance(a, episode, active)
    task.advance(b, episode, active, speed={"carrier": 1.0, "gripper": 1.0, "receiver": 1.0})
    task.advance(c, episode, active, speed={"carrier": 0.0})
    assert np.array_equal(a.carrier, b.carrier) and np.array_equal(a.receiver, b.receiver)
    assert np.array_equal(c.carrier, episode.carrier_home) and np.array_equal(
        c.receiver, a.receiver
    )


def test_durations_shrink_by_the_speed_factor():
    slow = make_demonstrations(4, seed=0, task=fixed(0.5))
    fast = make_demonstrations(4, seed=0, task=fixed(1.0))
    for s, f in zip(slow, fast, strict=True):
        assert mp_sequences(s) == mp_sequences(f)
        # every gain x2: the same path in half the time. Euler steps contract by (1 - dt K f)
        # per tick: ln(0.98) vs ln(0.96) / 2 at the largest gain, rates 1 % apart
        assert f.time[-1] * 2 == pytest.approx(s.time[-1], rel=0.015)
        assert f.time[-1] * 2 != s.time[-1]  # not by accident the same run


def test_a_hold_is_a_run_of_unchanged_features_of_the_drawn_length():
    task = PacedRelayTask(RelayTask(max_time=MAX_TIME), Pacing(pause=(0.5, 0.5)))
    demo = demonstrate(task, task.episodes(1, seed=0, stream=0)[0])
    labels = demo.labels["carrier"]
    carrier = demo.features[labels == labels[0], 0:2]  # its first activation
    still = np.all(np.diff(carrier, axis=0) == 0.0, axis=1).astype(int)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], still, [0]])))
    # one hold of 0.5 s at 100 Hz: 50 ticks without a move, and nowhere else standing still
    assert list(edges[1::2] - edges[::2]) == [50]
    assert demo.metadata["holds"] >= 1


def test_paced_demonstrations_vary_and_reach_the_goal():
    paced = make_demonstrations(6, seed=0)
    plain = relay.make_demonstrations(6, seed=0)
    for a, b in zip(paced, plain, strict=True):
        assert a.metadata["reached_goal"] and a.metadata["strategy"] == b.metadata["strategy"]
        for variable in ("gripper", "receiver"):  # the carrier may reach the goal before rest
            assert mp_sequences(a)[variable] == mp_sequences(b)[variable]
    assert sum(d.metadata["holds"] for d in paced) > 0
    ratios = {round(float(a.time[-1] / b.time[-1]), 2) for a, b in zip(paced, plain, strict=True)}
    assert len(ratios) > 3


def test_same_seed_same_demonstrations():
    a, b, c = (paced_relay(s, 4).demonstrations for s in (0, 0, 1))
    assert all(same(x, y) and x.metadata == y.metadata for x, y in zip(a, b, strict=True))
    assert not any(same(x, y) for x, y in zip(a, c, strict=True))


def test_paced_world_face_scores_every_episode():
    world = paced_relay(0, 2, demo=DEMO_PACING, robot=Pacing(speed=(0.5, 2.0)))
    assert isinstance(world, PacedWorld) and len(world.demonstrations) == 2
    task = PacedRelayTask(pacing=Pacing(speed=(0.5, 2.0)))
    episode = task.episodes(1, seed=7, stream=1)[0]
    # the demonstrator as the policy: it knows the episode, so it completes it
    scores = evaluate(PacedScriptedPolicy(task, episode), task, n_episodes=1, seed=7)
    assert [(s.outcome, s.strategy) for s in scores] == [("complete", "meet")]
    assert scores[0].time > 0


def test_a_fitted_sequencer_scores_as_it_does_one_episode_at_a_time(one_at_a_time):
    torch.set_num_threads(1)
    demonstrated = paced_relay(0, 2, relay=RelayTask(max_time=6.0))
    seq = ConcurrentSequencer.fit(demonstrated.demonstrations, seed=0, logger=None)
    # run with a limit short enough that one started episode times out (the others take
    # 3.7 s or start wrong): every outcome goes through both paths
    world = paced_relay(0, 2, relay=RelayTask(max_time=4.5))
    batched = world.evaluate(seq, 6, 9)  # all six episodes at once (seq.batched)
    assert batched == world.evaluate(one_at_a_time(seq), 6, 9)
    assert {s.outcome for s in batched} == {"complete", "incomplete", "wrong_start"}


def test_bad_counts_raise_config_error():
    with pytest.raises(ConfigError, match="n must be a positive integer"):
        make_demonstrations(0)
    with pytest.raises(ConfigError, match="n_episodes must be a positive integer"):
        evaluate(PacedScriptedPolicy(PacedRelayTask(), None), n_episodes=0)
