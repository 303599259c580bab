"""A scripted policy for the relay world that reads only the features.

The relay demonstrator (:func:`cpmp.worlds.relay.demonstrator.script`) knows the episode: the
meeting point, the shelf, the bin, the carrier's home. :class:`RelayFeaturePolicy` decides the
same switches from the feature stream ``[carrier_x, carrier_y, receiver_x, receiver_y,
grip_force, context]`` alone, which proves the world fair:

* the strategy (``carry``/``present`` first, ``withdraw``/``stow`` later) is the context
  feature: ``meet`` while ``context / CONTEXT_SCALE < 0.5``;
* the carrier's home is where it stands at ``t = 0``, and the present point is that home plus
  :data:`~cpmp.worlds.relay.world.PRESENT_OFFSET`;
* the meeting point and the destination (shelf or bin) are inferred from the motion of the
  carrier and the receiver (:class:`~cpmp.worlds.attractor.AttractorGoal`: two steps of
  an attractor give its goal, whatever its speed factor, and a tick held still is skipped),
  bounded by their nominal positions ± ``goal_jitter``;
* the receiver's ``approach`` goal is the object, which rides on the carrier until the grip: the
  receiver-carrier distance is a feature difference;
* the grip is the force feature (``close -> hold`` at ``contact_force``).

So it also runs the paced relay (:mod:`cpmp.worlds.relay.varied`): a speed factor changes the
step ratio, not the inferred goal, and a hold (features standing still mid-MP) is not taken for
an arrival, since arrival is judged by the distance to the inferred goal, not by stillness.
"""

from __future__ import annotations

import math

import numpy as np

from cpmp.worlds.attractor import AttractorGoal
from cpmp.worlds.relay.world import (
    BIN,
    CONTEXT_SCALE,
    MEETING_POINT,
    PRESENT_OFFSET,
    SHELF,
    RelayTask,
)

_CARRIER_OUT = ("carry", "present")


def _box(nominal: tuple[float, float], jitter: float) -> AttractorGoal:
    """A goal estimator bounded by ``nominal ± jitter`` per axis [m]."""
    return AttractorGoal([v - jitter for v in nominal], [v + jitter for v in nominal])


class RelayFeaturePolicy:
    """The relay demonstrator's switches, decided from the features only (see module doc).

    Guards on another variable's MP read the MPs before the tick, as the demonstrator's do, so
    such a switch comes one tick after the one it waits for. It reads the task's options
    (``tolerance``, ``contact_force``, ``goal_jitter``) and the world's nominal positions,
    never the episode. A policy object runs one episode at a time; :meth:`reset` starts a new
    one and forgets the last.

    Args:
        task: the relay task's options.
    """

    def __init__(self, task: RelayTask) -> None:
        self.task = task
        self.meeting = _box(MEETING_POINT, task.goal_jitter)
        """The carrier's ``carry`` goal."""
        self.delivery = {
            "meet": _box(SHELF, task.goal_jitter),
            "fetch": _box(BIN, task.goal_jitter),
        }
        """The receiver's ``withdraw`` and ``stow`` goals, by strategy."""
        self.destination = self.delivery["meet"]
        """The episode's delivery goal (the strategy's)."""
        self.home = (0.0, 0.0)
        """The carrier's home [m]: where it stood at ``t = 0``."""
        self.present = (0.0, 0.0)
        """The carrier's ``present`` goal [m]: its home plus the present offset."""
        self.meet = True
        """The strategy: ``meet`` (else ``fetch``)."""
        self.active: dict[str, str] = {}

    def reset(self, t: float, x: np.ndarray) -> dict[str, str]:
        """Start an episode at time ``t`` [s] (unused) with features ``x (6,)``.

        Returns:
            The initial MPs: ``carry`` (meet) or ``present`` (fetch), ``open``, ``approach``.
        """
        self.home = (float(x[0]), float(x[1]))
        self.present = (self.home[0] + PRESENT_OFFSET[0], self.home[1] + PRESENT_OFFSET[1])
        self.meet = bool(float(x[5]) / CONTEXT_SCALE < 0.5)
        self.destination = self.delivery["meet" if self.meet else "fetch"]
        for goal in (self.meeting, self.destination):
            goal.clear()
        self.meeting.observe(self.home)
        self.destination.observe((float(x[2]), float(x[3])))
        self.active = {
            "carrier": "carry" if self.meet else "present",
            "gripper": "open",
            "receiver": "approach",
        }
        return dict(self.active)

    def _carrier_arrived(self, carrier: tuple[float, float]) -> bool:
        """Whether the carrier is within ``tolerance`` of its ``carry``/``present`` goal."""
        if self.active["carrier"] == "carry":
            distance = self.meeting.distance()
        else:
            distance = math.dist(carrier, self.present)
        return distance < self.task.tolerance

    def step(self, t: float, x: np.ndarray) -> dict[str, str]:
        """One control tick at time ``t`` [s] (unused) with features ``x (6,)``.

        Returns:
            The active MPs after this tick's switches.
        """
        carrier = (float(x[0]), float(x[1]))
        receiver = (float(x[2]), float(x[3]))
        force = float(x[4])
        self.meeting.observe(carrier)
        self.destination.observe(receiver)
        tol = self.task.tolerance
        active = self.active
        new = dict(active)
        if active["gripper"] == "open" and active["carrier"] in _CARRIER_OUT:
            if math.dist(receiver, carrier) < tol and self._carrier_arrived(carrier):
                new["gripper"] = "close"
        if active["gripper"] == "close" and force >= self.task.contact_force:
            new["gripper"] = "hold"
        if active["carrier"] == "retreat" and math.dist(carrier, self.home) < tol:
            new["carrier"] = "rest"
        if active["gripper"] == "hold":
            if active["carrier"] in _CARRIER_OUT:
                new["carrier"] = "retreat"
            if active["receiver"] == "approach":
                new["receiver"] = "withdraw" if self.meet else "stow"
            if active["receiver"] != "approach" and self.destination.distance() < tol:
                new["gripper"] = "release"
        if new["carrier"] != active["carrier"]:
            self.meeting.restart()
        if new["receiver"] != active["receiver"]:
            self.destination.restart()
        self.active = new
        return dict(new)
