import numpy as np
import pytest

from cpmp import progress
from cpmp.config import KLRConfig
from cpmp.errors import ConfigError, DataError
from cpmp.predictors import make_predictor
from cpmp.predictors.base import FeatureScaler
from cpmp.progress import (
    cumulative_path_length,
    denoise_trajectory,
    expected_progress,
    feature_path_lengths,
    path_length,
    path_trajectory,
    progress_labels,
    support_count,
    support_point_count,
    support_points,
    tv_denoise,
    white_noise_std,
)

RULE = (KLRConfig().support_scale, KLRConfig().min_support, KLRConfig().max_support)
"""The klr predictor's default support rule (points per unit path length, minimum, maximum)."""


def test_hand_computed_example():
    # L1 steps: |1|+|0| = 1, |0|+|2| = 2, 0 -> cumulative 0, 1, 3, 3 -> normalised by 3
    x = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 2.0], [1.0, 2.0]])
    np.testing.assert_allclose(cumulative_path_length(x), [0.0, 1.0, 3.0, 3.0])
    np.testing.assert_allclose(expected_progress(x), [0.0, 1 / 3, 1.0, 1.0])
    assert path_length(x) == pytest.approx(3.0)


def test_l1_not_l2():
    x = np.array([[0.0, 0.0], [1.0, 1.0], [1.0, 2.0]])
    np.testing.assert_allclose(expected_progress(x), [0.0, 2 / 3, 1.0])


def test_monotone_and_ends_at_one():
    rng = np.random.default_rng(0)
    x = np.cumsum(rng.normal(size=(200, 5)), axis=0)
    phi = expected_progress(x)
    assert phi[0] == 0.0 and phi[-1] == 1.0
    assert np.all(np.diff(phi) >= 0)


def test_zero_length_falls_back_to_time_then_index():
    x = np.ones((4, 3))
    np.testing.assert_allclose(expected_progress(x), [0, 1 / 3, 2 / 3, 1])
    np.testing.assert_allclose(
        expected_progress(x, time=np.array([0.0, 0.1, 0.3, 1.0])), [0, 0.1, 0.3, 1.0]
    )
    np.testing.assert_allclose(expected_progress(np.ones((1, 3))), [1.0])
    np.testing.assert_array_equal(expected_progress(np.zeros((5, 2))), np.linspace(0.0, 1.0, 5))


def test_bad_input():
    with pytest.raises(DataError, match=r"shape \(n, d\)"):
        expected_progress(np.ones(3))
    with pytest.raises(DataError, match="NaN"):
        expected_progress(np.array([[0.0], [np.nan]]))
    with pytest.raises(DataError, match="at least one sample"):
        expected_progress(np.zeros((0, 2)))


def test_support_points_equidistant_in_l1_arc_length():
    x = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0]])  # L1 length 4
    pts = support_points(x, scale=1.0, min_support=3, max_support=None, noise="none")
    assert pts.shape == (4, 2)  # ceil(1.0 * 4) = 4
    np.testing.assert_allclose(pts, [[0, 0], [4 / 3, 0], [2, 2 / 3], [2, 2]])
    steps = np.abs(np.diff(pts, axis=0)).sum(1)
    np.testing.assert_allclose(steps, 4 / 3)


def test_support_count_rule():
    assert support_count(0.4, 2.0, 3, None) == 3  # min_support wins
    assert support_count(2.1, 2.0, 3, None) == 5  # ceil(4.2)
    assert support_count(100.0, 2.0, 3, 10) == 10  # capped
    with pytest.raises(ConfigError):
        support_count(1.0, -1.0, 3, None)
    # zero length: one point
    assert support_points(np.ones((5, 2)), 2.0, 3, None, "none").shape == (1, 2)


@pytest.mark.parametrize("max_support", [None, 4])
def test_support_point_count_is_what_support_points_places(max_support):
    rng = np.random.default_rng(0)
    trajectories = [
        np.cumsum(rng.normal(size=(50, 3)), axis=0),
        np.zeros((7, 2)),  # still: one point
        np.ones((1, 2)),  # a single sample
        np.linspace([0.0, 0.0], [0.1, 0.0], 5),  # short: the minimum
    ]
    for x in trajectories:
        placed = support_points(x, 2.0, 3, max_support, "none")
        assert support_point_count(x, 2.0, 3, max_support, "none") == len(placed)


# --- eq. 1 under feature noise (noise="auto") ---------------------------------------------


def _smooth_trajectories() -> list[np.ndarray]:
    """Noise-free trajectories as a simulator records them at 100 Hz: smooth motions, an MP
    converging and then resting, a binary contact flag, constants, a single sample."""
    t = np.linspace(0.0, 3.0, 300)
    converge = 1.0 - np.exp(-t / 0.4)
    return [
        np.column_stack([np.sin(2 * t), np.cos(5 * t), t**2, np.exp(-t)]),
        np.column_stack([converge, 0.5 * converge, np.full_like(t, 0.3), (t > 1.2) * 1.0]),
        np.column_stack([t, -2.0 * t]),
        np.zeros((40, 3)),
        np.ones((1, 2)),
    ]


