"""Recording sets of scripted demonstrations into the project's HDF5 format."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from cpmp.data import Demonstration, save_demonstrations
from cpmp.errors import ConfigError
from cpmp.sim.config import TaskConfig
from cpmp.sim.runner import record_demonstrations
from cpmp.sim.scene import STRATEGIES, Box, correct_strategy, sample_box

MAX_DRAWS_PER_BOX = 10_000
"""Rejection-sampling budget per box when balancing strategies."""


def sample_boxes(rng: np.random.Generator, cfg: TaskConfig, n: int, balanced: bool) -> list[Box]:
    """``n`` boxes from the configured ranges; with ``balanced``, strategies cycle round-robin
    over :data:`STRATEGIES` (rejection sampling, deterministic given ``rng``)."""
    if n < 0:
        raise ConfigError(f"n_demos must be >= 0, got {n}")
    boxes = []
    for i in range(n):
        want = STRATEGIES[i % len(STRATEGIES)] if balanced else None
        for _ in range(MAX_DRAWS_PER_BOX):
            box = sample_box(rng, cfg)
            if want is None or correct_strategy(box, cfg) == want:
                break
        else:
            raise ConfigError(
                f"no box with strategy {want!r} in width {cfg.width_range} x depth "
                f"{cfg.depth_range}; widen the ranges or set balanced=false"
            )
        boxes.append(box)
    return boxes


def collect_demonstrations(
    cfg: TaskConfig, n_demos: int, seed: int, path: str | os.PathLike[str], balanced: bool = True
) -> tuple[Path, list[Demonstration]]:
    """Record ``n_demos`` scripted demonstrations with boxes drawn from ``seed`` and save them.

    Demos are named ``demo_<i>_<strategy>``; all boxes run together
    (:func:`~cpmp.sim.runner.record_demonstrations`). Returns the written path and the
    demonstrations.
    """
    rng = np.random.default_rng(seed)
    boxes = sample_boxes(rng, cfg, n_demos, balanced)
    names = [f"demo_{i:03d}_{correct_strategy(box, cfg)}" for i, box in enumerate(boxes)]
    demos = record_demonstrations(boxes, cfg, names=names)
    failed = [d.name for d in demos if not (d.metadata or {}).get("success")]
    if failed:
        raise RuntimeError(f"the scripted demonstrator failed on {failed}; this is a bug")
    out = Path(path)
    save_demonstrations(out, demos)
    return out, demos
