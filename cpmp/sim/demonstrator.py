"""Scripted demonstrator: per-variable finite-state machines with thresholds (paper Sec. IV-A).

The strategy follows from the box size (:func:`cpmp.sim.scene.correct_strategy`). Grasping hands
run, per variable (``H`` = each grasping hand, ``C`` = the carrying hand: the right hand when
bimanual, else the single hand):

* ``H_pos``: ``reach_top`` (single) / ``reach_edge`` (both) -> ``C_pos``: ``lift`` ->
  ``carry`` -> ``lower`` -> ``home``; bimanually the left hand switches ``reach_edge`` ->
  ``follow_right`` together with the right hand's ``lift`` and goes ``home`` with it;
* ``H_rot``: ``down`` -> ``home`` once the hand has risen ``rise_distance`` after releasing;
* ``H_fingers``: ``relax`` -> ``preshape`` (palm within ``preshape_distance`` of its grasp
  goal) -> ``grasp`` (palm touches the box, at the goal and oriented) -> ``release`` (box
  lowered and resting on the container floor) -> ``relax`` (hand within ``relax_distance`` of
  home).

Synchronisation points: lifting starts only when *every* grasping hand's fingers have closed;
returning home starts only when every grasping hand has released. An idle hand keeps ``idle``,
``idle``, ``relax`` throughout. Guards read the measured state, so the switches happen at
different times per variable.

Settling: a switch fires only after its guard has held continuously for ``cfg.settle_time``.
The sample on which a guard first holds is labelled with the *new* MP, so without settling the
state that triggers a switch (e.g. the box touching the container floor) never occurs in the
old MP's activation: its learned progress is undefined there and the learned sequencer cannot
reproduce the switch. With settling, every activation ends on a short plateau in the guard's
state, which is also where the sequencer's plateau rule (switch once the transition probability
stops improving) fires. It also debounces contact guards.

Pacing (task options ``demo_speed``, ``demo_pause``, ``demo_pause_probability``; off by
default): given a :class:`~cpmp.worlds.pacing.Pacer`, the demonstrator runs each activation at
its drawn speed and holds it once where drawn (:mod:`cpmp.worlds.pacing`), as a person
demonstrating goes faster or slower and hesitates; the guards are unchanged.
"""

from __future__ import annotations

import numpy as np

from cpmp.sim.control import rotation_angle
from cpmp.sim.features import goal_distance
from cpmp.sim.mps import IDLE
from cpmp.sim.scene import HANDS, correct_strategy
from cpmp.sim.simulation import Simulation
from cpmp.worlds.pacing import Pacer

REACH_MPS = ("reach_top", "reach_edge")


