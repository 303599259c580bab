"""The relay task's scripted demonstrator: its labelled demonstrations and closed-loop policy.

The task is :mod:`cpmp.worlds.relay.world`; the same finite state machine records the
demonstrations and runs as a closed-loop policy (:class:`ScriptedPolicy`).

The scripted demonstrator (a finite state machine) switches as soon as a guard holds, with no
settle time:

* gripper ``open -> close``: carrier within ``tolerance`` of its goal and receiver within
  ``tolerance`` of the object; ``close -> hold``: grip force >= ``contact_force`` (``close``
  would settle at ``light_force``); ``hold -> release``: receiver within ``tolerance`` of the
  destination.
* carrier ``carry/present -> retreat`` and receiver ``approach -> withdraw/stow``: the gripper
  was holding at the previous tick (they feel the receiver take the object); carrier ``retreat
  -> rest``: within ``tolerance`` of home.

The synchronisation the features alone leave ambiguous: once the gripper starts closing, its
fingers travel for about 0.3 s before they touch the object, and no feature moves meanwhile.
That state lies far along ``carry``/``present`` and ``approach`` in feature space (both hands
have arrived; only a small rise of the force is left) and close to where ``retreat`` and
``withdraw``/``stow`` start, so graphs coupled only through the features (sequencer option
``coupling="none"``) fire them during the pause: the object leaves with the carrier, or the
receiver leaves without it, and the task cannot complete. The labels tell the difference: those
switches were only demonstrated while the gripper was in ``hold``, which the learned coupling
(``coupling="context"``) requires.
"""

from __future__ import annotations

import numpy as np

from cpmp.data import Demonstration
from cpmp.worlds.common import ScriptPolicy, positive_count, record_script, seeded_episodes
from cpmp.worlds.relay.world import (
    FEATURE_NAMES,
    STRATEGIES,
    VARIABLES,
    RelayEpisode,
    RelayTask,
)

_CARRIER_OUT = ("carry", "present")


def script(
    task: RelayTask, x: np.ndarray, episode: RelayEpisode, active: dict[str, str]
) -> dict[str, str]:
    """The demonstrator's switches from features ``x (6,)`` and the current MPs ``active``.

    Guards on other variables' MPs read ``active`` (this tick's labels), so such a switch
    comes one tick after the one it waits for.
    """
    carrier, receiver, force = x[0:2], x[2:4], x[4]
    tol = task.tolerance
    new = dict(active)
    if active["gripper"] == "open" and active["carrier"] in _CARRIER_OUT:
        goal = episode.meeting_point if active["carrier"] == "carry" else episode.present_point
        if np.linalg.norm(carrier - goal) < tol and np.linalg.norm(receiver - carrier) < tol:
            new["gripper"] = "close"
    if active["gripper"] == "close" and force >= task.contact_force:
        new["gripper"] = "hold"
    if active["carrier"] == "retreat" and np.linalg.norm(carrier - episode.carrier_home) < tol:
        new["carrier"] = "rest"
    if active["gripper"] == "hold":
        if active["carrier"] in _CARRIER_OUT:
            new["carrier"] = "retreat"
        if active["receiver"] == "approach":
            new["receiver"] = "withdraw" if episode.strategy == "meet" else "stow"
        if (
            active["receiver"] in ("withdraw", "stow")
            and np.linalg.norm(receiver - episode.destination) < tol
        ):
            new["gripper"] = "release"
    return new


def demonstrate(task: RelayTask, episode: RelayEpisode, name: str | None = None) -> Demonstration:
    """The scripted demonstrator's labelled demonstration of ``episode``.

    Recorded every ``dt`` from ``t = 0`` until the goal state is reached (or ``max_time``).
    """
    run = record_script(
        task,
        episode,
        lambda state: task.features(state, episode),
        lambda x, active: script(task, x, episode, active),
        VARIABLES,
    )
    metadata = {
        "task": "relay",
        "context": episode.context,
        "strategy": episode.strategy,
        "reached_goal": task.at_goal(run.state, episode),
    }
    return run.log.to_demonstration(FEATURE_NAMES, name, metadata)


class ScriptedPolicy(ScriptPolicy):
    """The demonstrator's finite state machine behind the :class:`~cpmp.records.Policy` interface.

    It knows the episode's goals, as the demonstrator does.
    """

    script = staticmethod(script)


def make_demonstrations(
    n: int, seed: int = 0, task: RelayTask | None = None
) -> list[Demonstration]:
    """``n`` demonstrations alternating meet and fetch (``demo_0`` meet), reproducible.

    Args:
        n: the number of demonstrations.
        seed: seeds the episodes.
        task: the task (default: :class:`~cpmp.worlds.relay.RelayTask`'s defaults).

    Returns:
        The demonstrations, named ``demo_<i>``.

    Raises:
        ConfigError: ``n`` is not a positive integer.
    """
    positive_count(n, "n")
    task = task or RelayTask()
    episodes = seeded_episodes(task.sample_episode, STRATEGIES, n, seed)
    return [demonstrate(task, episode, name=f"demo_{i}") for i, episode in enumerate(episodes)]
