"""How a closed-loop episode of a synthetic world ended (cpmp.worlds.outcomes), shared by the
worlds: a wrong start wins over reaching the goal, and counts list every outcome."""

from __future__ import annotations

from cpmp.worlds import OUTCOMES, count_outcomes, episode_outcome
from cpmp.worlds.relay.evaluation import OUTCOMES as RELAY_OUTCOMES


def test_a_wrong_start_is_scored_as_such_even_when_the_goal_was_reached():
    assert episode_outcome(started_right=False, reached_goal=True) == "wrong_start"
    assert episode_outcome(started_right=False, reached_goal=False) == "wrong_start"
    assert episode_outcome(started_right=True, reached_goal=True) == "complete"
    assert episode_outcome(started_right=True, reached_goal=False) == "incomplete"


def test_counts_list_every_outcome_in_order():
    assert OUTCOMES == RELAY_OUTCOMES == ("complete", "wrong_start", "incomplete")
    counts = count_outcomes(["incomplete", "complete", "incomplete"])
    assert list(counts.items()) == [("complete", 1), ("wrong_start", 0), ("incomplete", 2)]
    assert count_outcomes([]) == dict.fromkeys(OUTCOMES, 0)