class ScriptedDemonstrator:
    """The finite-state machine, as a policy with ``reset(t, x)`` / ``step(t, x)``.

    It reads the full simulator state (not only ``x``), like a human demonstrator would.
    ``done`` becomes True when every variable has reached its final MP's goal.

    Args:
        sim: the simulation it demonstrates in.
        pacer: paces its MPs (sets the simulation's speeds every tick); ``None``: nominal.
    """

    def __init__(self, sim: Simulation, pacer: Pacer | None = None) -> None:
        self.sim = sim
        self.pacer = pacer
        self.cfg = sim.cfg
        self.strategy = correct_strategy(sim.box, sim.cfg)
        self.hands: tuple[str, ...] = HANDS if self.strategy == "both" else (self.strategy,)
        self.carrier = "right" if self.strategy == "both" else self.strategy
        self.done = False
        self.active: dict[str, str] = {}
        self._release_z: dict[str, float] = {}
        self._pending: dict[str, tuple[str, float]] = {}

    def reset(self, t: float, x: np.ndarray) -> dict[str, str]:
        """Initial MPs for the strategy."""
        active = {}
        for hand in HANDS:
            active[f"{hand}_pos"] = IDLE
            active[f"{hand}_rot"] = IDLE
            active[f"{hand}_fingers"] = "relax"
        reach = "reach_edge" if self.strategy == "both" else "reach_top"
        for hand in self.hands:
            active[f"{hand}_pos"] = reach
            active[f"{hand}_rot"] = "down"
        self.active = active
        self.done = False
        self._release_z = {}
        self._pending = {}
        self._pace(active)
        return dict(active)

    def _pace(self, active: dict[str, str]) -> None:
        """The pacer's speeds of ``active`` (the next tick's MPs) to the simulation."""
        if self.pacer is not None:
            self.sim.set_speeds(self.pacer.speeds(active, self.sim.goal_distances(active)))

    # guards --------------------------------------------------------------------------------
    def _pos_error(self, hand: str) -> float:
        goal = self.sim.goal(f"{hand}_pos", self.active[f"{hand}_pos"])
        return float(np.linalg.norm(self.sim.ee_pos()[HANDS.index(hand)] - goal))

    def _rot_done(self, hand: str) -> bool:
        goal = self.sim.goal(f"{hand}_rot", self.active[f"{hand}_rot"])
        angle = float(rotation_angle(goal, self.sim.ee_rot()[HANDS.index(hand)]))
        return angle < self.cfg.rot_tol

    def _fingers_done(self, hand: str) -> bool:
        goal = self.sim.goal(f"{hand}_fingers", self.active[f"{hand}_fingers"])
        diff = self.sim.finger_angles()[hand] - goal
        return goal_distance(float(diff @ diff), self.cfg.finger_sigma) < self.cfg.finger_tol

    def step(self, t: float, x: np.ndarray) -> dict[str, str]:
        """Evaluate every guard on the current state; return the (possibly new) MPs.

        A switch whose guard holds is applied once the guard has held (proposing the same MP)
        for ``cfg.settle_time``.
        """
        wanted = self._guards()
        new = dict(self.active)
        for variable, mp in wanted.items():
            if mp == self.active[variable]:
                self._pending.pop(variable, None)
                continue
            pending = self._pending.get(variable)
            if pending is None or pending[0] != mp:
                self._pending[variable] = pending = (mp, t)
            if t - pending[1] >= self.cfg.settle_time - 1e-9:
                new[variable] = mp
                del self._pending[variable]
        ee = self.sim.ee_pos()
        for hand in self.hands:
            if new[f"{hand}_pos"] == "home" and self.active[f"{hand}_pos"] != "home":
                self._release_z[hand] = float(ee[HANDS.index(hand)][2])
        self.done = self._finished(self.active)
        self.active = new
        self._pace(new)
        return dict(new)

    def _guards(self) -> dict[str, str]:
        """The MPs the finite-state machine's guards ask for in the current state."""
        cfg, a = self.cfg, self.active
        new = dict(a)
        for hand in self.hands:
            fingers, pos = f"{hand}_fingers", f"{hand}_pos"
            if a[fingers] == "relax" and a[pos] in REACH_MPS:
                if self._pos_error(hand) < cfg.preshape_distance:
                    new[fingers] = "preshape"
            elif a[fingers] == "preshape" and a[pos] in REACH_MPS:
                touching = self.sim.palm_touches_box(hand)
                if touching and self._pos_error(hand) < cfg.pos_tol and self._rot_done(hand):
                    new[fingers] = "grasp"

        carrier = f"{self.carrier}_pos"
        holding = all(a[f"{h}_fingers"] == "grasp" and self._fingers_done(h) for h in self.hands)
        released = all(a[f"{h}_fingers"] == "release" and self._fingers_done(h) for h in self.hands)
        if a[carrier] in REACH_MPS and holding:
            new[carrier] = "lift"
            if self.strategy == "both":
                new["left_pos"] = "follow_right"
        elif a[carrier] == "lift" and self._pos_error(self.carrier) < cfg.pos_tol:
            new[carrier] = "carry"
        elif a[carrier] == "carry" and self._pos_error(self.carrier) < cfg.pos_tol:
            new[carrier] = "lower"
        elif a[carrier] == "lower" and released:
            for hand in self.hands:
                new[f"{hand}_pos"] = "home"
        elif (
            a[carrier] == "lower"
            and holding
            and self._pos_error(self.carrier) < cfg.pos_tol
            and self.sim.box_supported()
        ):
            for hand in self.hands:
                new[f"{hand}_fingers"] = "release"

        for hand in self.hands:
            if a[f"{hand}_pos"] != "home":
                continue
            ee = self.sim.ee_pos()[HANDS.index(hand)]
            if a[f"{hand}_rot"] == "down" and ee[2] > self._release_z[hand] + cfg.rise_distance:
                new[f"{hand}_rot"] = "home"
            if a[f"{hand}_fingers"] == "release" and self._pos_error(hand) < cfg.relax_distance:
                new[f"{hand}_fingers"] = "relax"
        return new

    def _finished(self, a: dict[str, str]) -> bool:
        """All variables in their final MP and at its goal."""
        # every hand's MPs first: the goal checks are read only once all MPs are final
        for hand in HANDS:
            final = ("home", "home") if hand in self.hands else (IDLE, IDLE)
            if (a[f"{hand}_pos"], a[f"{hand}_rot"], a[f"{hand}_fingers"]) != (*final, "relax"):
                return False
        for hand in HANDS:
            if self._pos_error(hand) > self.cfg.pos_tol or not self._rot_done(hand):
                return False
            if not self._fingers_done(hand):
                return False
        return True
