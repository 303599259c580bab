"""Predictor options (:mod:`cpmp.config.predictors`): non-finite or fractional values are
refused where they enter, whole-number floats are accepted as counts."""

from __future__ import annotations

import pytest
import torch

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


def test_dtype_auto_resolves_by_the_training_samples() -> None:
    from cpmp.config import DTYPES, FLOAT32_FROM_SAMPLES, KLRConfig, resolved_dtype

    assert KLRConfig().dtype == "auto" and set(DTYPES) == {"auto", "float32", "float64"}
    assert resolved_dtype("auto", FLOAT32_FROM_SAMPLES - 1) == "float64"
    assert resolved_dtype("auto", FLOAT32_FROM_SAMPLES) == "float32"
    assert resolved_dtype("float64", 10**7) == "float64"
    assert resolved_dtype("float32", 10) == "float32"
    assert KLRConfig().torch_dtype == torch.float64  # built outside a fit: float64
    with pytest.raises(ConfigError, match="dtype must be one of auto, float64, float32"):
        KLRConfig(dtype="float16")
