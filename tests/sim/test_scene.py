"""The scene (cpmp.sim.scene): the MuJoCo model, boxes and the strategy regions."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from cpmp.errors import ConfigError
from cpmp.sim import (
    Box,
    correct_strategy,
)
from cpmp.sim.scene import build_model


def test_model_has_25_actuated_hinges(cfg):
    model = build_model(Box(0.2, 0.15, 0.1), cfg)
    hinge = int(mujoco.mjtJoint.mjJNT_HINGE)
    position = [
        i
        for i in range(model.nu)
        if model.actuator_trntype[i] == int(mujoco.mjtTrn.mjTRN_JOINT)
        and model.jnt_type[model.actuator_trnid[i, 0]] == hinge
    ]
    assert len(position) == 25
    assert sum(model.jnt_type == hinge) == 25
    assert np.all(model.jnt_limited[model.jnt_type == hinge])
    assert model.geom("box").size == pytest.approx([0.075, 0.1, 0.05])


def test_strategy_regions(cfg, boxes):
    for strategy, box in boxes.items():
        assert correct_strategy(box, cfg) == strategy
    assert correct_strategy(Box(0.2, 0.22, 0.1), cfg) == "left"
    assert correct_strategy(Box(0.2001, 0.22, 0.1), cfg) == "both"


def test_box_rejects_a_negative_size():
    with pytest.raises(ConfigError):
        Box(-0.1, 0.1, 0.1)
