"""What every job's report shares: JSON files, seed statistics and the paper's Table I.

Light on purpose (numpy and the standard library): the main job's report
(:mod:`~cpmp.experiment.report`), the comparison's, the benchmarks' and the sweep aggregate
all write through it.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from cpmp.io import atomic_write_text, to_builtin

PAPER_TABLE_I: dict[str, dict[str, float]] = {
    "3": {"W": 3, "I": 4, "C": 13, "distance_mean": 0.13, "distance_std": 0.08},
    "6": {"W": 3, "I": 2, "C": 15, "distance_mean": 0.07, "distance_std": 0.04},
    "9": {"W": 2, "I": 2, "C": 16, "distance_mean": 0.06, "distance_std": 0.03},
}
"""The paper's Table I (20 random boxes per D)."""


jsonable = to_builtin
"""Recursively convert numpy values and tuples to JSON types (NaN -> None)."""


def write_json(path: str | Path, obj: object) -> Path:
    """Write ``obj`` as indented JSON, atomically; returns the path."""
    atomic_write_text(path, json.dumps(jsonable(obj), indent=2) + "\n")
    return Path(path)


def mean_std(values: list[float | None]) -> tuple[float | None, float | None]:
    """Mean and (population) std of the non-missing values (``None, None`` if there are none)."""
    xs = [v for v in values if v is not None]
    if not xs:
        return None, None
    return float(np.mean(xs)), float(np.std(xs))
