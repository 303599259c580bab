"""The peg task's scripted demonstrator: its switches and its labelled demonstrations.

The task is :mod:`cpmp.worlds.peg.world`. The demonstrator switches at the tick a guard holds
(no settle time); every guard reads this tick's features, and the demonstrator knows the
context's base (light or heavy) and hole depth, which are features too
(:mod:`cpmp.worlds.peg.policy` reads them from there):

* inserter ``align -> insert``: the hand within ``tolerance`` of the align pose (the hole
  estimate, ``align_clearance`` above the mouth) per axis, and the base heavy or the clamp
  force at least ``hold_force``;
* ``insert -> retract``: the insertion force at least ``force_threshold`` (a jam: the only
  feature that shows it); ``insert -> release``: the peg's depth within ``tolerance`` of the
  insertion depth (the hole's depth, half of it for a deep hole);
* ``retract -> align``: back within ``tolerance`` of the align height;
* ``release -> push`` (deep) / ``release -> home`` (shallow): the gripper open (``open_level``)
  and the hand within ``tolerance`` of ``LIFT`` above the peg;
* ``push -> home`` and holder ``hold -> retreat``: the peg home (its depth within ``tolerance``
  of the hole's).
"""

from __future__ import annotations

import numpy as np

from cpmp.data import Demonstration
from cpmp.worlds.common import record_script
from cpmp.worlds.peg.world import (
    CLAMP,
    DEEP_THRESHOLD,
    FEATURE_NAMES,
    FORCE,
    GRIP,
    HOLE_X,
    INSERTER_X,
    INSERTER_Z,
    LIFT,
    MOUTH_Z,
    PEG_DEPTH,
    VARIABLES,
    PegContext,
    PegTask,
)


def switches(
    task: PegTask, x: np.ndarray, active: dict[str, str], light: bool, depth: float
) -> dict[str, str]:
    """The demonstrator's MPs after a tick.

    Args:
        task: the task's options (its guards' thresholds).
        x: (13,) this tick's features, in :data:`~cpmp.worlds.peg.world.FEATURE_NAMES` order.
        active: variable -> MP before the tick.
        light: whether the base is light.
        depth: the hole's depth [m].

    Returns:
        Variable -> MP after the tick.
    """
    tol = task.tolerance
    deep = depth > DEEP_THRESHOLD
    ins_z, peg_depth = float(x[INSERTER_Z]), float(x[PEG_DEPTH])
    align_z = MOUTH_Z + task.align_clearance
    home = peg_depth >= depth - tol
    new = dict(active)
    mp = active["inserter"]
    if mp == "align":
        aligned = abs(x[INSERTER_X] - x[HOLE_X]) < tol and abs(ins_z - align_z) < tol
        if aligned and (not light or x[CLAMP] >= task.hold_force):
            new["inserter"] = "insert"
    elif mp == "insert":
        if x[FORCE] >= task.force_threshold:
            new["inserter"] = "retract"
        elif peg_depth >= (depth / 2 if deep else depth) - tol:
            new["inserter"] = "release"
    elif mp == "retract":
        if abs(ins_z - align_z) < tol:
            new["inserter"] = "align"
    elif mp == "release":
        lifted = abs(ins_z - (MOUTH_Z - peg_depth + LIFT)) < tol
        if x[GRIP] >= task.open_level and lifted:
            new["inserter"] = "push" if deep else "home"
    elif mp == "push" and home:
        new["inserter"] = "home"
    if active["holder"] == "hold" and home:
        new["holder"] = "retreat"
    return new


def demonstrate(task: PegTask, context: PegContext, name: str | None = None) -> Demonstration:
    """The scripted demonstrator's labelled demonstration of ``context``.

    Args:
        task: the task (its ``dt`` is the sample period).
        context: the context.
        name: the demonstration's name.

    Returns:
        Samples every ``dt`` from ``t = 0`` until the goal state (or ``max_time``), with
        metadata ``task``, ``strategy``, ``n_jams`` and ``reached_goal``.
    """
    light, depth = context.light, context.hole_depth
    run = record_script(
        task,
        context,
        lambda s: task.features(s, context),
        lambda x, active: switches(task, x, active, light, depth),
        VARIABLES,
    )
    metadata = {
        "task": "peg",
        "strategy": context.strategy,
        "n_jams": context.n_jams,
        "reached_goal": task.at_goal(run.state, context),
    }
    return run.log.to_demonstration(FEATURE_NAMES, name, metadata)
