"""The slip task's feature-only scripted policy.

It runs the demonstrator's finite state machine (:func:`cpmp.worlds.slip.demonstrator.switch`)
on the features it is given and on its own active MPs (its memory), with the task's fixed
options; it never sees the context or the run's state. That it completes the task is the proof
that every switch of the slip world, the slip included, can be decided from the features.
"""

from __future__ import annotations

import numpy as np

from cpmp.errors import DataError
from cpmp.worlds.slip.demonstrator import initial_mps, switch
from cpmp.worlds.slip.world import FEATURE_NAMES, SlipTask


class ScriptedSlipPolicy:
    """A :class:`~cpmp.records.Policy` that reads only the features ``x (10,)``.

    Args:
        task: the task's fixed options (tolerances), not an episode.
    """

    def __init__(self, task: SlipTask) -> None:
        self.task = task
        self.active: dict[str, str] = {}

    def reset(self, t: float, x: np.ndarray) -> dict[str, str]:
        """The initial MPs from the first features ``x (10,)`` (``t`` [s] unused)."""
        self.active = initial_mps(self._check(x))
        return dict(self.active)

    def step(self, t: float, x: np.ndarray) -> dict[str, str]:
        """The switches at features ``x (10,)`` (``t`` [s] unused); the active MPs after them."""
        self.active = switch(self.task, self._check(x), self.active)
        return dict(self.active)

    @staticmethod
    def _check(x: np.ndarray) -> np.ndarray:
        """``x`` as a float vector of the world's length.

        Raises:
            DataError: ``x`` is not ``(10,)``.
        """
        arr = np.asarray(x, dtype=float)
        if arr.shape != (len(FEATURE_NAMES),):
            raise DataError(
                f"the slip policy reads features ({len(FEATURE_NAMES)},), got {arr.shape}"
            )
        return arr
