"""The repetition task's scripted demonstrator: its labelled demonstrations and policy.

The task is :mod:`cpmp.worlds.repetition.world`; :class:`ScriptedPolicy` is the same finite
state machine as a closed-loop policy.

The demonstrator switches at the tick a guard holds, with no settle time. Guards on features
read this tick's features, so switches whose guards hold together fire together; guards on
another variable's MP read the MPs before the tick (as in :mod:`cpmp.worlds.relay`), so such a
switch comes one tick after the one it waits for:

* bowl ``present -> hold``: the bowl is within ``tolerance`` of the spot;
* ladle ``scoop -> pour``: the ladle holds ``min(capacity, remaining)`` and the bowl is in
  ``hold`` (a guard on the other variable: before the first pour the ladle waits, full, at the
  pot until the bowl is in place);
* ladle ``pour -> scoop``: the ladle is empty and soup remains to pour; ``pour -> rest``: the
  ladle is empty and nothing remains (the repetition is decided by the ``remaining`` feature);
* bowl ``hold -> serve``: nothing remains and the ladle is empty (a guard on the other
  variable's state, holding at the tick the ladle's ``pour -> rest`` does).

So the bowl waits in ``hold`` across every repetition, and in the state between two pours
(ladle empty at the spot, bowl in place) only ``remaining > 0`` tells it not to move on.
"""

from __future__ import annotations

import numpy as np

from cpmp.data.demonstration import Demonstration
from cpmp.worlds.common import ScriptPolicy, positive_count, record_script, seeded_episodes
from cpmp.worlds.repetition.world import (
    AMOUNT_EPS,
    FEATURE_NAMES,
    STRATEGIES,
    VARIABLES,
    RepetitionEpisode,
    RepetitionTask,
)


def script(
    task: RepetitionTask, x: np.ndarray, episode: RepetitionEpisode, active: dict[str, str]
) -> dict[str, str]:
    """The demonstrator's switches.

    Args:
        task: the task's options (``capacity``, ``tolerance``).
        x: (7,) features of this tick, in :data:`FEATURE_NAMES` order.
        episode: the episode (the spot the bowl must reach).
        active: variable -> MP before the tick.

    Returns:
        Variable -> MP after the tick.
    """
    fill, bowl, remaining = float(x[2]), x[3:5], float(x[6])
    empty = fill <= AMOUNT_EPS
    done = remaining <= AMOUNT_EPS
    new = dict(active)
    if active["ladle"] == "scoop":
        full = not done and fill >= min(task.capacity, remaining)
        if full and active["bowl"] == "hold":
            new["ladle"] = "pour"
    elif active["ladle"] == "pour" and empty:
        new["ladle"] = "rest" if done else "scoop"
    if active["bowl"] == "present" and np.linalg.norm(bowl - episode.spot) < task.tolerance:
        new["bowl"] = "hold"
    elif active["bowl"] == "hold" and done and empty:
        new["bowl"] = "serve"
    return new


def demonstrate(
    task: RepetitionTask, episode: RepetitionEpisode, name: str | None = None
) -> Demonstration:
    """The scripted demonstrator's labelled demonstration of ``episode``.

    Args:
        task: the task (its ``dt`` is the sample period).
        episode: the episode to demonstrate.
        name: the demonstration's name.

    Returns:
        Samples every ``dt`` from ``t = 0`` until the goal state is reached (or ``max_time``),
        with metadata ``task``, ``need``, ``strategy``, ``repetitions`` and ``reached_goal``.
    """
    run = record_script(
        task, episode, task.features, lambda x, active: script(task, x, episode, active), VARIABLES
    )
    metadata = {
        "task": "repetition",
        "need": episode.need,
        "strategy": episode.strategy,
        "repetitions": episode.repetitions,
        "reached_goal": task.at_goal(run.state, episode),
    }
    return run.log.to_demonstration(FEATURE_NAMES, name, metadata)


class ScriptedPolicy(ScriptPolicy):
    """The demonstrator's finite state machine as a :class:`~cpmp.records.Policy`.

    It knows the episode's spot, as the demonstrator does.
    """

    script = staticmethod(script)


def make_demonstrations(
    n: int, seed: int = 0, task: RepetitionTask | None = None
) -> list[Demonstration]:
    """``n`` demonstrations cycling the strategies, reproducible from ``seed``.

    Args:
        n: how many; ``demo_0`` is ``once``, ``demo_1`` ``twice``, ``demo_2`` ``thrice``, ...
        seed: the episodes' random numbers.
        task: the task (default options if ``None``).

    Returns:
        The demonstrations, named ``demo_<i>``.

    Raises:
        ConfigError: ``n`` is not a positive integer.
    """
    positive_count(n, "n")
    task = task or RepetitionTask()
    episodes = seeded_episodes(task.sample_episode, STRATEGIES, n, seed)
    return [demonstrate(task, episode, name=f"demo_{i}") for i, episode in enumerate(episodes)]
