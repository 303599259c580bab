"""A scripted policy for the repetition world that reads only the features.

The repetition demonstrator (:func:`cpmp.worlds.repetition.demonstrator.script`) knows the
episode's pouring spot; every other guard of it already reads only features (the ladle's fill,
the soup remaining) and the MPs. :class:`RepetitionFeaturePolicy` decides the same switches
from the feature stream ``[ladle_x, ladle_y, ladle_fill, bowl_x, bowl_y, bowl_level,
remaining]`` alone, which proves the world fair: the spot the bowl is presented at is inferred
from the bowl's motion (:class:`~cpmp.worlds.attractor.AttractorGoal`: two steps of an
attractor give its goal), bounded by :data:`~cpmp.worlds.repetition.world.SPOT` ±
``goal_jitter``. How often the ``scoop -> pour`` cycle repeats is the ``remaining`` feature.
"""

from __future__ import annotations

import numpy as np

from cpmp.worlds.attractor import AttractorGoal
from cpmp.worlds.repetition.world import AMOUNT_EPS, SPOT, RepetitionTask


class RepetitionFeaturePolicy:
    """The repetition demonstrator's switches, decided from the features only (see module doc).

    * bowl ``present -> hold``: the bowl within ``tolerance`` of its inferred goal (the spot);
    * ladle ``scoop -> pour``: the ladle holds ``min(capacity, remaining)`` and the bowl was in
      ``hold``; ``pour -> scoop``/``rest``: the ladle empty, soup remaining or not;
    * bowl ``hold -> serve``: nothing remains and the ladle is empty.

    Guards on the other variable's MP read the MPs before the tick, as the demonstrator's do.
    It reads the task's options (``capacity``, ``tolerance``, ``goal_jitter``), never the
    episode. A policy object runs one episode at a time; :meth:`reset` starts a new one and
    forgets the last.

    Args:
        task: the repetition task's options.
    """

    def __init__(self, task: RepetitionTask) -> None:
        self.task = task
        jitter = task.goal_jitter
        self.spot = AttractorGoal([v - jitter for v in SPOT], [v + jitter for v in SPOT])
        """The bowl's ``present`` goal [m]."""
        self.active: dict[str, str] = {}

    def reset(self, t: float, x: np.ndarray) -> dict[str, str]:
        """Start an episode at time ``t`` [s] (unused) with features ``x (7,)``.

        Returns:
            The initial MPs: ``present`` and ``scoop`` (the same for every amount).
        """
        self.spot.clear()
        self.spot.observe((float(x[3]), float(x[4])))
        self.active = {"bowl": "present", "ladle": "scoop"}
        return dict(self.active)

    def step(self, t: float, x: np.ndarray) -> dict[str, str]:
        """One control tick at time ``t`` [s] (unused) with features ``x (7,)``.

        Returns:
            The active MPs after this tick's switches.
        """
        fill, remaining = float(x[2]), float(x[6])
        self.spot.observe((float(x[3]), float(x[4])))
        empty = fill <= AMOUNT_EPS
        done = remaining <= AMOUNT_EPS
        active = self.active
        new = dict(active)
        if active["ladle"] == "scoop":
            full = not done and fill >= min(self.task.capacity, remaining)
            if full and active["bowl"] == "hold":
                new["ladle"] = "pour"
        elif active["ladle"] == "pour" and empty:
            new["ladle"] = "rest" if done else "scoop"
        if active["bowl"] == "present" and self.spot.distance() < self.task.tolerance:
            new["bowl"] = "hold"
        elif active["bowl"] == "hold" and done and empty:
            new["bowl"] = "serve"
        if new["bowl"] != active["bowl"]:
            self.spot.restart()
        self.active = new
        return dict(new)
