"""Predictor options (:mod:`cpmp.config.predictors`): non-finite or fractional values are
refused where they enter, whole-number floats are accepted as counts."""

from __future__ import annotations

import pytest

from cpmp.config import predictor_config
from cpmp.errors import ConfigError


@pytest.mark.parametrize(
    ("kind", "option", "value"),
    [
        ("klr", "gamma", float("inf")),
        ("klr", "l2", float("nan")),
        ("klr", "support_scale", float("nan")),
        ("klr", "max_support", 4.5),
        ("klr", "min_support", "3"),
        ("klr", "weight_floor", float("-inf")),
        ("mlp", "lr", float("nan")),
        ("mlp", "epochs", 10.5),
        ("klr_sparse", "refine_anchor", float("inf")),
    ],
)
def test_non_finite_or_fractional_predictor_options_are_config_errors(kind, option, value):
    with pytest.raises(ConfigError, match=option):
        predictor_config(kind, **{option: value})


def test_whole_number_floats_are_accepted_as_counts():
    assert predictor_config("klr", min_support=4.0).min_support == 4
