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
