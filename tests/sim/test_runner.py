"""The closed-loop runner (cpmp.sim.runner): outcomes of one episode, and many boxes together
giving exactly the one-at-a-time results."""

from __future__ import annotations

import numpy as np
import pytest

from cpmp.errors import ConfigError, UnknownMPError
from cpmp.sequencer.sequencer import ConcurrentSequencer
from cpmp.sim import (
    Box,
    Simulation,
    mp_sequences,
    record_demonstration,
    run_episode,
)
from cpmp.sim.policies import ReplayPolicy
from cpmp.sim.runner import run_episodes


def test_replayed_demo_completes(demos, boxes, cfg):
    demo, ticks = demos["left"], []
    policy = ReplayPolicy(demo)
    result = run_episode(boxes["left"], policy, cfg, expected=demo, on_tick=ticks.append)
    assert result.outcome == "complete", result.reason
    assert result.box_in_container and result.hands_home
    assert result.sequences == mp_sequences(demo)
    # the replay switches when the labels do: the runner's records are the demonstration's
    ran = sorted((e.t, e.variable, e.source, e.target) for e in result.transitions)
    assert ran == [(e.t, e.variable, e.source, e.target) for e in demo.transitions()]
    assert result.transitions[0].state.shape == (33,)
    assert all(np.isnan(e.probability) for e in result.transitions)
    # one tick record per control tick, with what the runner observed
    dt = cfg.control_dt
    assert [tick.t for tick in ticks[:3]] == pytest.approx([0.0, dt, 2 * dt])
    np.testing.assert_array_equal(ticks[0].features, demo.features[0])
    assert ticks[0].active == {v: str(labels[0]) for v, labels in demo.labels.items()}
    assert "box" in ticks[0].body_poses and ticks[0].progress == {}


def test_wrong_start_and_wrong_transition(demos, boxes, cfg):
    result = run_episode(boxes["right"], ReplayPolicy(demos["left"]), cfg, expected=demos["right"])
    assert result.outcome == "wrong_start"
    assert result.initial["left_pos"] == "reach_top"

    class SkipLift(ReplayPolicy):
        def step(self, t, x):
            active = super().step(t, x)
            if active["right_pos"] == "lift":
                active["right_pos"] = "carry"
            return active

    result = run_episode(boxes["right"], SkipLift(demos["right"]), cfg, expected=demos["right"])
    assert result.outcome == "incomplete"
    assert "right_pos: reach_top -> carry" in result.reason


def test_time_out_and_unknown_mp(demos, boxes, cfg):
    class Frozen(ReplayPolicy):
        def step(self, t, x):
            return self.reset(0.0, x)

    result = run_episode(
        boxes["right"], Frozen(demos["right"]), cfg, max_time=1.0, expected=demos["right"]
    )
    assert result.outcome == "incomplete" and "time-out" in result.reason
    assert result.duration == pytest.approx(1.0)

    class Bogus(ReplayPolicy):
        def reset(self, t, x):
            return dict(super().reset(t, x), right_pos="fly")

    with pytest.raises(UnknownMPError):
        run_episode(boxes["right"], Bogus(demos["right"]), cfg, expected=demos["right"])


def test_divergence_is_reported_not_raised(demos, boxes, cfg, monkeypatch):
    original = Simulation.step

    def blow_up(self):
        if self.t > 0.5:
            self.data.qvel[:] = np.nan  # what an unstable integration leaves behind
        return original(self)

    monkeypatch.setattr(Simulation, "step", blow_up)
    result = run_episode(boxes["both"], ReplayPolicy(demos["both"]), cfg, expected=demos["both"])
    assert result.outcome == "diverged"
    assert "diverged" in result.reason
    assert not result.box_in_container


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


@pytest.fixture(scope="module")
def learned(demos):
    """The learned sequencer (cpmp defaults, klr) on the three demonstrations."""
    return ConcurrentSequencer.fit(list(demos.values()), "klr", seed=0, logger=None)


@pytest.mark.slow
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


def test_an_incomplete_episode_names_the_switch_that_never_came(learned, demos, boxes, cfg):
    """Issue #36: the cause of an incomplete outcome, explained by a fitted sequencer, from the
    sequences alone for any other policy (and none for a complete or wrong-start one)."""
    demo = demos["right"]
    want = mp_sequences(demo)

    class Frozen(ReplayPolicy):
        def step(self, t, x):
            return self.reset(0.0, x)

    weak = learned.with_config(threshold=0.999)  # a p that never passes: no switch fires
    frozen, sequencer = run_episodes(
        [boxes["right"]] * 2,
        [Frozen(demo), weak],
        cfg,
        expected=[demo] * 2,
        max_time=1.0,
    )
    for result in (frozen, sequencer):
        cause = result.cause
        assert result.outcome == "incomplete" and cause is not None
        v = cause.variable
        assert result.sequences[v] == [cause.current] and want[v][:2] == [
            cause.current,
            cause.expected,
        ]
        assert result.reason.endswith(cause.describe()) and "time-out" in result.reason
    assert frozen.cause.reason == "unknown" and np.isnan(frozen.cause.best_p)
    cause = sequencer.cause
    assert cause.reason == "below_threshold" and cause.threshold == 0.999
    assert 0.0 <= cause.final_p <= cause.best_p < 0.999 and 0.0 < cause.best_t <= 1.0

    class SkipLift(ReplayPolicy):
        def step(self, t, x):
            active = super().step(t, x)
            if active["right_pos"] == "lift":
                active["right_pos"] = "carry"
            return active

    wrong = run_episode(boxes["right"], SkipLift(demo), cfg, expected=demo).cause
    assert (wrong.reason, wrong.variable, wrong.current, wrong.expected, wrong.fired) == (
        "wrong_transition",
        "right_pos",
        "reach_top",
        "lift",
        "carry",
    )
    assert wrong.at > 0.0
    complete = run_episode(boxes["right"], ReplayPolicy(demo), cfg, expected=demo)
    assert complete.outcome == "complete" and complete.cause is None
