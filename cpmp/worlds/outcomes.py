"""The outcome of one closed-loop episode of a synthetic world, and their counts.

Every world scores an episode the same way: ``wrong_start`` when the policy's initial MPs differ
from the demonstrator's, else ``complete`` when the goal state was reached within the time
limit and ``incomplete`` when not.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Literal, get_args

Outcome = Literal["complete", "wrong_start", "incomplete"]
"""How one closed-loop episode of a synthetic world ended (see the module doc)."""
OUTCOMES: tuple[Outcome, ...] = get_args(Outcome)
"""Every :data:`Outcome`, in the order the counts list them."""


def episode_outcome(started_right: bool, reached_goal: bool) -> Outcome:
    """The outcome of one episode.

    Args:
        started_right: the policy's initial MPs were the demonstrator's.
        reached_goal: the goal state was reached within the time limit.

    Returns:
        ``wrong_start``, ``complete`` or ``incomplete``.
    """
    if not started_right:
        return "wrong_start"
    return "complete" if reached_goal else "incomplete"


def count_outcomes(outcomes: Iterable[Outcome]) -> dict[Outcome, int]:
    """The number of episodes per outcome, every outcome present (in :data:`OUTCOMES` order)."""
    counts = dict.fromkeys(OUTCOMES, 0)
    for outcome in outcomes:
        counts[outcome] += 1
    return counts
