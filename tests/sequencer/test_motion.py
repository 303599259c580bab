"""Speed envelopes and ambient features (cpmp.sequencer.motion), learned from labelled
demonstrations and read by the transition rule."""

from __future__ import annotations

import numpy as np
from progress_doubles import FirstColumnsAreProgress

from cpmp.config import SequencerConfig
from cpmp.data import Demonstration
from cpmp.graph import SequenceGraph
from cpmp.predictors import PredictorConfig
from cpmp.progress import white_noise_std
from cpmp.sequencer import ConcurrentSequencer, motion
from cpmp.sequencer.motion import (
    SpeedLimit,
    SpeedMeter,
    ambient_features,
    learn_speed_limits,
    motion_data,
    window_speed,
    without_ambient,
)
from cpmp.sequencer.switching import Coupling

DT = 0.01


def _demo(x: np.ndarray, labels: dict[str, list[str]]) -> Demonstration:
    n = len(x)
    names = [f"f{j}" for j in range(x.shape[1])]
    return Demonstration(np.arange(n) * DT, x, labels, names)


def _arrival(n_move: int = 100, n_rest: int = 50, speed_at_end: float = 0.0) -> np.ndarray:
    """Feature 0 moves 0 -> 1 and slows to ``speed_at_end`` [1/s]; feature 1 never moves."""
    s = np.linspace(0.0, 1.0, n_move)
    f0 = 1.0 - (1.0 - s) ** 2  # decelerates to 0 at s = 1
    f0 = np.concatenate([f0, 1.0 + speed_at_end * DT * np.arange(1, n_rest + 1)])
    return np.stack([f0, np.zeros_like(f0)], axis=1)


def test_window_speed_is_the_displacement_over_the_newest_sample_a_window_old():
    t = np.arange(30) * DT
    x = np.stack([t * 2.0, np.zeros_like(t)], axis=1)
    inv = np.array([0.5, 0.0])  # range 2 for feature 0; feature 1 ignored
    np.testing.assert_allclose(window_speed(x, t, 20, inv), [1.0, 0.0])
    assert window_speed(x, t, round(motion.SPEED_WINDOW / DT) - 1, inv) is None  # none old yet


def test_a_switch_made_at_rest_gets_a_tight_envelope_on_the_features_its_source_moves():
    x = _arrival()
    demo = _demo(x, {"arm": ["go"] * 100 + ["back"] * 50})
    limits = learn_speed_limits(motion_data([demo]), ["arm"], np.ptp(x, axis=0))
    limit = limits[("arm", "go", "back")]
    np.testing.assert_array_equal(limit.features, [0])  # feature 1 never moves under go
    at_switch = window_speed(x, demo.time, 100, np.array([1.0, 0.0]))[0]
    top = np.abs(np.diff(x[:100, 0])).max() / DT
    want = max(motion.SPEED_FACTOR * at_switch, motion.SPEED_FLOOR * top)
    np.testing.assert_allclose(limit.limit, [want])
    # the source's top speed is far above the envelope: a switch mid-motion is held
    assert limit.exceeded(np.array([top / 2, 0.0])).tolist() == [0]
    assert limit.exceeded(np.array([want / 2, 5.0])).size == 0
    back = SpeedLimit.from_dict(limit.to_dict())
    np.testing.assert_array_equal(back.features, limit.features)
    np.testing.assert_allclose(back.limit, limit.limit)


def test_the_speed_meter_reads_the_newest_measurement_a_window_old():
    meter = SpeedMeter(np.array([2.0, 0.0]))
    meter.reset(0.0, np.zeros(2))
    assert meter.speed() is None
    for k in range(1, 31):
        meter.observe(k * DT, np.array([k * DT * 4.0, 1.0]))
    np.testing.assert_allclose(meter.speed(), [2.0, 0.0])  # 4 per s over range 2
    assert len(meter._seen) <= 12  # it keeps one window, not the episode
    meter.reset(1.0, np.zeros(2))  # a new episode forgets the last one
    assert meter.speed() is None


