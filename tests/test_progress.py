import numpy as np
import pytest

from cpmp.errors import ConfigError, DataError
from cpmp.progress import (
    cumulative_path_length,
    expected_progress,
    path_length,
    support_count,
    support_point_count,
    support_points,
)


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
    assert np.all(np.isfinite(expected_progress(np.zeros((5, 2)))))


def test_bad_input():
    with pytest.raises(DataError, match=r"shape \(n, d\)"):
        expected_progress(np.ones(3))
    with pytest.raises(DataError, match="NaN"):
        expected_progress(np.array([[0.0], [np.nan]]))
    with pytest.raises(DataError, match="at least one sample"):
        expected_progress(np.zeros((0, 2)))


def test_support_points_equidistant_in_l1_arc_length():
    x = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0]])  # L1 length 4
    pts = support_points(x, scale=1.0, min_support=3)
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
    assert support_points(np.ones((5, 2)), 2.0, 3).shape == (1, 2)  # zero length: one point


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
        placed = support_points(x, 2.0, 3, max_support)
        assert support_point_count(x, 2.0, 3, max_support) == len(placed)
