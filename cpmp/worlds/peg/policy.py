"""The peg task's feature-only scripted policy: the proof that its switches are decidable.

:class:`FeaturePolicy` reads only the feature vectors it is given (and the task's fixed option
values: thresholds, tolerances), never the context or the run's state. It remembers only its
own MPs. The base (light or heavy) comes from the ``base_mass`` feature and the hole's depth
from the ``hole_depth`` feature; the switches are the demonstrator's
(:func:`cpmp.worlds.peg.demonstrator.switches`, whose guards read features only).
"""

from __future__ import annotations

import numpy as np

from cpmp.errors import DataError
from cpmp.worlds.peg.demonstrator import switches
from cpmp.worlds.peg.world import BASE_MASS, FEATURE_NAMES, HOLE_DEPTH, MASS_THRESHOLD, PegTask


class FeaturePolicy:
    """A :class:`~cpmp.records.Policy` for the peg task that sees the features only.

    Args:
        task: the task's options (thresholds and tolerances; no context).
    """

    def __init__(self, task: PegTask) -> None:
        self.task = task
        self.active: dict[str, str] = {}

    @staticmethod
    def _features(x: np.ndarray) -> np.ndarray:
        """``x`` as a float vector ``(13,)``.

        Raises:
            DataError: ``x`` has another shape.
        """
        x = np.asarray(x, dtype=float)
        if x.shape != (len(FEATURE_NAMES),):
            raise DataError(
                f"the peg policy reads {len(FEATURE_NAMES)} features, got shape {x.shape}"
            )
        return x

    def reset(self, t: float, x: np.ndarray) -> dict[str, str]:
        """The initial MPs from features ``x (13,)`` at ``t`` [s] (unused): a light base is held."""
        x = self._features(x)
        light = float(x[BASE_MASS]) < MASS_THRESHOLD
        self.active = {"holder": "hold" if light else "rest", "inserter": "align"}
        return dict(self.active)

    def step(self, t: float, x: np.ndarray) -> dict[str, str]:
        """The MPs after a tick at ``t`` [s] (unused) from its features ``x (13,)``."""
        x = self._features(x)
        light = float(x[BASE_MASS]) < MASS_THRESHOLD
        self.active = switches(self.task, x, self.active, light, float(x[HOLE_DEPTH]))
        return dict(self.active)