def test_speed_since_an_mp_began_is_its_own_motion():
    """A re-align that starts from rest: over the whole window its speed reads half what the
    arm moves since the MP began, so the speed is cut at the MP's start."""
    meter = SpeedMeter(np.array([1.0]))
    meter.reset(0.0, np.zeros(1))
    for k in range(1, 21):  # still until 0.2 s, then 2 per s from the switch at 0.2 s
        meter.observe(k * DT, np.zeros(1))
    moving = 3  # ticks of motion, less than a window
    assert moving * DT < motion.SPEED_WINDOW
    for k in range(21, 21 + moving):
        meter.observe(k * DT, np.array([(k - 20) * DT * 2.0]))
    # over the whole window, part of it still: 0.06 m over the window
    np.testing.assert_allclose(meter.speed(), [2.0 * moving * DT / motion.SPEED_WINDOW])
    np.testing.assert_allclose(meter.speed(since=0.2), [2.0])  # 0.06 m over 0.03 s
    assert meter.speed(since=0.2 + moving * DT) is None  # nothing measured after it began yet
    np.testing.assert_allclose(meter.speed(since=0.1), meter.speed())  # began before the window


def _attractor(rate: float, n: int, x0: float = 0.0) -> np.ndarray:
    """A first-order attractor to 1 from ``x0`` at ``rate`` [1/s], ``n`` samples ``DT`` apart."""
    return 1.0 - (1.0 - x0) * np.exp(-rate * DT * np.arange(n))


def test_a_switch_demonstrated_at_one_pace_waits_for_the_same_share_of_the_move_at_another():
    """Demonstrated at rate 4/s, switched 3 % of the move short of the goal. A robot running
    the MP 4x slower passes the demonstrated speed in ranges/s 12 % short of it: the first
    bound alone lets it switch there; the share of its own top speed holds it until it is as
    close as demonstrated (within the factor of 2)."""
    n_go = int(np.ceil(np.log(1 / 0.03) / (4.0 * DT)))  # 3 % of the move left
    go = _attractor(4.0, n_go + 1)
    x = np.concatenate([go, np.full(50, go[-1])])[:, None]
    labels = {"arm": ["go"] * (n_go + 1) + ["back"] * 50}
    limit = learn_speed_limits(motion_data([_demo(x, labels)]), ["arm"], np.array([1.0]))[
        ("arm", "go", "back")
    ]
    assert limit.share is not None and limit.slack is not None
    robot = _attractor(1.0, 600)
    meter, top, first_only, both = SpeedMeter(np.array([1.0])), np.zeros(1), None, None
    meter.reset(0.0, robot[:1])
    for k in range(1, len(robot)):
        meter.observe(k * DT, robot[k : k + 1])
        speed = meter.speed(since=0.0)
        if speed is None:  # not a window old yet
            continue
        top = np.maximum(top, speed)
        left = 1.0 - robot[k]
        if first_only is None and limit.exceeded(speed).size == 0:
            first_only = left
        if both is None and limit.exceeded(speed, top).size == 0:
            both = left
    assert first_only is not None and both is not None
    assert first_only > 0.1  # the demonstrated speed, reached 4x further out
    assert 0.03 <= both <= 2 * 0.03 * 1.1  # the demonstrated share of the move, x2
    # a faster robot is held by the first bound: at the same share it moves 4x faster
    fast = np.array([4.0 * 4.0 * 0.05])
    assert limit.exceeded(fast, np.array([16.0 * 0.9])).tolist() == [0]


def test_a_speed_limit_keeps_its_share_bound_through_its_checkpoint_form():
    limit = SpeedLimit(np.array([1, 3]), np.array([0.5, 0.2]), np.array([0.1, 0.2]), np.zeros(2))
    back = SpeedLimit.from_dict(limit.to_dict())
    for a, b in zip(back, limit, strict=True):
        np.testing.assert_array_equal(a, b)
    speed, top = np.array([0.0, 0.3, 0.0, 0.1]), np.array([0.0, 1.0, 0.0, 1.0])
    assert limit.exceeded(speed, top).tolist() == [0]  # 30 % of its top speed, 10 % allowed
    old = SpeedLimit.from_dict({"features": [1, 3], "limit": [0.5, 0.2]})  # saved before it
    assert old.share is None and old.exceeded(speed, top).size == 0


