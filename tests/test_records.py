"""The shared records (cpmp.records): what a producer leaves out keeps its documented default,
a transition's feature vector takes no part in equality or hashing, and kinds are checked."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cpmp.errors import DataError
from cpmp.records import (
    CAUSE_REASONS,
    NOTE_KINDS,
    SWITCH_KINDS,
    Divergence,
    PendingSwitch,
    RecoveryCounts,
    SequencerNote,
    TickInfo,
    TransitionEvent,
    count_recoveries,
    divergence,
    episode_cause,
    pending_switch,
)


def test_transitions_compare_and_hash_without_their_state() -> None:
    seen = TransitionEvent(0.5, "v", "a", "b", 0.7, np.zeros(3))
    read_back = TransitionEvent(0.5, "v", "a", "b", 0.7)  # a recording keeps no state
    assert seen == read_back
    assert hash(seen) == hash(read_back)
    assert len({seen, read_back, TransitionEvent(0.5, "v", "a", "b", 0.7, np.ones(3))}) == 1
    assert seen != TransitionEvent(0.5, "v", "a", "b", 0.7, kind="recovery")
    assert seen != TransitionEvent(0.5, "v", "a", "c", 0.7)


def test_fields_a_producer_does_not_know_keep_their_defaults() -> None:
    event = TransitionEvent(1.0, "v", "a", "b")
    assert math.isnan(event.probability)
    assert event.state is None and event.kind == "switch"
    first, second = TickInfo(0.1), TickInfo(0.2)
    assert (first.progress, first.active, first.features, first.body_poses) == ({}, {}, None, {})
    first.active["v"] = "a"
    assert second.active == {}  # every tick has its own mappings


def test_a_kind_outside_its_closed_set_is_refused_where_the_record_is_made() -> None:
    assert SWITCH_KINDS == ("switch", "recovery")
    assert NOTE_KINDS == ("hold", "recovery", "give_up", "nonfinite", "clock_step")
    with pytest.raises(DataError, match="one of switch, recovery, got 'jump'"):
        TransitionEvent(0.5, "v", "a", "b", kind="jump")
    with pytest.raises(
        DataError, match="one of hold, recovery, give_up, nonfinite, clock_step, got 'Hold'"
    ):
        SequencerNote(0.5, "Hold", "v", "held")
    assert SequencerNote(0.5, "recovery", "v", "resolved").kind == "recovery"


def test_a_recovery_is_right_when_the_demonstrator_made_that_switch() -> None:
    expected = {"u": ["A", "B", "C"], "w": ["X", "Y"]}
    events = [
        TransitionEvent(1.0, "u", "A", "B", kind="recovery"),  # u's 1st switch: to B, right
        TransitionEvent(2.0, "w", "X", "Y"),  # switches by the rule are not counted
        TransitionEvent(3.0, "w", "Y", "X", kind="recovery"),  # w's 2nd: the demonstrator ends
        TransitionEvent(4.0, "u", "B", "A", kind="recovery"),  # u's 2nd: to C there, wrong
    ]
    assert count_recoveries(events, expected) == RecoveryCounts(right=1, wrong=2)
    assert count_recoveries([], expected) == (0, 0)


def test_divergence_finds_a_wrong_switch_first_then_the_first_missing_one() -> None:
    expected = {"u": ["A", "B", "C"], "w": ["X", "Y"]}
    assert divergence({"u": ["A", "B"], "w": ["X"]}, expected) == Divergence("u", 2, "B", "C", "")
    assert divergence({"u": ["A", "B", "C"], "w": ["X"]}, expected) == Divergence(
        "w", 1, "X", "Y", ""
    )
    # a wrong switch of w comes before u's missing one; one switch too many is wrong too
    assert divergence({"u": ["A"], "w": ["X", "Z"]}, expected) == Divergence("w", 1, "X", "Y", "Z")
    assert divergence({"u": ["A", "B", "C", "A"], "w": ["X", "Y"]}, expected) == Divergence(
        "u", 3, "C", "", "A"
    )
    assert divergence(expected, expected) is None
    assert divergence({"u": ["B"], "w": ["X"]}, expected) is None  # a wrong start


def test_of_several_missing_switches_the_variable_furthest_behind_is_named() -> None:
    """A helper that only has its last switch left waits for the others: the variable with the
    most demonstrated switches still to make is named (ties: ``expected``'s order)."""
    expected = {"holder": ["hold", "retreat"], "inserter": ["align", "insert", "release", "home"]}
    found = divergence({"holder": ["hold"], "inserter": ["align"]}, expected)
    assert found == Divergence("inserter", 1, "align", "insert", "")
    found = divergence({"holder": ["hold"], "inserter": ["align", "insert", "release"]}, expected)
    assert found == Divergence("holder", 1, "hold", "retreat", "")  # one left each: first


def test_pending_switch_from_sequences_alone_and_its_words() -> None:
    expected = {"u": ["A", "B", "C"], "w": ["X", "Y"]}
    cause = pending_switch({"u": ["A", "B"], "w": ["X", "Y"]}, expected)
    assert (cause.variable, cause.current, cause.expected, cause.reason) == (
        "u",
        "B",
        "C",
        "unknown",
    )
    assert math.isnan(cause.best_p) and "u B -> C never fired" in cause.describe()
    events = [TransitionEvent(1.5, "w", "X", "Z")]
    wrong = pending_switch({"u": ["A"], "w": ["X", "Z"]}, expected, events)
    assert (wrong.reason, wrong.fired, wrong.at) == ("wrong_transition", "Z", 1.5)
    assert "w X -> Z fired at 1.50 s instead of -> Y" in wrong.describe()
    done = pending_switch(expected, expected)
    assert done.reason == "task_unfinished" and done.variable == ""
    assert pending_switch({"u": ["C"], "w": ["X"]}, expected) is None


def test_episode_cause_asks_a_policy_that_explains_itself() -> None:
    expected = {"u": ["A", "B"]}
    told = PendingSwitch("u", "A", "B", "below_threshold", best_p=0.3, best_t=1.0)

    class Explains:
        def explain(self, want):
            assert want == expected
            return told

    class Batch:
        def explain(self, index, want):
            return told if index == 2 else None

    assert episode_cause(Explains(), {"u": ["A"]}, expected) is told
    assert episode_cause(Batch(), {"u": ["A"]}, expected, index=2) is told
    # nothing explained (or no explain at all): what the sequences say
    assert episode_cause(Batch(), {"u": ["A"]}, expected, index=0).reason == "unknown"
    assert episode_cause(object(), {"u": ["A"]}, expected).reason == "unknown"


def test_pending_switch_round_trips_and_refuses_an_unknown_reason() -> None:
    cause = PendingSwitch(
        "v", "lower", "home", "still_improving", 0.926, 7.16, 0.9, 0.65, detail="note"
    )
    data = cause.to_dict()
    assert data["at"] is None and data["best_p"] == 0.926  # nan as None: JSON-ready
    back = PendingSwitch.from_dict(data)
    assert back.describe() == cause.describe() and math.isnan(back.at)
    assert (
        cause.describe() == "v lower -> home never fired: p reached 0.926 at 7.16 s, above 0.65 "
        "but still rising (note)"
    )
    assert set(CAUSE_REASONS) >= {"below_threshold", "held", "given_up", "not_a_successor"}
    with pytest.raises(DataError, match="reason is one of"):
        PendingSwitch("v", "a", "b", "slow")
    with pytest.raises(DataError, match="not a pending switch"):
        PendingSwitch.from_dict({"variable": "v"})
