"""The goal-nearest baseline's options (cpmp.config.goal_nearest): defaults and validation."""

import dataclasses

import pytest

from cpmp.config import GoalNearestConfig, goal_nearest_options
from cpmp.errors import ConfigError


def test_defaults_and_valid_options():
    assert dataclasses.asdict(GoalNearestConfig()) == {
        "speed_threshold": 0.02,
        "hold_time": 0.1,
        "motion_share": 0.1,
        "feature_scaling": "global",
    }
    assert goal_nearest_options({"hold_time": 0}) == GoalNearestConfig(hold_time=0)


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"speed_threshold": 0.0}, "speed_threshold must be > 0"),
        ({"hold_time": -0.1}, "hold_time must be >= 0 s"),
        ({"motion_share": 1.5}, r"motion_share must be in \[0, 1\]"),
        ({"motion_share": float("nan")}, "motion_share must be finite"),
        ({"hold_time": True}, "hold_time must be a number"),
        ({"feature_scaling": "log"}, "feature_scaling must be one of global, none"),
        ({"patience": 0.05}, "unknown option.*patience.*valid options: speed_threshold"),
    ],
)
def test_invalid_options_say_what_to_fix(options, message):
    with pytest.raises(ConfigError, match=message):
        goal_nearest_options(options)
