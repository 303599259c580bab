"""Fixtures of the simulator's tests and of the benchmarks that run it: the task config, one box
and one scripted demonstration per strategy (imported by their conftest.py files)."""

from __future__ import annotations

import pytest
import torch

from cpmp.sim import Box, TaskConfig, record_demonstration

torch.set_num_threads(1)

BOXES = {
    "both": Box(0.25, 0.15, 0.10),
    "right": Box(0.15, 0.12, 0.10),
    "left": Box(0.15, 0.20, 0.10),
}


@pytest.fixture(scope="session")
def cfg() -> TaskConfig:
    return TaskConfig()


@pytest.fixture(scope="session")
def boxes() -> dict[str, Box]:
    """One box per strategy, keyed by strategy."""
    return dict(BOXES)


@pytest.fixture(scope="session")
def demos(cfg: TaskConfig) -> dict:
    """One scripted demonstration per strategy."""
    return {s: record_demonstration(box, cfg, name=f"demo_{s}") for s, box in BOXES.items()}
