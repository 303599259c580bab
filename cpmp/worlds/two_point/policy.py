"""A scripted policy for the two-point world that reads only the features.

The two-point demonstrator (:meth:`cpmp.worlds.two_point.task.SyntheticTask._demo_switch`) knows
the episode's goals; :class:`TwoPointFeaturePolicy` decides the same switches from the feature
stream alone, which proves the world fair: what a learned sequencer sees suffices.

A goal is not a feature, but the attractor's motion gives it away
(:class:`~cpmp.worlds.attractor.AttractorGoal`).
"""

from __future__ import annotations

import numpy as np

from cpmp.worlds.attractor import AttractorGoal
from cpmp.worlds.two_point.task import VARIABLES, SyntheticTask


class TwoPointFeaturePolicy:
    """The two-point demonstrator's switches, decided from the features ``[p_a, p_b, c]`` only.

    * initial MPs: ``a_go`` and, from the context feature, ``b_go`` (``c >= 0.5``, parallel) or
      ``b_wait``;
    * a point is *near* its goal when its inferred goal (:class:`AttractorGoal`, bounded by
      ``1 ± goal_jitter``) is within ``tolerance``; with that, the demonstrator's guards:
      ``a_go -> a_wait`` (``b`` waiting, ``a`` near), ``b_wait -> b_go`` (``a`` was waiting),
      both ``*_back`` (``b`` going and near, ``a`` out and near).

    It reads the task's options (``tolerance``, ``goal_jitter``), never the episode.
    A policy object runs one episode at a time; :meth:`reset` starts a new one.

    Args:
        task: the two-point task's options.
    """

    def __init__(self, task: SyntheticTask) -> None:
        self.task = task
        low, high = [1.0 - task.goal_jitter], [1.0 + task.goal_jitter]
        self.goal = {"a": AttractorGoal(low, high), "b": AttractorGoal(low, high)}
        """Per point: its "out" goal (``a_go``/``a_wait``, ``b_go``) [positions' unit]."""
        self.active: dict[str, str] = {}

    def reset(self, t: float, x: np.ndarray) -> dict[str, str]:
        """Start an episode at time ``t`` [s] (unused) with features ``x (3,)``.

        Returns:
            The initial MPs: ``a_go``, and ``b_go`` or ``b_wait`` as the context says.
        """
        for i, v in enumerate(VARIABLES):
            self.goal[v].clear()
            self.goal[v].observe((float(x[i]),))
        parallel = float(x[2]) >= 0.5
        self.active = {"a": "a_go", "b": "b_go" if parallel else "b_wait"}
        return dict(self.active)

    def _near(self, v: str) -> bool:
        """Whether point ``v`` is within ``tolerance`` of its "out" goal."""
        return self.goal[v].distance() < self.task.tolerance

    def step(self, t: float, x: np.ndarray) -> dict[str, str]:
        """One control tick at time ``t`` [s] (unused) with features ``x (3,)``.

        Returns:
            The active MPs after this tick's switches.
        """
        for i, v in enumerate(VARIABLES):
            self.goal[v].observe((float(x[i]),))
        a, b = self.active["a"], self.active["b"]
        new = dict(self.active)
        if a == "a_go" and b == "b_wait" and self._near("a"):
            new["a"] = "a_wait"  # the same goal: a's estimate carries on
        if b == "b_wait" and a == "a_wait":
            new["b"] = "b_go"
        # b's "out" goal is known only under b_go (b_wait returns it to 0)
        if b == "b_go" and a in ("a_go", "a_wait") and self._near("b") and self._near("a"):
            new["a"], new["b"] = "a_back", "b_back"
        if new["a"] != a and new["a"] == "a_back":
            self.goal["a"].restart()
        if new["b"] != b:
            self.goal["b"].restart()
        self.active = new
        return dict(new)
