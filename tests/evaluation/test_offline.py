"""Offline evaluation computations of :mod:`cpmp.evaluation.offline` that need no fitted model: the
progress-curve statistics behind Fig. 6 (:func:`~cpmp.evaluation.offline.progress_curves`)."""

from __future__ import annotations

import numpy as np
import pytest

from cpmp.errors import ConfigError, DataError
from cpmp.evaluation.offline import progress_curves


def test_progress_curves_identity_is_diagonal() -> None:
    activations = [(np.linspace(0, 1, n), np.linspace(0, 1, n)) for n in (11, 101, 37)]
    curves = progress_curves(activations, n_bins=21)
    assert curves["n_activations"] == 3
    np.testing.assert_allclose(curves["time"], np.linspace(0, 1, 21))
    # Linear data resample exactly; 1e-12 allows float rounding in np.interp.
    np.testing.assert_allclose(curves["predicted_mean"], curves["time"], atol=1e-12)
    np.testing.assert_allclose(curves["predicted_std"], 0.0, atol=1e-12)
    np.testing.assert_allclose(curves["expected_mean"], curves["time"], atol=1e-12)


def test_progress_curves_offset_and_spread() -> None:
    expected = np.linspace(0, 1, 1001)
    curves = progress_curves([(expected, expected + 0.1), (expected, expected - 0.3)], n_bins=10)
    np.testing.assert_allclose(curves["predicted_mean"], curves["time"] - 0.1, atol=1e-12)
    np.testing.assert_allclose(curves["predicted_std"], 0.2, atol=1e-12)

    late = progress_curves([(expected, expected + 0.1)], n_bins=10)
    np.testing.assert_allclose(late["progress_bins"], np.arange(10) / 10 + 0.05)
    # Each bin's samples are spread evenly, so their mean sits within half a sample
    # spacing (5e-4) of the bin centre.
    np.testing.assert_allclose(late["binned_mean"], late["progress_bins"] + 0.1, atol=1e-3)
    assert late["binned_count"].sum() == 1001


def test_progress_curves_empty_bins_are_nan() -> None:
    curves = progress_curves([(np.array([0.0, 0.05]), np.array([0.2, 0.3]))], n_bins=4)
    assert curves["binned_mean"][0] == pytest.approx(0.25)
    assert np.all(np.isnan(curves["binned_mean"][1:]))


def test_progress_curves_rejects_bad_shapes() -> None:
    with pytest.raises(DataError, match=r"activations\[1\].*\(5,\) and \(4,\)"):
        progress_curves([(np.zeros(3), np.zeros(3)), (np.zeros(5), np.zeros(4))])
    with pytest.raises(DataError, match="n >= 2"):
        progress_curves([(np.zeros((3, 2)), np.zeros((3, 2)))])
    with pytest.raises(DataError, match="at least one"):
        progress_curves([])
    with pytest.raises(ConfigError, match="n_bins"):
        progress_curves([(np.zeros(3), np.zeros(3))], n_bins=1)
