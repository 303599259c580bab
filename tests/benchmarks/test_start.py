"""The start-decision analysis behind docs/results.md's start table (scripts/bench_start.py)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from cpmp.benchmarks.start import SEQUENCER_RULES, markdown, wrong_starts
from cpmp.sim import Box, TaskConfig, record_demonstration
from cpmp.sim.scene import correct_strategy
from cpmp.sim.simulation import Simulation

torch.set_num_threads(1)
BOXES = [Box(0.25, 0.15, 0.10), Box(0.15, 0.12, 0.10), Box(0.15, 0.20, 0.10)]


@pytest.fixture(scope="module")
def task() -> TaskConfig:
    return TaskConfig()


@pytest.fixture(scope="module")
def train(task: TaskConfig) -> list:
    return [record_demonstration(b, task, name=f"demo_{i}") for i, b in enumerate(BOXES)]


def first_features(task: TaskConfig, boxes: list[Box]) -> np.ndarray:
    out = []
    for box in boxes:
        sim = Simulation(task, box)
        sim.reset()
        out.append(sim.features())
    return np.stack(out)


def test_training_boxes_start_right(task: TaskConfig, train: list) -> None:
    """Scored on the training boxes themselves, cpmp's default start and every classifier that
    interpolates its training data choose each box's own strategy."""
    correct = [correct_strategy(b, task) for b in BOXES]
    counts = wrong_starts(train, first_features(task, BOXES), BOXES, correct, seed=0)
    assert set(SEQUENCER_RULES) <= set(counts)
    for rule in ("cpmp defaults", "nearest training box, scaled features"):
        assert counts[rule] == 0, rule
    for rule in [r for r in counts if r.startswith("oracle size")]:
        assert counts[rule] == 0, rule


def test_far_boxes_follow_their_nearest_training_box(task: TaskConfig, train: list) -> None:
    """Boxes near one training box but across a region boundary are wrong for the oracle nearest
    neighbour: the count is the number of such boxes, not a constant."""
    near_both_but_right = Box(0.19, 0.15, 0.10)  # nearest training box: the wide 'both' one
    near_right = Box(0.14, 0.12, 0.10)
    boxes = [near_both_but_right, near_right]
    correct = [correct_strategy(b, task) for b in boxes]
    assert correct == ["right", "right"]
    counts = wrong_starts(
        train, first_features(task, boxes), boxes, correct, seed=0, size_scale=(0.2, 0.12)
    )
    assert counts["oracle size: nearest training box"] == 1


def test_markdown_has_a_row_per_rule() -> None:
    result = {"mean_per_20": {3: {"a": 1.0, "b": 2.5}, 6: {"a": 0.5, "b": 2.0}}}
    text = markdown(result)
    assert "| a | 1.0 | 0.5 |" in text and "| b | 2.5 | 2.0 |" in text
