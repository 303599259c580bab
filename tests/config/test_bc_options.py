"""The behaviour-cloning baseline's options (cpmp.config.bc): defaults and validation."""

import dataclasses

import pytest

from cpmp.config import BCConfig, bc_options
from cpmp.errors import ConfigError


def test_defaults_and_valid_options():
    assert dataclasses.asdict(BCConfig()) == {
        "gamma": 4.0,
        "max_supports": 64,
        "l2": 1e-4,
        "class_weight": "balanced",
        "threshold": 0.5,
        "max_iter": 50,
        "feature_scaling": "global",
    }
    assert bc_options({"threshold": 0.7, "l2": 0}) == BCConfig(threshold=0.7, l2=0)
    with pytest.raises(dataclasses.FrozenInstanceError):
        BCConfig().gamma = 1.0  # type: ignore[misc]


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"gamma": 0.0}, "bc gamma must be > 0"),
        ({"gamma": float("inf")}, "bc option gamma must be finite"),
        ({"l2": -1e-3}, "bc l2 must be >= 0"),
        ({"threshold": 1.0}, r"bc threshold must be in \(0, 1\)"),
        ({"threshold": "high"}, "bc option threshold must be a number"),
        ({"max_supports": 0}, "bc max_supports must be an integer >= 1"),
        ({"max_supports": 2.5}, "bc max_supports must be an integer >= 1"),
        ({"max_iter": True}, "bc max_iter must be an integer >= 1"),
        ({"class_weight": "inverse"}, "bc class_weight must be one of balanced, none"),
        ({"feature_scaling": "log"}, "bc feature_scaling must be one of global, none"),
        ({"hold_time": 0.1}, "unknown option.*hold_time.*sequencer=bc.*valid options: gamma"),
    ],
)
def test_invalid_options_say_what_to_fix(options, message):
    with pytest.raises(ConfigError, match=message):
        bc_options(options)