def test_a_switch_waits_until_its_source_has_slowed_to_the_demonstrated_share_of_its_pace():
    """v: A -> B with φ(A) = 0.9 from the start; x follows an attractor at 2/s. The envelope
    allows any speed in ranges/s but only 10 % of x's top speed under A: the switch comes once
    x has slowed to that (about 1.1 s), and the hold note says why."""
    g = SequenceGraph("v")
    for mp in "AB":
        g.add_node(mp)
    g.initial_nodes = {"A"}
    g.edges = {("A", "B")}
    limit = SpeedLimit(np.array([2]), np.array([100.0]), np.array([0.1]), np.zeros(1))
    order = g.ordered_nodes()
    model = FirstColumnsAreProgress([("v", mp) for mp in order], 3, PredictorConfig())
    names = [mp.lower() for mp in order] + ["x"]

    def run(speed_limit: SpeedLimit) -> ConcurrentSequencer:
        coupling = Coupling(speed={("v", "A", "B"): speed_limit})
        seq = ConcurrentSequencer({"v": g}, model, names, SequencerConfig(), None, None, coupling)
        seq.reset(0.0, [0.9, 0.0, 0.0])
        t = 0.0
        while t < 3.0 - 1e-9 and seq.active["v"] == "A":
            t = round(t + DT, 10)
            seq.step(t, [0.9, 0.0, 1.0 - np.exp(-2.0 * t)], stamp=t)
        return seq

    (switch,) = run(limit).events
    slowed = np.log(1 / 0.1) / 2.0  # the speed is 10 % of the first one's
    assert slowed <= switch.t <= slowed + 0.2
    assert any("of its top speed under A" in n.text for n in run(limit).notes)
    (early,) = run(SpeedLimit(limit.features, limit.limit)).events  # the first bound only
    assert early.t < 0.2


def test_a_feature_moving_alike_under_every_mp_is_ambient():
    n = 200
    t = np.arange(n) * DT
    wobble = 0.1 * np.sin(2 * np.pi * 2.0 * t)  # moves the same under every MP
    arm = np.concatenate([np.linspace(0, 1, 100), np.ones(100)])  # moves under go only
    x = np.stack([arm, wobble, np.zeros(n)], axis=1)
    demo = _demo(x, {"arm": ["go"] * 100 + ["rest"] * 100})
    data = motion_data([demo])
    np.testing.assert_array_equal(ambient_features(data, ["arm"], 3), [False, True, False])
    one_mp = _demo(x, {"arm": ["go"] * n})
    assert not ambient_features(motion_data([one_mp]), ["arm"], 3).any()  # nothing to compare


def test_a_coordinate_whose_variable_never_rests_is_not_ambient(monkeypatch):
    """A ladle on its way out and back, switched before it arrives: its rate is alike under
    both MPs, but its velocity turns at every switch; a slow drift's and a conveyor's do not."""
    tau, dt, n = 0.2, DT, 600
    t = np.arange(n) * dt
    ladle, labels, pos, goal = np.zeros(n), [], 0.0, 1.0
    for i in range(n):
        if abs(goal - pos) < 0.4:  # switched well before arriving: never at rest
            goal = -goal
        labels.append("out" if goal > 0 else "back")
        pos += (goal - pos) * dt / tau
        ladle[i] = pos
    drift = 0.05 * np.sin(2 * np.pi * 0.3 * t)
    conveyor = 0.2 * t
    x = np.stack([ladle, drift, conveyor], axis=1)
    data = motion_data([_demo(x, {"ladle": labels})])
    assert len(set(labels)) == 2 and labels.count("out") > 100 and labels.count("back") > 100
    np.testing.assert_array_equal(ambient_features(data, ["ladle"], 3), [False, True, True])
    monkeypatch.setattr(motion, "KINK_RATIO", float("inf"))  # the rates alone misread the ladle
    np.testing.assert_array_equal(ambient_features(data, ["ladle"], 3), [True, True, True])


def test_without_ambient_zeroes_the_ambient_ranges():
    feature_range = np.array([1.0, 1.0, 1.5])
    np.testing.assert_array_equal(
        without_ambient(feature_range, np.array([False, False, True])), [1.0, 1.0, 0.0]
    )
    np.testing.assert_array_equal(without_ambient(feature_range, None), feature_range)


def test_coupling_keeps_the_motion_facts_through_its_checkpoint_form():
    x = _arrival()
    demo = _demo(x, {"arm": ["go"] * 100 + ["back"] * 50})
    coupling = Coupling.learn([demo], ["arm"], feature_range=np.ptp(x, axis=0))
    assert ("arm", "go", "back") in coupling.speed and coupling.ambient is not None
    assert Coupling.from_dict(coupling.to_dict()) == coupling
    assert "f0 at most 2x as fast as demonstrated" in "\n".join(
        coupling.describe("arm", demo.feature_names)
    )
    plain = Coupling.learn([demo], ["arm"])
    assert not plain.speed and plain.ambient is None
    assert Coupling.from_dict(plain.to_dict()) == plain


