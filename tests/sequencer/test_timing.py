"""Switching in time (cpmp.sequencer.timing and the rules on measurement time): the same switch
times at any control rate, with jitter and dropped ticks; stale features, clock steps and
non-finite features add no evidence."""

import math

import numpy as np
import pytest
from progress_doubles import FirstColumnsAreProgress

from cpmp.config import SequencerConfig
from cpmp.errors import DataError
from cpmp.graph import SequenceGraph
from cpmp.predictors import PredictorConfig
from cpmp.sequencer.sequencer import ConcurrentSequencer
from cpmp.sequencer.switching import PaperRule, PeakRule
from cpmp.sequencer.timing import MeasurementClock

THRESHOLD, PATIENCE, MIN_IMPROVEMENT = 0.65, 0.05, 1e-3


def _chain(**config) -> ConcurrentSequencer:
    """One variable, A -> B; features (φ_A, φ_B): p = φ_A (1 - φ_B)."""
    g = SequenceGraph("v")
    for mp in "AB":
        g.add_node(mp)
    g.initial_nodes = {"A"}
    g.edges = {("A", "B")}
    model = FirstColumnsAreProgress([("v", "A"), ("v", "B")], 2, PredictorConfig())
    return ConcurrentSequencer({"v": g}, model, ["a", "b"], SequencerConfig(**config))


def _ticks(rate: float, end: float, jitter: float = 0.0, drop: float = 0.0, seed: int = 0):
    """Tick times in (0, end]: every 1/rate s, each period scaled by 1 + U(-jitter, jitter),
    each tick dropped with probability ``drop``."""
    rng = np.random.default_rng(seed)
    out, t = [], 0.0
    while t < end:
        t += (1.0 + rng.uniform(-jitter, jitter)) / rate
        if rng.random() >= drop:
            out.append(t)
    return out


def _fire_time(p, ticks):
    """Feed ``p(t)`` at the ``ticks`` to the paper rule (node entered at t = 0, where p was
    measured); the first tick that fires and the longest tick interval up to it."""
    rule = PaperRule(THRESHOLD, PATIENCE, MIN_IMPROVEMENT)
    rule.observe(0.0, [p(0.0)])
    last, longest = 0.0, 0.0
    for t in ticks:
        longest = max(longest, t - last)
        last = t
        if rule.update(t, [p(t)], [True]) is not None:
            return t, longest
    return None, longest


def _ideal(p, dt=1e-5):
    """The continuous rule: the first t with p(t) > threshold and p(t) <= p(t - patience) +
    min_improvement (t >= patience)."""
    t = PATIENCE
    while t < 5.0:
        if p(t) > THRESHOLD and p(t) <= p(t - PATIENCE) + MIN_IMPROVEMENT:
            return t
        t += dt
    raise AssertionError("the ideal rule never fires")


PROFILES = {
    # an attractor converging: fires once the 50 ms gain falls below the tolerance (~1 s)
    "converging": lambda t: 0.9 - 0.5 * math.exp(-t / 0.2),
    # a peak above the threshold that falls back: fires on the way down
    "peak": lambda t: 0.85 * math.exp(-(((t - 0.6) / 0.25) ** 2)),
    # ready at the node's entry: fires once 50 ms of measurements span it
    "ready": lambda t: 0.8,
}


@pytest.mark.parametrize("profile", sorted(PROFILES))
@pytest.mark.parametrize(
    ("rate", "jitter", "drop"),
    [(30.0, 0.0, 0.0), (50.0, 0.0, 0.0), (100.0, 0.0, 0.0), (250.0, 0.0, 0.0),
     (1000.0, 0.0, 0.0), (100.0, 0.3, 0.0), (100.0, 0.3, 0.1), (30.0, 0.3, 0.1)],
)  # fmt: skip
def test_the_rule_switches_within_one_tick_of_the_ideal_time_at_any_rate(
    profile, rate, jitter, drop
):
    p = PROFILES[profile]
    ideal = _ideal(p)
    for seed in range(3):
        fired, longest = _fire_time(p, _ticks(rate, 3.0, jitter, drop, seed))
        assert fired is not None
        # at or after the ideal time, and no later than the tick interval that contains it
        # (1e-3 s: the linear interpolation of p between ticks, ~2e-5 of p at 30 Hz)
        assert ideal - 1e-3 <= fired <= ideal + longest + 1e-3, (fired, ideal, longest)


@pytest.mark.parametrize(
    ("rate", "jitter", "drop"),
    [(100.0, 0.0, 0.0), (250.0, 0.0, 0.0), (1000.0, 0.0, 0.0), (100.0, 0.3, 0.0),
     (100.0, 0.3, 0.1)],
)  # fmt: skip
def test_the_peak_rule_catches_an_event_spike_at_any_rate(rate, jitter, drop):
    """p jumps at 0.5 s and falls below the threshold 50 ms later (an event, then the running
    MPs carry the state away): the peak rule fires on the first measurement after the jump's,
    the paper rule never."""
    spike = lambda t: 0.01 if t < 0.5 else 0.85 - 4.0 * (t - 0.5)  # noqa: E731
    for seed in range(3):
        ticks = _ticks(rate, 2.0, jitter, drop, seed)
        fired = {}
        for name, cls in (("paper", PaperRule), ("peak", PeakRule)):
            rule = cls(THRESHOLD, PATIENCE, MIN_IMPROVEMENT)
            rule.observe(0.0, [spike(0.0)])
            fired[name] = next(
                (t for t in ticks if rule.update(t, [spike(t)], [True]) is not None), None
            )
        after = [t for t in ticks if t >= 0.5]
        assert fired == {"paper": None, "peak": after[1]}, (fired, after[:3])


