"""The slip task's scripted demonstrator: its switching guards and labelled demonstrations.

The task is :mod:`cpmp.worlds.slip.world`. The demonstrator is a finite state machine whose
guards read only the features of the tick and the MPs active before it (its own memory), with
the task's fixed options (tolerances and the fixed geometry: grasp and carry heights, the
drawer's ``x``); it never reads the hidden context. So the same machine is the feature-only
scripted policy (:mod:`cpmp.worlds.slip.policy`). It switches at the tick a guard holds; a guard
on another variable's MP reads the MPs before the tick, so such a switch comes one tick after the
one it waits for:

* gripper ``open -> close``: the arm (``reach`` or ``lower``) is within ``tolerance`` of the
  object (``object_x``, ``GRASP_Z``) and the gripper is open (``grip >= OPEN_READY``);
* arm ``reach``/``lower`` -> ``lift``: the fingers hold the object (``contact``) while closing;
* arm ``lift -> lower`` and gripper ``close -> open`` (the slip, mid-``lift``): ``contact``
  dropped while the arm lifts;
* arm ``lift -> place``: holding at the carry height (``arm_z >= CARRY_Z - tolerance``) with
  the drawer open (``drawer_ext >= OPEN_EXT - tolerance``): the arm waits there while the
  drawer still opens;
* gripper ``close -> release``: the arm (``place``) within ``tolerance`` of the place point,
  ``PLACE_CLEARANCE`` above ``shelf_z`` (the end condition read from the shelf feature);
* arm ``place -> retreat``: the gripper released and open again;
* drawer ``pull_open -> hold_open``: ``drawer_ext >= OPEN_EXT - tolerance``; ``hold_open ->
  push_shut``: the drawer's scale reads the object and the arm is out of the drawer's mouth
  (so the drawer holds open through every try).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from cpmp.data import Demonstration
from cpmp.worlds.common import positive_count, record_script
from cpmp.worlds.slip.world import (
    CARRY_Z,
    DRAWER_X,
    FEATURE_NAMES,
    GRASP_Z,
    LOAD_MIN,
    MOUTH_HALF_X,
    OPEN_EXT,
    OPEN_READY,
    PLACE_CLEARANCE,
    STRATEGIES,
    VARIABLES,
    SlipContext,
    SlipTask,
)


def switch(task: SlipTask, x: np.ndarray, active: Mapping[str, str]) -> dict[str, str]:
    """The demonstrator's switches at features ``x``.

    Args:
        task: the task's options (``tolerance``).
        x: ``(10,)`` features of this tick, in :data:`FEATURE_NAMES` order.
        active: variable -> MP before the tick.

    Returns:
        Variable -> MP after the tick.
    """
    arm_x, arm_z, grip, contact = float(x[0]), float(x[1]), float(x[2]), x[3] > 0.5
    object_x, ext, shelf_z, load = float(x[4]), float(x[5]), float(x[6]), float(x[7])
    tol = task.tolerance
    arm, gripper, drawer = active["arm"], active["gripper"], active["drawer"]
    drawer_open = ext >= OPEN_EXT - tol
    new = dict(active)
    # the arm
    if arm in ("reach", "lower") and gripper == "close" and contact:
        new["arm"] = "lift"
    elif arm == "lift":
        if not contact:
            new["arm"] = "lower"
        elif arm_z >= CARRY_Z - tol and drawer_open:
            new["arm"] = "place"
    elif arm == "place" and gripper == "release" and grip >= OPEN_READY:
        new["arm"] = "retreat"
    # the gripper
    if gripper == "open" and arm in ("reach", "lower") and grip >= OPEN_READY:
        if math.hypot(arm_x - object_x, arm_z - GRASP_Z) < tol:
            new["gripper"] = "close"
    elif gripper == "close":
        if arm == "lift" and not contact:
            new["gripper"] = "open"
        elif arm == "place" and contact:
            if math.hypot(arm_x - DRAWER_X, arm_z - shelf_z - PLACE_CLEARANCE) < tol:
                new["gripper"] = "release"
    # the drawer
    if drawer == "pull_open" and drawer_open:
        new["drawer"] = "hold_open"
    elif drawer == "hold_open" and load >= LOAD_MIN and arm_x < DRAWER_X - MOUTH_HALF_X - tol:
        new["drawer"] = "push_shut"
    return new


def initial_mps(x: np.ndarray) -> dict[str, str]:
    """The initial MPs from the first features ``x (10,)``: the drawer's from ``drawer_ext``."""
    drawer = "hold_open" if float(x[5]) >= OPEN_EXT / 2 else "pull_open"
    return {"arm": "reach", "gripper": "open", "drawer": drawer}


def demonstrate(task: SlipTask, context: SlipContext, name: str | None = None) -> Demonstration:
    """The scripted demonstrator's labelled demonstration of ``context``.

    Args:
        task: the task (its ``dt`` is the sample period).
        context: the episode.
        name: the demonstration's name.

    Returns:
        Samples every ``dt`` from ``t = 0`` until the goal state (or ``max_time``), with
        metadata ``task``, ``strategy``, ``n_slips``, ``shelf_z``, ``drawer_open`` and
        ``reached_goal``.
    """
    run = record_script(
        task,
        context,
        lambda state: task.features(state, context),
        lambda x, active: switch(task, x, active),
        VARIABLES,
    )
    metadata = {
        "task": "slip",
        "strategy": context.strategy,
        "n_slips": context.n_slips,
        "shelf_z": context.shelf_z,
        "drawer_open": context.drawer_open,
        "reached_goal": task.at_goal(run.state, context),
    }
    return run.log.to_demonstration(FEATURE_NAMES, name, metadata)


def slip_cycle(i: int, max_slips: int) -> int:
    """The slip count of demonstration ``i``: ``(i + 1 + i // 4) % (max_slips + 1)``.

    The first ``max_slips + 1`` demonstrations hold every count (1, 2, 0 by default: even three
    demonstrations show a slip and the retry loop), and the shift by ``i // 4`` makes each
    strategy (cycling over four) meet every count in turn.
    """
    return (i + 1 + i // len(STRATEGIES)) % (max_slips + 1)


def make_contexts(
    task: SlipTask, n: int, seed: int, *, cycle_slips: bool = False
) -> list[SlipContext]:
    """``n`` contexts cycling :data:`STRATEGIES` (item ``i`` has ``STRATEGIES[i % 4]``).

    Args:
        task: the task.
        n: how many.
        seed: seeds the one generator all are drawn from, in order.
        cycle_slips: slip counts by :func:`slip_cycle` (the demonstrations' way) instead of
            drawn uniformly.

    Returns:
        The contexts.

    Raises:
        ConfigError: ``n`` is not a positive integer.
    """
    positive_count(n, "n")
    rng = np.random.default_rng(seed)
    return [
        task.sample_context(
            rng,
            STRATEGIES[i % len(STRATEGIES)],
            slip_cycle(i, task.max_slips) if cycle_slips else None,
        )
        for i in range(n)
    ]


def make_demonstrations(task: SlipTask, n: int, seed: int) -> list[Demonstration]:
    """``n`` demonstrations named ``demo_<i>``: strategies and slip counts cycled, geometry drawn.

    Raises:
        ConfigError: ``n`` is not a positive integer.
    """
    contexts = make_contexts(task, n, seed, cycle_slips=True)
    return [demonstrate(task, c, name=f"demo_{i}") for i, c in enumerate(contexts)]
