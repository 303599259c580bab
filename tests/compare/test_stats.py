"""Bootstrap intervals and paired differences on synthetic numbers with known answers."""

from __future__ import annotations

import numpy as np
import pytest

from cpmp.compare.stats import (
    BootstrapOptions,
    SeedUnits,
    interval,
    paired_difference,
    pooled_mean,
    replicates,
    sign_flip_p,
)
from cpmp.errors import ConfigError, DataError

FAST = BootstrapOptions(samples=1000, level=0.95, seed=0)


def bernoulli_seeds(rng: np.random.Generator, p: float, seeds: int, n: int) -> list[SeedUnits]:
    """``seeds`` seeds of ``n`` 0/1 episodes, each complete with probability ``p``."""
    return [SeedUnits.of(rng.random(n) < p) for _ in range(seeds)]


def test_estimate_is_the_weighted_mean_over_all_units():
    # two held-out demos of 10 and 30 samples with MAE 0.1 and 0.3: 0.25 over the 40 samples
    seeds = [SeedUnits.of([0.1], [10]), SeedUnits.of([0.3], [30])]
    assert pooled_mean(seeds) == pytest.approx(0.25, rel=1e-12)  # rel: float rounding only
    out = interval(seeds, FAST)
    assert out.estimate == pytest.approx(0.25, rel=1e-12)
    assert (out.seeds, out.units) == (2, 2)
    # one unit per seed: the replicates are means of resampled seeds, inside the seeds' range
    assert 0.1 <= out.low <= out.estimate <= out.high <= 0.3
    assert out.low < out.high


def test_same_seed_same_interval_another_seed_another():
    rng = np.random.default_rng(1)
    seeds = bernoulli_seeds(rng, 0.6, 3, 20)
    first = interval(seeds, FAST)
    assert interval(seeds, FAST) == first
    assert np.array_equal(replicates([seeds], 300, seed=0), replicates([seeds], 300, seed=0))
    assert not np.array_equal(replicates([seeds], 300, seed=0), replicates([seeds], 300, seed=1))
    assert interval(seeds, BootstrapOptions(samples=1000, seed=1)).estimate == first.estimate


def test_interval_contains_the_mean_and_narrows_with_more_episodes():
    rng = np.random.default_rng(2)
    small = interval(bernoulli_seeds(rng, 0.7, 4, 20), FAST)
    large = interval(bernoulli_seeds(rng, 0.7, 4, 500), FAST)
    for out in (small, large):
        assert out.low <= out.estimate <= out.high
    assert large.high - large.low < 0.5 * (small.high - small.low)
    assert large.low < 0.7 < large.high


def test_coverage_of_a_known_completion_rate():
    """Over 200 data sets of 5 seeds x 40 episodes drawn at p = 0.7, the 95 % interval holds
    p in at least 90 % of them (resampling seeds and episodes counts the episode noise twice
    when seeds do not differ, so it errs wide) and is not wider than twice the binomial
    normal-approximation interval on average."""
    rng = np.random.default_rng(3)
    p, seeds, n = 0.7, 5, 40
    covered, widths = 0, []
    for i in range(200):
        out = interval(bernoulli_seeds(rng, p, seeds, n), BootstrapOptions(samples=400, seed=i))
        covered += out.low <= p <= out.high
        widths.append(out.high - out.low)
    binomial = 2 * 1.96 * np.sqrt(p * (1 - p) / (seeds * n))
    assert covered >= 180
    assert np.mean(widths) < 2.0 * binomial


def test_seed_effect_widens_the_interval():
    """Seeds that differ (a training draw that helps or hurts) widen the interval beyond what
    the same number of episodes of one rate gives: the seed level is resampled."""
    rng = np.random.default_rng(4)
    flat = interval([SeedUnits.of(rng.random(100) < 0.6) for _ in range(4)], FAST)
    varied = interval([SeedUnits.of(rng.random(100) < q) for q in (0.3, 0.5, 0.7, 0.9)], FAST)
    assert varied.high - varied.low > 2 * (flat.high - flat.low)


def test_identical_rows_do_not_differ():
    rng = np.random.default_rng(5)
    row = bernoulli_seeds(rng, 0.5, 3, 50)
    out = paired_difference(row, row, FAST)
    assert (out.estimate, out.low, out.high) == (0.0, 0.0, 0.0)
    assert not out.excludes(0.0)


def test_a_large_shift_is_significant_and_its_sign_kept():
    rng = np.random.default_rng(6)
    a = [SeedUnits.of(rng.normal(0.30, 0.05, 30)) for _ in range(3)]
    b = [SeedUnits.of(u.values - 0.1) for u in a]  # the same demos, each 0.1 lower
    out = paired_difference(a, b, FAST)
    assert out.estimate == pytest.approx(0.1, abs=1e-12)  # abs: float rounding only
    assert out.excludes(0.0) and out.low > 0
    assert paired_difference(b, a, FAST).high < 0