def _moving_then_resting(n: int = 300) -> np.ndarray:
    """``(n, 3)``: a straight segment of L1 length 1.5 traversed as a converging MP does (fast
    at first, then at rest), and one constant feature."""
    s = 1.0 - np.exp(-np.linspace(0.0, 3.0, n) / 0.4)
    return np.column_stack([s, 0.5 * s, np.full(n, 0.3)])


def test_white_noise_std_is_exactly_zero_without_noise():
    for x in _smooth_trajectories():
        np.testing.assert_array_equal(white_noise_std(x), np.zeros(x.shape[1]))


@pytest.mark.parametrize("with_signal", [False, True])
def test_white_noise_std_recovers_sigma(with_signal):
    n = 4000
    sigma = np.array([0.01, 0.1, 1.0, 10.0])
    x = sigma * np.random.default_rng(3).standard_normal((n, 4))
    if with_signal:  # a smooth motion underneath does not bias the estimate
        x = x + np.sin(np.linspace(0.0, 6.0, n))[:, None] * [1.0, 5.0, 0.1, 3.0]
    # the estimate's relative standard error is about 1.8 / sqrt(n) (measured over 200 draws)
    np.testing.assert_allclose(white_noise_std(x), sigma, rtol=5 * 1.8 / np.sqrt(n))


def _tv_objective(x: np.ndarray, y: np.ndarray, lam: float) -> float:
    return 0.5 * float(np.sum((y - x) ** 2)) + lam * float(np.abs(np.diff(y)).sum())


@pytest.mark.parametrize("lam", [0.01, 0.3, 2.0])
def test_tv_denoise_is_the_minimiser(lam):
    rng = np.random.default_rng(int(lam * 100))
    for n in (2, 3, 17, 200):
        x = np.cumsum(rng.normal(size=n)) + rng.normal(size=n)
        y = tv_denoise(x, lam)
        # optimality: x - y = D^T u with |u_i| <= lam, u_i = lam * sign(y_{i+1} - y_i) where
        # y jumps; u is minus the running sum of the residual (tolerance: float rounding)
        u = -np.cumsum(x - y)
        assert abs(u[-1]) < 1e-9 * n
        assert np.all(np.abs(u[:-1]) <= lam + 1e-9)
        jumps = np.abs(np.diff(y)) > 1e-9
        np.testing.assert_allclose(u[:-1][jumps], lam * np.sign(np.diff(y)[jumps]), atol=1e-9)
        # and no perturbation does better
        for _ in range(20):
            assert _tv_objective(x, y, lam) <= _tv_objective(x, y + 1e-3 * rng.normal(size=n), lam)


def test_tv_denoise_limits():
    x = np.array([0.0, 3.0, -1.0, 2.0])
    np.testing.assert_array_equal(tv_denoise(x, 0.0), x)
    np.testing.assert_allclose(tv_denoise(x, 1e6), np.full(4, x.mean()))
    np.testing.assert_array_equal(tv_denoise(np.array([5.0]), 1.0), [5.0])


def test_clean_labels_and_supports_unchanged():
    time = np.linspace(0.0, 3.0, 300)
    for x in _smooth_trajectories():
        np.testing.assert_array_equal(denoise_trajectory(x), x)
        t = time[: len(x)]
        np.testing.assert_array_equal(
            expected_progress(x, t, noise="auto"), expected_progress(x, t)
        )
        np.testing.assert_array_equal(
            progress_labels(x, t, "path_denoised"), progress_labels(x, t, "path")
        )
        np.testing.assert_array_equal(
            support_points(x, *RULE, "auto"), support_points(x, *RULE, "none")
        )


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_labels_of_a_noisy_line_stay_close_to_the_clean_labels(seed):
    clean = _moving_then_resting()
    sigma = 0.01
    x = clean + sigma * np.random.default_rng(seed).standard_normal(clean.shape)
    reference = expected_progress(clean)
    # tolerance: the noise's L1 size (3 noisy features) relative to the path's L1 length 1.5
    unit = 3 * sigma / path_length(clean)
    new = np.abs(expected_progress(x, noise="auto") - reference)
    assert new.mean() < unit and new.max() < 6 * unit
    # eq. 1 on the recorded features drifts towards normalised time: it fails this tolerance
    old = np.abs(expected_progress(x) - reference)
    assert old.mean() > 10 * unit


