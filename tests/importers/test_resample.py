"""One clock for streams at different rates: cleaning, gaps, interpolation, hold, glitches."""

import numpy as np
import pytest

from cpmp.errors import DataError
from cpmp.importers.resample import (
    Gap,
    align_quaternions,
    clean_stream,
    interpolate_linear,
    interpolate_slerp,
    merge_short_activations,
    rotation_columns,
    uniform_clock,
    zero_order_hold,
)


def test_clean_stream_sorts_out_of_order_samples_and_counts_them():
    stream = clean_stream("s", np.array([0.0, 0.2, 0.1, 0.3]), np.array([0, 2, 1, 3]))
    np.testing.assert_array_equal(stream.time, [0.0, 0.1, 0.2, 0.3])
    np.testing.assert_array_equal(stream.values, [0, 1, 2, 3])
    assert stream.report.n_out_of_order == 1
    assert stream.report.n_duplicates == 0
    assert stream.report.n_samples == 4


def test_clean_stream_keeps_the_last_received_of_repeated_stamps():
    stream = clean_stream("s", np.array([0.0, 0.1, 0.1, 0.2]), np.array(["a", "b", "c", "d"]))
    np.testing.assert_array_equal(stream.time, [0.0, 0.1, 0.2])
    np.testing.assert_array_equal(stream.values, ["a", "c", "d"])
    assert stream.report.n_duplicates == 1
    assert stream.report.n_out_of_order == 0


def test_clean_stream_reports_gaps_longer_than_the_limit():
    t = np.array([0.0, 0.1, 0.2, 0.9, 1.0, 1.5])
    stream = clean_stream("topic /x", t, np.zeros(6), max_gap=0.3)
    assert stream.report.gaps == (Gap("topic /x", 0.2, 0.9), Gap("topic /x", 1.0, 1.5))
    assert stream.report.gaps[0].duration == pytest.approx(0.7)
    assert clean_stream("s", t, np.zeros(6)).report.gaps == ()  # no limit, no gaps


def test_clean_stream_refuses_empty_streams_and_bad_stamps():
    with pytest.raises(DataError, match="topic /x: no samples"):
        clean_stream("topic /x", np.array([]), np.array([]))
    with pytest.raises(DataError, match="stamp 1 is nan"):
        clean_stream("s", np.array([0.0, np.nan]), np.zeros(2))


def test_uniform_clock_includes_the_end_and_has_the_rate():
    clock = uniform_clock(0.004, 1.004, 50.0)
    assert len(clock) == 51
    assert clock[0] == 0.004
    assert clock[-1] == pytest.approx(1.004)
    np.testing.assert_allclose(np.diff(clock), 0.02)
    assert len(uniform_clock(0.0, 0.019, 50.0)) == 1
    assert len(uniform_clock(1.0, 0.0, 50.0)) == 0


def test_interpolate_linear_is_exact_on_lines_and_returns_columns():
    t = np.array([0.0, 1.0, 3.0])
    values = np.column_stack([2 * t + 1, -t])
    clock = np.array([0.0, 0.5, 2.0, 3.0])
    np.testing.assert_allclose(
        interpolate_linear(t, values, clock), np.column_stack([2 * clock + 1, -clock])
    )
    assert interpolate_linear(t, t, clock).shape == (4, 1)


def test_zero_order_hold_keeps_the_last_sample_at_or_before_each_tick():
    t = np.array([0.0, 0.35, 0.7])
    labels = np.array(["reach", "grasp", "lift"])
    clock = np.array([0.0, 0.2, 0.35, 0.5, 0.9])
    np.testing.assert_array_equal(
        zero_order_hold(t, labels, clock), ["reach", "reach", "grasp", "grasp", "lift"]
    )
    with pytest.raises(DataError, match="before the first sample"):
        zero_order_hold(t, labels, np.array([-0.1, 0.0]))


def test_merge_short_activations_removes_a_glitch_and_reports_it():
    time = np.arange(10) * 0.02
    labels = np.array(["a"] * 4 + ["b"] * 2 + ["a"] * 4)
    result = merge_short_activations(time, labels, 0.05)
    np.testing.assert_array_equal(result.labels, ["a"] * 10)
    (glitch,) = result.glitches
    assert (glitch.mp, glitch.merged_into) == ("b", "a")
    assert glitch.start == pytest.approx(0.08)
    assert glitch.duration == pytest.approx(0.04)


def test_merge_short_activations_keeps_long_ones_and_merges_a_short_start_forward():
    time = np.arange(10) * 0.1
    labels = np.array(["x"] + ["a"] * 4 + ["b"] * 5)
    result = merge_short_activations(time, labels, 0.15)
    np.testing.assert_array_equal(result.labels, ["a"] * 5 + ["b"] * 5)
    assert [g.merged_into for g in result.glitches] == ["a"]
    unchanged = merge_short_activations(time, labels, 0.0)
    np.testing.assert_array_equal(unchanged.labels, labels)
    assert unchanged.glitches == ()


def _yaw(angle):
    angle = np.asarray(angle, dtype=float)
    return np.column_stack([0 * angle, 0 * angle, np.sin(angle / 2), np.cos(angle / 2)])


def test_a_quaternion_sign_flip_is_aligned_and_slerped_without_a_dip():
    t = np.arange(6) * 0.1
    q = _yaw(t)
    q[2:4] *= -1  # mocap: the same rotations with the other sign
    clock = np.linspace(0.0, 0.5, 26)
    linear = interpolate_linear(t, q, clock)
    assert np.linalg.norm(linear, axis=1).min() < 0.21  # component-wise: |q| = 0.2 midway
    aligned = align_quaternions(q)
    assert aligned.n_flips == 2
    np.testing.assert_allclose(aligned.values, _yaw(t))
    slerped = interpolate_slerp(t, aligned.values, clock)
    np.testing.assert_allclose(slerped, _yaw(clock), atol=1e-12)  # exact on one axis
    # slerp takes the shorter arc even of unaligned samples
    np.testing.assert_allclose(np.abs(interpolate_slerp(t, q, clock)), np.abs(_yaw(clock)))
    with pytest.raises(DataError, match=r"quaternion 1 is .* not a rotation"):
        align_quaternions(np.array([[0, 0, 0, 1.0], [0, 0, 0, 0]]), "topic /q")


def test_rotation_columns_give_the_rotation_vector_and_the_6d_representation():
    angle = np.array([0.0, 0.5, np.pi - 1e-3])
    q = _yaw(angle)
    np.testing.assert_allclose(rotation_columns(-q, "rotvec")[:, 2], angle, atol=1e-9)
    axis = np.array([1.0, 2.0, 2.0]) / 3.0
    general = np.append(axis * np.sin(0.35), np.cos(0.35))[None, :]
    np.testing.assert_allclose(rotation_columns(general, "rotvec")[0], axis * 0.7)
    six = rotation_columns(q, "matrix6")
    c, s = np.cos(angle), np.sin(angle)
    np.testing.assert_allclose(six, np.column_stack([c, s, 0 * c, -s, c, 0 * c]), atol=1e-12)
    np.testing.assert_allclose(rotation_columns(q, "quat"), q)
    with pytest.raises(DataError, match="unknown rotation representation 'euler'"):
        rotation_columns(q, "euler")
