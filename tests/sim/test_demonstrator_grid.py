"""The demonstrator must succeed on every box in the configured ranges (slow: ~35 s)."""

from __future__ import annotations

import numpy as np
import pytest

from cpmp.sim import Box, TaskConfig, correct_strategy, record_demonstration, sample_box


@pytest.mark.slow
def test_demonstrator_succeeds_on_grid_and_random_boxes():
    cfg = TaskConfig()
    grid = [
        Box(w, d, cfg.box_height)
        for w in np.linspace(*cfg.width_range, 5)
        for d in np.linspace(*cfg.depth_range, 4)
    ]
    rng = np.random.default_rng(2024)
    boxes = grid + [sample_box(rng, cfg) for _ in range(10)]
    failures = []
    for box in boxes:
        meta = record_demonstration(box, cfg).metadata
        if not meta["success"] or meta["strategy"] != correct_strategy(box, cfg):
            failures.append((box, meta))
    assert not failures
