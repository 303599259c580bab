"""Feature noise: reproducibility, noise level, constant features, no mutation, bad input."""

import math

import numpy as np
import pytest

from cpmp.data.augment import add_feature_noise, feature_ranges, noisy_features
from cpmp.data.demonstration import Demonstration
from cpmp.errors import ConfigError
from cpmp.progress import white_noise_std


def _demos(n_demos: int = 3, n: int = 2000, seed: int = 0) -> list[Demonstration]:
    """Demos with features of different ranges and a constant context column."""
    rng = np.random.default_rng(seed)
    out = []
    for m in range(n_demos):
        t = np.arange(n) * 0.01
        x = np.column_stack(
            [
                np.sin(t + m),  # range ~2
                10.0 * rng.uniform(size=n),  # range ~10
                np.full(n, 0.3),  # constant: no noise
            ]
        )
        labels = {"v": np.where(t < t[n // 2], "a", "b")}
        out.append(
            Demonstration(
                t, x, labels, ["s", "u", "ctx"], name=f"demo_{m}", metadata={"context": 0.3}
            )
        )
    return out


def test_same_seed_same_noise_other_seed_other_noise():
    demos = _demos()
    a = add_feature_noise(demos, 0.05, seed=7)
    b = add_feature_noise(demos, 0.05, seed=7)
    c = add_feature_noise(demos, 0.05, seed=8)
    for x, y, z in zip(a, b, c, strict=True):
        assert np.array_equal(x.features, y.features)
        assert not np.array_equal(x.features, z.features)


@pytest.mark.parametrize("sigma", [0.01, 0.05])
def test_noise_std_is_sigma_times_range(sigma):
    demos = _demos()
    ranges = feature_ranges(demos)
    noisy = add_feature_noise(demos, sigma, seed=1)
    diff = np.concatenate([n.features - d.features for n, d in zip(noisy, demos, strict=True)])
    std = diff.std(axis=0)
    # 6000 samples per column: the sample std is within ~2 % (1 sigma) of the true one
    np.testing.assert_allclose(std[:2], sigma * ranges[:2], rtol=0.08)
    assert np.all(np.abs(diff.mean(axis=0)[:2]) < 4 * sigma * ranges[:2] / math.sqrt(len(diff)))
    assert np.array_equal(diff[:, 2], np.zeros(len(diff)))  # constant feature untouched


def test_given_ranges_are_used():
    demos = _demos(n_demos=2)
    noisy = add_feature_noise(demos, 0.1, seed=2, ranges=[1.0, 0.0, 2.0])
    diff = np.concatenate([n.features - d.features for n, d in zip(noisy, demos, strict=True)])
    np.testing.assert_allclose(diff.std(axis=0), [0.1, 0.0, 0.2], rtol=0.08, atol=1e-12)


def test_everything_but_features_kept_and_inputs_not_modified():
    demos = _demos()
    before = [(d.features.copy(), d.time.copy(), dict(d.metadata)) for d in demos]
    noisy = add_feature_noise(demos, 0.05, seed=3)
    for d, (x, t, meta) in zip(demos, before, strict=True):
        assert np.array_equal(d.features, x) and np.array_equal(d.time, t)
        assert d.metadata == meta
    for n, d in zip(noisy, demos, strict=True):
        assert n is not d and n.features is not d.features
        assert n.name == d.name and n.feature_names == d.feature_names
        assert np.array_equal(n.time, d.time)
        assert all(np.array_equal(n.labels[v], d.labels[v]) for v in d.labels)
        assert n.metadata == {**d.metadata, "feature_noise": 0.05}


def test_zero_sigma_returns_equal_copies():
    demos = _demos(n_demos=2, n=50)
    out = add_feature_noise(demos, 0.0, seed=0)
    for n, d in zip(out, demos, strict=True):
        assert np.array_equal(n.features, d.features) and n.features is not d.features
    assert add_feature_noise([], 0.1, seed=0) == []


@pytest.mark.parametrize("sigma", [-0.01, math.nan, math.inf, "0.1", None, True])
def test_bad_sigma_raises(sigma):
    with pytest.raises(ConfigError, match="sigma"):
        add_feature_noise(_demos(n_demos=1, n=10), sigma, seed=0)


def test_bad_ranges_raise():
    demos = _demos(n_demos=1, n=10)
    with pytest.raises(ConfigError, match="one entry per feature"):
        add_feature_noise(demos, 0.1, seed=0, ranges=[1.0, 1.0])
    with pytest.raises(ConfigError, match="finite"):
        add_feature_noise(demos, 0.1, seed=0, ranges=[1.0, -1.0, 1.0])


def test_noisy_features_for_closed_loop():
    rng = np.random.default_rng(0)
    x = np.array([1.0, 2.0, 3.0])
    samples = np.stack([noisy_features(x, 0.05, [2.0, 0.0, 10.0], rng) for _ in range(4000)])
    assert np.array_equal(x, [1.0, 2.0, 3.0])  # not modified
    np.testing.assert_allclose(samples.std(axis=0), [0.1, 0.0, 0.5], rtol=0.08, atol=1e-12)
    assert np.all(samples[:, 1] == 2.0)
    batch = noisy_features(np.zeros((5, 3)), 0.0, [1.0, 1.0, 1.0], rng)
    assert batch.shape == (5, 3) and not batch.any()


def test_noise_level_is_what_the_progress_label_estimates():
    """add_feature_noise and cpmp.progress.white_noise_std agree on the noise's size: ~0
    before, ``sigma * range`` after (what the noise-robust eq. 1 removes)."""
    t = np.arange(3000) * 0.01
    x = np.column_stack([np.sin(t), 4.0 * np.cos(0.3 * t), np.full_like(t, 0.3)])
    demo = Demonstration(t, x, {"v": np.full(len(t), "a")}, ["s", "c", "ctx"], name="demo_0")
    np.testing.assert_array_equal(white_noise_std(x), np.zeros(3))
    sigma = 0.01
    (noisy,) = add_feature_noise([demo], sigma, seed=5)
    expected = sigma * feature_ranges([demo])
    # relative standard error of the estimate: about 1.8 / sqrt(n); constant features stay 0
    np.testing.assert_allclose(white_noise_std(noisy.features), expected, rtol=5 * 1.8 / 55)
