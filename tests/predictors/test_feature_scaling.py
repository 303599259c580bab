"""Feature scaling (:class:`cpmp.predictors.FeatureScaler`, option ``feature_scaling``): the
fitted offsets and scales, and units that never matter: the same demonstrations in other units
give the same model."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from cpmp.data.demonstration import Demonstration
from cpmp.errors import ConfigError
from cpmp.predictors import FeatureScaler
from cpmp.sequencer.sequencer import ConcurrentSequencer

# three features in different units and a constant one (scale 1 in the per-feature modes)
SAMPLES = np.array([[0.0, 10.0, -2.0, 7.0], [1.0, 30.0, -1.0, 7.0], [3.0, 20.0, 2.0, 7.0]])


@pytest.mark.parametrize(
    ("mode", "offset", "scale"),
    [
        ("global", [0.0, 10.0, -2.0, 7.0], [20.0, 20.0, 20.0, 20.0]),
        ("minmax", [0.0, 10.0, -2.0, 7.0], [3.0, 20.0, 4.0, 1.0]),
        (
            "standard",
            [4 / 3, 20.0, -1 / 3, 7.0],
            [np.sqrt(14 / 9), np.sqrt(200 / 3), np.sqrt(26 / 9), 1.0],
        ),
        ("none", [0.0] * 4, [1.0] * 4),
    ],
)
def test_fitted_offset_and_scale(mode: str, offset: list[float], scale: list[float]) -> None:
    scaler = FeatureScaler(4)
    scaler.fit(SAMPLES, mode)
    np.testing.assert_allclose(scaler.offset.numpy(), offset, rtol=1e-12)
    np.testing.assert_allclose(scaler.scale.numpy(), scale, rtol=1e-12)
    scaled = scaler(torch.as_tensor(SAMPLES)).numpy()
    np.testing.assert_allclose(scaled, scaler.transform(SAMPLES), rtol=0, atol=0)
    np.testing.assert_allclose(scaled, (SAMPLES - offset) / scale, rtol=1e-12)


def test_global_scaling_does_not_see_units() -> None:
    a, b = FeatureScaler(4), FeatureScaler(4)
    a.fit(SAMPLES, "global")
    b.fit(SAMPLES * 1e3, "global")
    # the same numbers up to the rounding of the unit change
    np.testing.assert_allclose(b.transform(SAMPLES * 1e3), a.transform(SAMPLES), atol=1e-12)


def _in_units(demos: list[Demonstration], factor: float) -> list[Demonstration]:
    return [
        Demonstration(d.time, d.features * factor, d.labels, d.feature_names, d.name) for d in demos
    ]


@pytest.fixture(scope="module")
def reference(train_demos):
    return ConcurrentSequencer.fit(train_demos, "klr", seed=0, logger=None)


@pytest.mark.parametrize("factor", [1e3, 1e-3])
def test_units_do_not_change_graphs_supports_or_progress(
    reference, train_demos, test_demos, factor
):
    seq = ConcurrentSequencer.fit(_in_units(train_demos, factor), "klr", seed=0, logger=None)
    assert seq.describe() == reference.describe()
    assert seq.predictor.support_counts() == reference.predictor.support_counts()
    x = test_demos[0].features
    np.testing.assert_allclose(seq.progress(x * factor), reference.progress(x), atol=1e-6)


def test_paper_scaling_none_depends_on_units(train_demos):
    """With the paper's raw features the support count follows the units (why ``global`` is
    the default)."""
    a = ConcurrentSequencer.fit(train_demos, "klr", seed=0, logger=None, feature_scaling="none")
    b = ConcurrentSequencer.fit(
        _in_units(train_demos, 10.0), "klr", seed=0, logger=None, feature_scaling="none"
    )
    total = sum(a.predictor.support_counts().values())
    assert sum(b.predictor.support_counts().values()) > 3 * total


def test_support_cap_names_the_options_to_change(train_demos):
    with pytest.raises(ConfigError, match="max_total_support"):
        ConcurrentSequencer.fit(
            _in_units(train_demos, 1e9), "klr", seed=0, logger=None, feature_scaling="none"
        )
