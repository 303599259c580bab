"""Units never matter: the same demonstrations in other units give the same model."""

from __future__ import annotations

import numpy as np
import pytest

from cpmp.data import Demonstration
from cpmp.errors import ConfigError
from cpmp.sequencer import ConcurrentSequencer


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