def test_support_count_follows_the_motion_not_the_noise():
    clean = _moving_then_resting()
    x = clean + 0.05 * np.random.default_rng(0).standard_normal(clean.shape)
    count = support_point_count(clean, *RULE, "none")
    assert support_point_count(x, *RULE, "auto") == count
    assert len(support_points(x, *RULE, "auto")) == count
    assert support_point_count(x, *RULE, "none") > 10 * count  # every noisy step adds length


def test_feature_path_lengths_split_the_path_length():
    x = _moving_then_resting() + 0.01 * np.random.default_rng(4).standard_normal((300, 3))
    for noise in ("none", "auto"):
        per_feature = feature_path_lengths(x, noise)
        assert per_feature.shape == (3,)
        assert per_feature.sum() == pytest.approx(path_length(x, noise))
    # denoised, the constant feature travels (almost) nowhere and x travels twice as far as y
    lengths = feature_path_lengths(x, "auto")
    assert lengths[2] < 0.05 * lengths[0]
    assert lengths[0] / lengths[1] == pytest.approx(2.0, rel=0.1)


def test_path_trajectory_is_what_the_noise_option_measures_along():
    """Measuring on ``path_trajectory(x, noise)`` with ``noise="none"`` is measuring ``x``
    with ``noise``: how a fit reuses one denoising for labels, supports and weights."""
    x = _moving_then_resting() + 0.01 * np.random.default_rng(5).standard_normal((300, 3))
    path = path_trajectory(x, "auto")
    np.testing.assert_array_equal(path, denoise_trajectory(x))
    assert np.abs(path - x).max() > 0.005  # noise was detected and removed
    assert path_trajectory(x, "none") is x  # float64 features as recorded, not copied
    np.testing.assert_array_equal(expected_progress(path), expected_progress(x, noise="auto"))
    np.testing.assert_array_equal(feature_path_lengths(path), feature_path_lengths(x, "auto"))
    np.testing.assert_array_equal(
        support_points(path, *RULE, "none"), support_points(x, *RULE, "auto")
    )
    with pytest.raises(ConfigError, match="path noise must be one of auto, none"):
        path_trajectory(x, "median")


def test_progress_module_keeps_no_state_between_calls():
    """No cache or other container at module level (the fit hands denoised trajectories on
    instead); and denoising the same trajectory twice does the work twice."""
    containers = [
        name
        for name, value in vars(progress).items()
        if isinstance(value, (dict, list, set)) and not name.startswith("__")
    ]
    assert containers == []
    x = _moving_then_resting() + 0.01 * np.random.default_rng(6).standard_normal((300, 3))
    calls = []

    def counting_tv_denoise(signal: np.ndarray, lam: float) -> np.ndarray:
        calls.append(lam)
        return tv_denoise(signal, lam)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(progress, "tv_denoise", counting_tv_denoise)
        first = denoise_trajectory(x)
        second = denoise_trajectory(x)
    np.testing.assert_array_equal(first, second)
    assert len(calls) == 6 and calls[:3] == calls[3:]  # 3 noisy features, denoised each time


def test_path_noise_option():
    with pytest.raises(ConfigError, match="path noise must be one of auto, none"):
        expected_progress(np.zeros((3, 2)), noise="median")
    keys = [("v", "a")]
    assert make_predictor("klr", keys, 2).labels == "path_denoised"  # the default
    assert make_predictor("klr", keys, 2, path_noise="none").labels == "path"
    assert make_predictor("mlp", keys, 2, path_noise="auto").labels == "path_denoised"
    assert make_predictor("time_phase", keys, 2).labels == "time"
    with pytest.raises(ConfigError, match="path_noise must be one of auto, none"):
        make_predictor("klr", keys, 2, path_noise="yes")


def test_global_scale_is_measured_on_the_denoised_features():
    """White noise widens every feature's range; with path_noise auto the scaler sees the
    ranges of the motion, so path lengths and support counts in scaled units stay put."""
    moving = _moving_then_resting()
    flag = (np.arange(300) >= 150) * 1.0  # a contact flag: the widest feature, as in cpmp.sim
    clean = np.concatenate([np.column_stack([moving, flag])] * 3)
    sigma = 0.01
    scales = {}
    for seed in range(5):
        noisy = clean + sigma * np.random.default_rng(seed).standard_normal(clean.shape)
        for noise in ("none", "auto"):
            scaler = FeatureScaler(4, noise=noise)
            scaler.fit(noisy, "global")
            scales.setdefault(noise, []).append(float(scaler.scale[0]))
    clean_scaler = FeatureScaler(4, noise="auto")
    clean_scaler.fit(clean, "global")
    assert float(clean_scaler.scale[0]) == 1.0  # nothing detected: the recorded range
    # the range of 900 noisy samples per level grows by about 2 * 3 sigma; denoised, the
    # flag's long plateaus keep their level (TV shrinks a plateau of m samples by lam / m)
    assert min(scales["none"]) - 1.0 > 4 * sigma
    assert max(abs(s - 1.0) for s in scales["auto"]) < sigma
