"""The clock benchmark (cpmp.benchmarks.clock, scripts/bench_clock.py): the clocked policy does
to time and features what each condition says, the reference condition is the worlds' own loop,
and the quick run writes the documented, reproducible JSON."""

from __future__ import annotations

import json

import numpy as np
import pytest

from cpmp.benchmarks.clock import (
    CONDITION_NAMES,
    CONDITIONS,
    REFERENCE,
    ClockCondition,
    ClockedPolicy,
    ClockSettings,
    main,
    run_clock_benchmark,
    run_synthetic_episode,
    sim_task,
)
from cpmp.data import mp_sequences
from cpmp.errors import ConfigError, DataError
from cpmp.worlds.registry import make_world, world_names
from cpmp.worlds.two_point import SyntheticTask, evaluate

BY_NAME = {c.name: c for c in CONDITIONS}
START = {"a": "a_go", "b": "b_go"}  # the parallel strategy's start, never switching


class Recorder:
    """Records what it is handed; never switches (or raises on NaN with ``strict``)."""

    def __init__(self, strict: bool = False) -> None:
        self.strict = strict
        self.t: list[float] = []
        self.x: list[np.ndarray] = []
        self.stamps: list[float] = []

    def reset(self, t, x):
        self.t, self.x, self.stamps = [t], [np.array(x)], [t]
        return dict(START)

    def step(self, t, x, stamp=None):
        if self.strict and not np.isfinite(x).all():
            raise DataError("features contain NaN")
        self.t.append(t)
        self.x.append(np.array(x))
        self.stamps.append(stamp)
        return dict(START)


def run_recorder(condition: str, strict: bool = False, seed: int = 0):
    """One parallel two-point episode (no switch, so it runs to max_time) under ``condition``."""
    world = make_world("two_point")
    episode = SyntheticTask().sample_episode(np.random.default_rng(3), context=0.9)
    reference = world.demonstrate(episode)
    inner = Recorder(strict)
    policy = ClockedPolicy(inner, BY_NAME[condition], np.random.default_rng(seed), 3.0)
    record = run_synthetic_episode(world, episode, policy, reference)
    return inner, policy, record


def test_reference_condition_is_the_worlds_own_loop(fitted_klr):
    """At 100 Hz the clocked two-point loop gives the sequencer exactly what
    SyntheticTask.rollout gives it: the same outcomes, sequences and switch times."""
    world = make_world("two_point")
    task = SyntheticTask()
    episodes = world.contexts(10, 1000)
    completed = 0
    for i, episode in enumerate(episodes):
        reference = world.demonstrate(episode)
        sequences, done = task.rollout(episode, fitted_klr)
        times = {v: [e.t for e in fitted_klr.events if e.variable == v] for v in sequences}
        policy = ClockedPolicy(fitted_klr, BY_NAME[REFERENCE], np.random.default_rng(i), 3.0)
        record = run_synthetic_episode(world, episode, policy, reference)
        want = mp_sequences(reference)
        assert record.sequences == sequences and record.switch_times == times
        if any(sequences[v][0] != want[v][0] for v in want):
            assert record.outcome == "wrong_start"
        else:  # two_point is not strict: reaching the goal completes it
            assert record.outcome == ("complete" if done else "incomplete")
        same = record.outcome == "complete" and sequences == want
        assert len(record.switch_errors) == (sum(len(t) for t in times.values()) if same else 0)
        completed += record.outcome == "complete"
    assert completed >= 8  # the default fit completes the two-point task (docs/results.md)
    assert evaluate(fitted_klr, n_episodes=10, seed=1000)["complete"] == completed


def test_a_slow_sensor_holds_the_features_with_their_measurement_time():
    inner, policy, _ = run_recorder("sensor_10hz")
    t, x, stamps = np.array(inner.t), np.array(inner.x), np.array(inner.stamps, dtype=float)
    np.testing.assert_allclose(np.diff(t), 0.01, atol=1e-9)  # the policy still ticks at 100 Hz
    sample = np.floor(t / 0.1 + 1e-6) * 0.1
    np.testing.assert_allclose(stamps, sample, atol=1e-9)
    for k in range(1, len(t)):
        same_sample = sample[k] == sample[k - 1]
        assert np.array_equal(x[k], x[k - 1]) == same_sample, t[k]
    assert policy.calls == len(t) - 1 and policy.stamp_keyword == "stamp"