def test_pairing_sees_a_small_consistent_difference():
    """Rows that agree on 190 of 200 episodes and differ on 10, all in a's favour (5 points):
    the paired interval excludes 0, while the two rows' own intervals overlap."""
    rng = np.random.default_rng(7)
    b = [rng.random(50) < 0.7 for _ in range(4)]
    a = [x.copy() for x in b]
    flipped = 0
    for x in a:
        for i in np.flatnonzero(~x)[:3]:
            if flipped < 10:
                x[i], flipped = True, flipped + 1
    assert flipped == 10
    rows_a, rows_b = [SeedUnits.of(x) for x in a], [SeedUnits.of(x) for x in b]
    diff = paired_difference(rows_a, rows_b, FAST)
    assert diff.estimate == pytest.approx(10 / 200, abs=1e-12)  # abs: float rounding only
    assert diff.excludes(0.0)
    own_a, own_b = interval(rows_a, FAST), interval(rows_b, FAST)
    assert own_a.low < own_b.high  # unpaired, the same numbers would not separate


def test_same_rate_different_episodes_is_not_significant():
    """Two rows drawn independently at the same rate (a fixed draw, checked by hand not to be
    one of the 5 % that separate by chance)."""
    rng = np.random.default_rng(8)
    a, b = bernoulli_seeds(rng, 0.6, 3, 60), bernoulli_seeds(rng, 0.6, 3, 60)
    assert not paired_difference(a, b, FAST).excludes(0.0)


@pytest.mark.parametrize("k", [4, 8])
def test_sign_flip_p_is_the_sign_test_on_the_discordant_episodes(k):
    """``k`` of 60 paired episodes differ, all in one direction: the exact two-sided sign test
    gives 2 * 0.5**k (0.125 for 4: not significant, though the percentile bootstrap interval
    already excludes 0; 0.0078 for 8)."""
    b = np.zeros(60)
    a = b.copy()
    a[: k // 2] = a[30 : 30 + k // 2] = 1.0  # half of them in each seed
    rows_a = [SeedUnits.of(a[:30]), SeedUnits.of(a[30:])]
    rows_b = [SeedUnits.of(b[:30]), SeedUnits.of(b[30:])]
    p = sign_flip_p(rows_a, rows_b, 4000, seed=0)
    # 4000 flips: Monte Carlo sd of p is at most 0.0053 (at 0.125); 0.02 is about 4 sd
    assert p == pytest.approx(2 * 0.5**k, abs=0.02)
    if k == 4:
        assert paired_difference(rows_a, rows_b, FAST).excludes(0.0)  # why the test is needed
        assert p > 0.05


def test_sign_flip_p_of_identical_rows_is_one_and_of_a_shift_small():
    rng = np.random.default_rng(9)
    a = [SeedUnits.of(rng.normal(0.3, 0.05, 20)) for _ in range(2)]
    assert sign_flip_p(a, a, 500, seed=0) == 1.0
    b = [SeedUnits.of(u.values - 0.02) for u in a]
    assert sign_flip_p(a, b, 500, seed=0) == pytest.approx(1 / 501, rel=1e-12)


def test_replicates_resample_within_the_drawn_seed_only():
    """A seed of all-0 units and one of all-1 units: every replicate's mean is a multiple of
    1/2 (seed draws only), whatever the units drawn inside each seed."""
    seeds = [SeedUnits.of(np.zeros(7)), SeedUnits.of(np.ones(3))]
    draws = replicates([seeds], 500, seed=0)[:, 0]
    # weighted by unit counts: both seeds 0 -> 0, both 1 -> 1, one of each -> 3/10
    assert set(np.round(draws, 12)) == {0.0, 0.3, 1.0}


def test_unpaired_rows_and_bad_units_are_refused():
    a = [SeedUnits.of([1.0, 0.0]), SeedUnits.of([1.0])]
    with pytest.raises(DataError, match="same seeds and units"):
        paired_difference(a, [SeedUnits.of([1.0, 0.0]), SeedUnits.of([1.0, 1.0])], FAST)
    with pytest.raises(DataError, match="without units"):
        SeedUnits.of([])
    with pytest.raises(DataError, match="weights"):
        SeedUnits.of([0.1, 0.2], [1.0, 0.0])
    with pytest.raises(DataError, match="finite"):
        SeedUnits.of([np.nan])
    with pytest.raises(ConfigError, match="level"):
        BootstrapOptions(level=1.0)
    with pytest.raises(ConfigError, match="samples"):
        BootstrapOptions(samples=10)
