"""What the synthetic worlds share (cpmp.worlds.common): many episodes of one policy at once."""

from __future__ import annotations

import pytest
import torch

from cpmp.sequencer import ConcurrentSequencer
from cpmp.worlds import relay
from cpmp.worlds.common import run_policies, run_policy, seeded_episodes
from cpmp.worlds.relay.world import STRATEGIES, VARIABLES, RelayTask

torch.set_num_threads(1)


@pytest.fixture(scope="module")
def relay_seq() -> ConcurrentSequencer:
    # two demonstrations: a weak fit, so the episodes end in every way
    return ConcurrentSequencer.fit(relay.make_demonstrations(2, seed=0), seed=0, logger=None)


@pytest.mark.slow
def test_a_batch_runs_each_episode_as_run_policy_does(relay_seq):
    # short: some episodes stop at the limit (half of these 10), others before at different ticks
    task = RelayTask(max_time=4.6)
    episodes = seeded_episodes(task.sample_episode, STRATEGIES, 10, seed=4)
    batched = run_policies(task, episodes, relay_seq, task.features, VARIABLES)
    single = [
        run_policy(task, e, relay_seq, lambda s, e=e: task.features(s, e), VARIABLES)
        for e in episodes
    ]
    assert len(batched) == len(single) == 10
    for b, s in zip(batched, single, strict=True):
        assert (b.sequences, b.time, b.initial, b.reached_goal) == (
            s.sequences,
            s.time,
            s.initial,
            s.reached_goal,
        )
        assert (b.state.carrier == s.state.carrier).all() and b.state.holder == s.state.holder
    ended = {(r.reached_goal, r.time == pytest.approx(task.max_time)) for r in batched}
    # goals at different ticks (one may come at the last tick), and time-outs
    assert {(True, False), (False, True)} <= ended
    assert len({r.time for r in batched if r.reached_goal}) > 1


def test_a_policy_without_batched_runs_one_episode_at_a_time(relay_seq, one_at_a_time):
    task = RelayTask(max_time=4.0)
    episodes = seeded_episodes(task.sample_episode, STRATEGIES, 4, seed=4)
    policy = one_at_a_time(relay_seq)
    runs = run_policies(task, episodes, policy, task.features, VARIABLES)
    expected = run_policies(task, episodes, relay_seq, task.features, VARIABLES)
    assert [(r.sequences, r.time) for r in runs] == [(r.sequences, r.time) for r in expected]
    assert run_policies(task, [], relay_seq, task.features, VARIABLES) == []