def test_a_slow_sensor_read_every_tick_is_not_evidence_of_convergence():
    """φ_A rises by 0.2/s (0.01 per 50 ms > the tolerance) and is sensed at 10 Hz by a loop at
    100 Hz: between refreshes the features repeat, which is no evidence that p stopped."""
    ramp = lambda s: min(0.7 + 0.2 * s, 0.9)  # noqa: E731 - rises until 1 s, then flat
    runs = {"no stamp": _chain(), "stamped": _chain(), "fresh": _chain()}
    for seq in runs.values():
        seq.reset(0.0, [ramp(0.0), 0.0])
    switched = {}
    for k in range(1, 200):
        t = round(0.01 * k, 10)
        sample = round(0.1 * math.floor(t / 0.1 + 1e-9), 10)  # zero-order hold at 10 Hz
        noise = 1e-7 * math.sin(100.0 * sample)  # a real sensor's: each refresh differs
        held = [ramp(sample) + noise, 0.0]
        steps = {
            "no stamp": runs["no stamp"].step(t, held),
            "stamped": runs["stamped"].step(t, held, stamp=sample),
            "fresh": runs["fresh"].step(t, [ramp(t), 0.0], stamp=t),
        }
        for name, active in steps.items():
            if active["v"] == "B":
                switched.setdefault(name, t)
    # none fires while p rises; each once the ramp is flat for 50 ms of measurements
    assert switched["fresh"] == pytest.approx(1.05)
    assert switched["stamped"] == pytest.approx(1.1)  # the first refresh 50 ms into the flat
    assert switched["no stamp"] == pytest.approx(1.1)


def test_a_stamp_that_has_not_advanced_adds_no_evidence():
    seq = _chain()
    seq.reset(0.0, [0.8, 0.0])
    for k in range(1, 50):  # p = 0.8 > threshold, but every tick is the measurement at t = 0
        assert seq.step(0.01 * k, [0.8, 0.0], stamp=0.0) == {"v": "A"}
    assert seq.step(0.5, [0.8, 0.0], stamp=0.5) == {"v": "B"}  # 0.5 s of flat p, measured
    with pytest.raises(DataError, match="stamp"):
        seq.step(0.6, [0.8, 0.0], stamp=0.7)  # measured after it is given


def test_an_unchanged_vector_without_stamps_counts_as_rest_after_stale_time():
    seq = _chain(stale_time=0.2)
    seq.reset(0.0, [0.8, 0.0])
    t = 0.0
    while seq.active == {"v": "A"}:
        t = round(t + 0.01, 10)
        seq.step(t, [0.8, 0.0])
    # the repeats are the measurement at 0 until 0.2 s; the next tick is a new one, 0.21 s
    # after the first: p has not improved over more than 50 ms of measurements
    assert t == pytest.approx(0.21)


def test_a_clock_step_is_not_time_that_passed():
    """A stall (p = 0.5 below the threshold, the features at rest) resolves after stall_time of
    measured time; a forward step of the clock by 1 s on the way changes nothing but a note."""

    def run(jump):
        seq = _chain(stall_time=1.0, recovery_threshold=0.3)
        seq.reset(0.0, [0.5, 0.0])
        for k in range(1, 200):
            t = round(0.01 * k + (jump if k >= 50 else 0.0), 10)
            seq.step(t, [0.5, 0.0], stamp=t)
        return seq

    steady, stepped = run(0.0), run(1.0)
    (recovery,) = steady.events
    assert recovery.kind == "recovery" and recovery.t == pytest.approx(1.0)
    (late,) = stepped.events
    assert late.kind == "recovery" and late.t == pytest.approx(2.0)  # 1.0 s of measured time
    step_notes = [n for n in stepped.notes if n.kind == "clock_step"]
    assert len(step_notes) == 1 and step_notes[0].t == pytest.approx(1.5)
    assert "jumped by 1.010 s" in step_notes[0].text


def test_measurement_clock_median_period_and_steps():
    clock = MeasurementClock(stale_time=0.25)
    clock.reset(0.0, np.zeros(1))
    for k in range(1, 6):
        reading = clock.tick(0.02 * k, np.full(1, k))
        assert reading.fresh and reading.clock_step == 0.0
    assert clock.period == pytest.approx(0.02)
    reading = clock.tick(0.18, np.full(1, 6.0))  # 4 periods (dropped ticks): time passed
    assert reading.clock_step == 0.0 and reading.m == pytest.approx(0.18)
    reading = clock.tick(0.5, np.full(1, 7.0))  # 16 periods: a step; one period counts
    assert reading.clock_step == pytest.approx(0.30)
    assert reading.m == pytest.approx(0.20)
    assert not clock.tick(0.51, None).fresh  # no usable features: no measurement


def test_nan_features_hold_every_mp_and_are_noted_once_per_burst():
    seq = _chain(patience=0.0)
    seq.reset(0.0, [0.1, 0.0])
    t = 0.0
    for burst in range(2):
        for _ in range(3):
            t = round(t + 0.01, 10)
            assert seq.step(t, [math.nan, math.inf]) == {"v": "A"}  # never raises
            assert seq.last_tick.active == {"v": "A"}
        t = round(t + 0.01, 10)
        seq.step(t, [0.2 + 0.1 * burst, 0.0])  # a finite tick ends the burst
    assert [n.kind for n in seq.notes] == ["nonfinite", "nonfinite"]
    assert "non-finite features (columns 0, 1)" in seq.notes[0].text
    assert not seq.events
    strict = _chain(nonfinite="raise")
    strict.reset(0.0, [0.1, 0.0])
    with pytest.raises(DataError, match="non-finite features"):
        strict.step(0.01, [math.nan, 0.0])
    with pytest.raises(DataError, match="NaN"):
        seq.reset(0.0, [math.nan, 0.0])  # at the start there is no MP to keep
