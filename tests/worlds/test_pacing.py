"""The pacer of paced worlds (cpmp.worlds.pacing): speeds drawn per activation, one hold each."""

from __future__ import annotations

import math

import pytest

from cpmp.config.task import PAUSE_AT, Pacing
from cpmp.errors import ConfigError
from cpmp.worlds.pacing import Pacer

DT = 0.01


def run(pacer: Pacer, mps: list[str], distance: list[float]) -> list[float]:
    """The speed factors of variable ``v`` over ticks with its MP and distance per tick."""
    return [pacer.speeds({"v": m}, {"v": d})["v"] for m, d in zip(mps, distance, strict=True)]


def test_unpaced_runs_at_one_and_draws_nothing():
    pacer = Pacer(Pacing(), seed=0, dt=DT)
    state = pacer.rng.bit_generator.state
    assert run(pacer, ["a"] * 5 + ["b"] * 5, [1.0 - 0.1 * k for k in range(10)]) == [1.0] * 10
    assert pacer.rng.bit_generator.state == state and pacer.holds == []


def test_speed_is_drawn_per_activation_within_the_range():
    pacer = Pacer(Pacing(speed=(0.5, 2.0)), seed=1, dt=DT)
    mps = [name for name in "abcdefgh" for _ in range(3)]
    factors = run(pacer, mps, [1.0] * len(mps))
    per_activation = factors[::3]
    assert all(0.5 <= f <= 2.0 for f in per_activation)
    assert factors == [f for f in per_activation for _ in range(3)]  # constant within one
    assert len(set(per_activation)) == len(per_activation)  # a new draw each activation
    assert [p.speed for _, _, p in pacer.paces] == per_activation


def test_a_hold_starts_at_the_drawn_fraction_and_lasts_its_ticks():
    pacer = Pacer(Pacing(speed=(1.5, 1.5), pause=(0.2, 0.2)), seed=2, dt=DT)
    distance = [1.0 - 0.01 * k for k in range(100)]
    factors = run(pacer, ["a"] * 100, distance)
    (_, _, pace) = pacer.paces[0]
    assert PAUSE_AT[0] <= pace.pause_at <= PAUSE_AT[1] and pace.pause_ticks == 20
    start = next(k for k, d in enumerate(distance) if d <= 1.0 - pace.pause_at)
    assert factors[:start] == [1.5] * start
    assert factors[start : start + 20] == [0.0] * 20
    assert factors[start + 20 :] == [1.5] * (100 - start - 20)  # one hold per activation
    assert [(h.variable, h.mp, h.start, h.ticks) for h in pacer.holds] == [("v", "a", start, 20)]


def test_pause_probability_decides_how_many_activations_hold():
    never = Pacer(Pacing(pause=(0.1, 0.1), pause_probability=0.0), seed=3, dt=DT)
    always = Pacer(Pacing(pause=(0.1, 0.1), pause_probability=1.0), seed=3, dt=DT)
    mps = [f"m{i}" for i in range(40) for _ in range(50)]
    distance = [1.0 - 0.02 * (k % 50) for k in range(len(mps))]
    run(never, mps, distance)
    run(always, mps, distance)
    assert len(never.holds) == 0 and len(always.holds) == 40
    half = Pacer(Pacing(pause=(0.1, 0.1), pause_probability=0.5), seed=3, dt=DT)
    run(half, mps, distance)
    assert 10 <= len(half.holds) <= 30  # binomial(40, 0.5): outside only with p < 0.002


def test_no_pause_mps_and_activations_at_their_goal_never_hold():
    pacing = Pacing(pause=(0.1, 0.1))
    pacer = Pacer(pacing, seed=4, dt=DT, no_pause={"v/follow"}, min_distance=1e-3)
    run(pacer, ["follow"] * 30, [1.0 - 0.03 * k for k in range(30)])
    run(pacer, ["idle"] * 30, [1e-4] * 30)
    run(pacer, ["reach"] * 30, [1.0 - 0.03 * k for k in range(30)])
    assert [h.mp for h in pacer.holds] == ["reach"]


def test_same_seed_same_paces_other_seed_other_paces():
    pacing = Pacing(speed=(0.5, 2.0), pause=(0.3, 1.0), pause_probability=0.5)

    def paces(seed):
        pacer = Pacer(pacing, seed=seed, dt=DT)
        run(pacer, [f"m{i}" for i in range(10) for _ in range(5)], [1.0] * 50)
        return [p for _, _, p in pacer.paces]

    assert paces((0, 0, 1)) == paces((0, 0, 1))
    assert paces((0, 0, 1)) != paces((0, 0, 2))


def test_speed_draws_are_log_uniform():
    pacer = Pacer(Pacing(speed=(0.5, 2.0)), seed=5, dt=DT)
    logs = [math.log(pacer.draw().speed) for _ in range(4000)]
    # log-uniform on [log 0.5, log 2]: mean 0, half the draws below 1 (4000 draws: sd 0.008)
    assert abs(sum(logs) / len(logs)) < 0.03
    assert abs(sum(v < 0 for v in logs) / len(logs) - 0.5) < 0.03


def test_bad_period_and_pacing_raise_config_error():
    with pytest.raises(ConfigError, match="dt must be > 0"):
        Pacer(Pacing(), seed=0, dt=0.0)
    with pytest.raises(ConfigError, match=r"Pacing\.speed must be"):
        Pacing(speed=(0.0, 1.0))
    with pytest.raises(ConfigError, match=r"Pacing\.pause_probability"):
        Pacing(pause_probability=-0.5)