def test_a_clock_step_jumps_time_but_not_state():
    inner, _, record = run_recorder("clock_step_1s")
    t, x = np.array(inner.t), np.array(inner.x)
    jumps = np.flatnonzero(np.diff(t) > 0.5)
    assert len(jumps) == 1 and t[jumps[0]] == pytest.approx(1.49)  # at half of 3 s
    assert np.diff(t)[jumps[0]] == pytest.approx(1.01)
    moved = np.linalg.norm(np.diff(x[:, :2], axis=0), axis=1)
    assert moved[jumps[0]] <= moved[jumps[0] - 1] + 1e-12  # one tick of motion, not a second
    assert record.time == pytest.approx(8.0)  # the true time runs to max_time unchanged


def test_rates_jitter_and_drops_shape_the_policy_ticks():
    inner, _, _ = run_recorder("rate_30hz")
    np.testing.assert_allclose(np.diff(inner.t), 1 / 30, atol=1e-9)
    inner, _, _ = run_recorder("jitter_30pct")
    periods = np.diff(inner.t)
    assert periods.min() >= 0.007 - 1e-9 and periods.max() <= 0.013 + 1e-9
    # uniform over ±30 % of 10 ms: std 6 ms / sqrt(12) = 1.73 ms; ~800 periods
    assert periods.std() > 0.0015 and abs(periods.mean() - 0.01) < 0.0005
    inner, policy, _ = run_recorder("drop_10pct")
    assert policy.calls == len(inner.t) - 1
    assert 0.05 < policy.dropped / (policy.calls + policy.dropped) < 0.15


def test_nan_bursts_reach_the_policy_and_an_error_stops_it():
    inner, policy, record = run_recorder("nan_burst")
    nan = ~np.isfinite(np.array(inner.x)).all(axis=1)
    assert nan.sum() == 6 and policy.error is None  # two bursts of three ticks
    assert np.array(inner.t)[nan] == pytest.approx([1.0, 1.01, 1.02, 2.0, 2.01, 2.02])
    inner, policy, record = run_recorder("nan_burst", strict=True)
    assert "NaN" in record.error and record.outcome == "incomplete"
    assert record.time == pytest.approx(1.0)  # the episode stopped with the policy


def test_simulator_options_per_condition():
    reference = sim_task(BY_NAME[REFERENCE])
    assert reference.control_dt == 0.01 and reference.physics_dt == pytest.approx(0.002)
    slow, fast = sim_task(BY_NAME["rate_30hz"]), sim_task(BY_NAME["rate_1000hz"])
    assert slow.control_dt == pytest.approx(1 / 30) and slow.physics_dt <= 0.002
    assert round(slow.control_dt / slow.physics_dt) == 17
    assert (fast.control_dt, fast.physics_dt) == (0.001, 0.001)
    assert sim_task(BY_NAME["jitter_30pct"]).control_dt == 0.002


def test_bad_settings_are_refused(tmp_path, capsys):
    with pytest.raises(ConfigError, match="unknown"):
        ClockSettings(worlds=("moon",))
    with pytest.raises(ConfigError, match="rate"):
        ClockCondition("x", rate=0.0)
    assert main(["--episodes", "0", "--out", str(tmp_path / "x.json")]) == 2
    assert "positive integer" in capsys.readouterr().err
    assert not (tmp_path / "x.json").exists()


def test_every_registered_world_is_a_default_world():
    """The bench has no list of its own: its worlds are the registry's and the simulator."""
    assert ClockSettings().worlds == (*world_names(), "sim")
    assert ClockSettings.quick().worlds == world_names()


@pytest.mark.slow
def test_quick_run_writes_reproducible_json(run_script, tmp_path):
    out = tmp_path / "clock.json"
    # two worlds keep it short: a single one and a family (its member pooled like a seed)
    worlds = ("two_point", "procedural")
    done = run_script(
        "bench_clock.py", "--quick", "--worlds", *worlds, "--out", str(out), timeout=600
    )
    assert done.returncode == 0, done.stderr[-3000:]
    assert "| two_point |" in done.stdout
    result = json.loads(out.read_text())
    assert set(result["worlds"]) == set(worlds)
    assert list(result["conditions"]) == list(CONDITION_NAMES)
    for world in result["worlds"].values():
        assert set(world["conditions"]) == set(CONDITION_NAMES)
        for summary in world["conditions"].values():
            outcomes = summary["complete"] + summary["wrong_start"] + summary["incomplete"]
            assert outcomes == summary["n_episodes"] == 2
        assert set(world["per_seed"]) == {"0"}
    # the same settings in this process give the same numbers
    again = run_clock_benchmark(
        ClockSettings.quick(worlds=("two_point",), conditions=("jitter_30pct", "drop_10pct"))
    )
    for name, summary in again["worlds"]["two_point"]["conditions"].items():
        assert summary == result["worlds"]["two_point"]["conditions"][name]
