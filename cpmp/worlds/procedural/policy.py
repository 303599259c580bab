"""The feature-only scripted policy of a procedural task: the proof that the task is fair.

It reads only the feature vectors it is given and remembers only its own active MPs; it knows
the task's spec (nominal goals, tolerance, guards) but never a context's hidden draws (jittered
goals, failure count) or the run's state. The initial MPs come from the ``context`` feature,
every switch from the demonstrator's guards (:class:`~cpmp.worlds.procedural.demonstrator.
Switches`), which read only the features. So wherever it completes every episode, every
demonstrated switch is decidable from the features.
"""

from __future__ import annotations

import numpy as np

from cpmp.worlds.procedural.demonstrator import Switches
from cpmp.worlds.procedural.generator import CONTEXT_SPLIT, TaskSpec


class FeaturePolicy:
    """A :class:`~cpmp.records.Policy` over the features of one procedural task.

    Args:
        spec: the task.
    """

    def __init__(self, spec: TaskSpec) -> None:
        self.spec = spec
        self._switch = Switches(spec)
        self._context = spec.feature_names.index("context")
        self.active: dict[str, str] = {}

    def reset(self, t: float, x: np.ndarray) -> dict[str, str]:
        """The initial MPs the ``context`` feature of ``x (d,)`` decides (``t`` [s] unused)."""
        side = "a" if float(np.asarray(x)[self._context]) < CONTEXT_SPLIT else "b"
        self.active = self.spec.initial_mps(side)
        return dict(self.active)

    def step(self, t: float, x: np.ndarray) -> dict[str, str]:
        """The active MPs after the switches the guards take at features ``x (d,)``."""
        self.active = self._switch(np.asarray(x, float), self.active)
        return dict(self.active)