def test_an_envelope_holds_a_switch_while_the_source_still_moves(train_demos, monkeypatch):
    """Replaying a demonstration: with the learned envelopes the sequencer makes the
    demonstrated switches; with zero envelopes a switch out of a moving MP is held (the hold
    note names the speed) and fewer switches come."""

    def replay(seq: ConcurrentSequencer, demo: Demonstration) -> tuple[list[float], list[str]]:
        seq.reset(float(demo.time[0]), demo.features[0])
        for t, x in zip(demo.time[1:], demo.features[1:], strict=True):
            seq.step(float(t), x)
        return [e.t for e in seq.events], [n.text for n in seq.notes if n.kind == "hold"]

    learned = ConcurrentSequencer.fit(train_demos, seed=0, logger=None)
    monkeypatch.setattr(motion, "SPEED_FACTOR", 0.0)
    monkeypatch.setattr(motion, "SPEED_FLOOR", 0.0)
    strict = ConcurrentSequencer.fit(train_demos, seed=0, logger=None)
    demo = train_demos[0]
    times, _ = replay(learned, demo)
    late, holds = replay(strict, demo)
    demonstrated = sum(len(demo.switch_indices(v)) for v in demo.variables)
    assert len(times) == demonstrated
    assert any("ranges/s (demonstrated switches allow 0)" in h for h in holds)
    assert len(late) < len(times)


def test_a_noisy_feature_gets_the_speed_its_noise_adds_at_run_time():
    """Learned along the denoised demonstration, plus NOISE_Z x the speed noise of a 100 ms
    window: sensor noise at run time does not hold the switch."""
    x = _arrival()
    labels = {"arm": ["go"] * 100 + ["back"] * 50}
    noisy = x.copy()
    noisy[:, 0] += np.random.default_rng(0).normal(0.0, 0.01, len(x))
    r = np.ptp(x, axis=0)
    clean = learn_speed_limits(motion_data([_demo(x, labels)]), ["arm"], r)
    loud = learn_speed_limits(motion_data([_demo(noisy, labels)]), ["arm"], r)
    edge = ("arm", "go", "back")
    np.testing.assert_array_equal(loud[edge].features, clean[edge].features)
    sigma = white_noise_std(noisy)[0]  # the estimate of the 0.01 the demonstration has
    assert 0.5 * 0.01 < sigma < 1.5 * 0.01
    allowance = motion.NOISE_Z * np.sqrt(2.0) * sigma / motion.SPEED_WINDOW / r[0]
    assert loud[edge].limit[0] >= allowance > clean[edge].limit[0]


def test_a_switch_waits_for_its_source_mps_own_motion_not_the_rest_before_it():
    """v: R -> A -> B, where A -> B was demonstrated with x settled (envelope 1 range/s). A
    starts from rest and moves x at 1.5 ranges/s for 0.2 s while its p is already 0.9 (a
    re-align that starts where the last align ended): the switch waits until A stops moving.
    Over the whole 100 ms window (half of it the rest before A) x read 0.75: it fired early."""
    g = SequenceGraph("v")
    for mp in "RAB":
        g.add_node(mp)
    g.initial_nodes = {"R"}
    g.edges = {("R", "A"), ("A", "B")}
    limit = SpeedLimit(np.array([3]), np.array([1.0]))
    coupling = Coupling(speed={("v", "A", "B"): limit})
    order = g.ordered_nodes()
    model = FirstColumnsAreProgress([("v", mp) for mp in order], 4, PredictorConfig())
    names = [mp.lower() for mp in order] + ["x"]
    seq = ConcurrentSequencer({"v": g}, model, names, SequencerConfig(), None, None, coupling)
    seq.reset(0.0, [0.0, 0.0, 0.0, 0.0])
    t, x, began, stopped = 0.0, 0.0, None, None
    while t < 1.0 - 1e-9 and seq.active["v"] != "B":
        t = round(t + DT, 10)
        if seq.active["v"] == "A":
            began = t if began is None else began
            if t - began < 0.2 - 1e-9:
                x += 1.5 * DT
            elif stopped is None:
                stopped = t
        ahead = "R" if seq.active["v"] == "R" else "A"  # the active MP's φ is 0.9
        seq.step(t, [0.9 if mp == ahead else 0.0 for mp in order] + [x], stamp=t)
    (into_a, into_b) = [(e.source, e.target, e.t) for e in seq.events]
    assert into_a[:2] == ("R", "A") and into_b[:2] == ("A", "B")
    assert stopped is not None and into_b[2] >= stopped
    assert any("x moves at 1.5 ranges/s" in n.text for n in seq.notes)
