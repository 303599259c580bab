"""Batched rollouts: many boxes stepped together give exactly the one-at-a-time results."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from cpmp.errors import ConfigError, CpmpError
from cpmp.sequencer import ConcurrentSequencer
from cpmp.sim import Box, Simulation, record_demonstration, run_episode
from cpmp.sim.runner import ReplayPolicy, run_episodes
from cpmp.sim.simulation import prepare_steps, shared_kinematics


def _same_result(one, together):
    """Outcome, reason, time and every transition (time, MPs, bit-exact state) equal."""
    assert (together.outcome, together.reason) == (one.outcome, one.reason)
    assert together.duration == one.duration
    assert (together.initial, together.sequences) == (one.initial, one.sequences)
    assert (together.box_in_container, together.hands_home) == (
        one.box_in_container,
        one.hands_home,
    )
    assert [(tr.t, tr.variable, tr.source, tr.target) for tr in together.transitions] == [
        (tr.t, tr.variable, tr.source, tr.target) for tr in one.transitions
    ]
    for a, b in zip(together.transitions, one.transitions, strict=True):
        np.testing.assert_array_equal(a.state, b.state)


class Ticks:
    """``on_tick`` callback keeping the times and active MPs it saw."""

    def __init__(self) -> None:
        self.seen: list[tuple[float, dict[str, str]]] = []

    def __call__(self, info) -> None:
        self.seen.append((info.t, info.active))


def test_batched_jacobians_and_controls_equal_single_ones_bit_for_bit(cfg):
    kin = shared_kinematics(cfg.compile_kinematics)
    rng = np.random.default_rng(0)
    sims = [Simulation(cfg, Box(w, d, 0.1)) for w, d in ((0.25, 0.15), (0.15, 0.12), (0.15, 0.2))]
    q = rng.uniform(sims[0].arm_limits[..., 0], sims[0].arm_limits[..., 1], size=(5, 2, 7))
    together = kin.fk_jacobian(q)
    for i in range(len(q)):
        for got, want in zip(together, kin.fk_jacobian(q[i]), strict=True):
            np.testing.assert_array_equal(got[i], want)
    # one tick of three different boxes' controllers together, then alone from the same state
    active = {v: names[0] for v, names in sims[0].mp_names.items()}
    active.update(right_pos="reach_top", right_rot="down", left_pos="reach_edge")
    alone = [Simulation(cfg, sim.box) for sim in sims]
    for group in (sims, alone):
        for sim in group:
            sim.set_active(active)
    prepare_steps(sims)
    for sim, single in zip(sims, alone, strict=True):
        assert sim.step() and single.step()
        np.testing.assert_array_equal(sim.data.ctrl, single.data.ctrl)
        np.testing.assert_array_equal(sim.data.qpos, single.data.qpos)
    # a prepared control belongs to the MPs it was computed for
    prepare_steps(sims[:1])
    with pytest.raises(CpmpError, match="after prepare_steps"):
        sims[0].set_active(dict(active, right_fingers="grasp"))


def test_compiled_jacobian_is_not_recompiled_by_the_rollouts():
    kin = shared_kinematics.__wrapped__(True)  # a fresh build, not the session's cached one
    if not kin.compiled:
        pytest.skip("torch.compile is unavailable here; the eager Jacobian runs")
    # the start-up check compiled it for the inputs fk_jacobian makes: any robot count runs
    # that code (a recompile would cost seconds per process)
    eager = shared_kinematics(False)
    with torch.compiler.set_stance("fail_on_recompile"):
        for q in (np.zeros((2, 7)), np.zeros((1, 2, 7)), np.full((6, 2, 7), 0.3)):
            for got, want in zip(kin.fk_jacobian(q), eager.fk_jacobian(q), strict=True):
                np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)


@pytest.fixture(scope="module")
def learned(demos):
    """The learned sequencer (cpmp defaults, klr) on the three demonstrations."""
    return ConcurrentSequencer.fit(list(demos.values()), "klr", seed=0, logger=None)


def test_batched_rollout_of_learned_policy_equals_one_at_a_time(learned, boxes, demos, cfg):
    extra = Box(0.28, 0.11, 0.1)  # an unseen box, as the reproduction draws them
    run_boxes = [boxes["both"], boxes["right"], boxes["left"], extra]
    expected = [demos["both"], demos["right"], demos["left"], record_demonstration(extra, cfg)]
    serial, serial_events, serial_ticks = [], [], []
    for box, demo in zip(run_boxes, expected, strict=True):
        ticks = Ticks()
        serial.append(run_episode(box, learned, cfg, expected=demo, on_tick=ticks))
        serial_events.append(list(learned.events))
        serial_ticks.append(ticks.seen)
    batch = learned.batched(len(run_boxes))
    ticks = [Ticks() for _ in run_boxes]
    ended = []
    together = run_episodes(
        run_boxes,
        batch,
        cfg,
        expected=expected,
        on_tick=ticks,
        on_result=lambda i, result: ended.append((i, result.outcome)),
    )
    for one, both in zip(serial, together, strict=True):
        _same_result(one, both)
    for i, (episode, events) in enumerate(zip(batch.episodes, serial_events, strict=True)):
        assert [(e.t, e.variable, e.target, e.kind) for e in episode.events] == [
            (e.t, e.variable, e.target, e.kind) for e in events
        ]
        assert ticks[i].seen == serial_ticks[i]  # callbacks see every tick of their episode
    assert sorted(ended) == [(i, r.outcome) for i, r in enumerate(serial)]
    # the episodes end at different times: the batch shrinks as they finish
    assert len({r.duration for r in serial}) == len(serial)
    assert "complete" in {r.outcome for r in serial}


def test_a_sequencer_passed_as_is_is_batched_inside(learned, boxes, demos, cfg):
    pairs = [(boxes["right"], demos["right"]), (boxes["left"], demos["left"])]
    serial = [run_episode(box, learned, cfg, max_time=2.0, expected=demo) for box, demo in pairs]
    together = run_episodes(
        [p[0] for p in pairs], learned, cfg, expected=[p[1] for p in pairs], max_time=2.0
    )
    assert [r.outcome for r in together] == ["incomplete", "incomplete"]  # time-outs
    assert all(r.transitions for r in together)  # the first switches come within 2 s
    for one, both in zip(serial, together, strict=True):
        _same_result(one, both)


def test_one_policy_per_box_with_wrong_start_and_time_out(boxes, demos, cfg):
    cases = [
        (boxes["right"], ReplayPolicy(demos["left"]), demos["right"]),  # wrong start
        (boxes["left"], ReplayPolicy(demos["left"]), demos["left"]),  # time-out at 1.5 s
        (boxes["both"], ReplayPolicy(demos["both"]), demos["both"]),
    ]
    serial = [
        run_episode(box, policy, cfg, max_time=1.5, expected=demo) for box, policy, demo in cases
    ]
    fresh = [ReplayPolicy(demo) for demo in (demos["left"], demos["left"], demos["both"])]
    together = run_episodes(
        [c[0] for c in cases], fresh, cfg, expected=[c[2] for c in cases], max_time=1.5
    )
    assert [r.outcome for r in together] == ["wrong_start", "incomplete", "incomplete"]
    assert "time-out" in together[1].reason and together[0].duration == 0.0
    for one, both in zip(serial, together, strict=True):
        _same_result(one, both)


def test_run_episodes_rejects_mismatched_inputs(boxes, demos, cfg):
    two = [boxes["right"], boxes["left"]]
    with pytest.raises(ConfigError, match="one policy per box"):
        run_episodes(two, ReplayPolicy(demos["right"]), cfg)
    with pytest.raises(ConfigError, match="expected must hold one entry per box"):
        run_episodes(two, [ReplayPolicy(demos["right"])] * 2, cfg, expected=[demos["right"]])
    assert run_episodes([], ReplayPolicy(demos["right"]), cfg) == []
