"""The shared records (cpmp.records): what a producer leaves out keeps its documented default,
a transition's feature vector takes no part in equality or hashing, and kinds are checked."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cpmp.errors import DataError
from cpmp.records import (
    NOTE_KINDS,
    SWITCH_KINDS,
    RecoveryCounts,
    SequencerNote,
    TickInfo,
    TransitionEvent,
    count_recoveries,
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
