"""The simulated task's options (cpmp.config.task): validation and the mapping form."""

from __future__ import annotations

import pytest

from cpmp.config.task import TaskConfig, as_task_config
from cpmp.errors import ConfigError


def test_invalid_config_raises_config_error():
    with pytest.raises(ConfigError):
        TaskConfig(width_range=(0.3, 0.1))
    with pytest.raises(ConfigError):
        TaskConfig.from_dict({"control_dt": 0.003})
    with pytest.raises(ConfigError):
        TaskConfig.from_dict({"no_such_option": 1})
    with pytest.raises(ConfigError, match="compile_kinematics must be true or false"):
        TaskConfig.from_dict({"compile_kinematics": "yes"})


def test_as_task_config_takes_a_config_a_mapping_or_none():
    cfg = TaskConfig(max_time=5.0)
    assert as_task_config(cfg) is cfg
    assert as_task_config({"max_time": 5.0}) == cfg
    assert as_task_config(None) == TaskConfig()
    assert TaskConfig.from_dict(cfg.to_dict()) == cfg


@pytest.mark.parametrize(
    ("option", "value", "message"),
    [
        ("demo_speed", [0.0, 2.0], "demo_speed must be .* min > 0"),
        ("demo_speed", [2.0, 0.5], "demo_speed must be .* min <= max"),
        ("robot_speed", [1.0, 9.0], "robot_speed must be .* max <= 4"),
        ("demo_speed", 2.0, "demo_speed must be null or \\[min, max\\]"),
        ("demo_speed", [1.0, "fast"], "demo_speed must be null or \\[min, max\\]"),
        ("demo_pause", [-0.1, 1.0], "demo_pause must be .* min >= 0"),
        ("robot_pause", [1.0, 0.3], "robot_pause must be .* min <= max"),
        ("demo_pause_probability", 1.5, "demo_pause_probability must be a number in \\[0, 1\\]"),
        ("robot_pause_probability", True, "robot_pause_probability must be a number"),
    ],
)
def test_bad_pacing_options_name_the_option(option, value, message):
    with pytest.raises(ConfigError, match=message):
        TaskConfig.from_dict({option: value})


def test_pacing_is_off_by_default_and_kept_out_of_the_plain_dict():
    cfg = TaskConfig()
    assert not cfg.demo_pacing.varied and not cfg.robot_pacing.varied
    assert not any(k.startswith(("demo_", "robot_")) for k in cfg.to_dict())


def test_pacing_options_round_trip_through_the_dict():
    cfg = TaskConfig.from_dict({"demo_speed": [0.5, 2], "demo_pause": [0.3, 1.0]})
    assert cfg.demo_speed == (0.5, 2.0) and cfg.demo_pause == (0.3, 1.0)
    assert cfg.demo_pacing.varied and not cfg.robot_pacing.varied
    plain = cfg.to_dict()
    assert plain["demo_speed"] == [0.5, 2.0] and plain["demo_pause_probability"] == 1.0
    assert "robot_speed" not in plain
    assert TaskConfig.from_dict(plain) == cfg
