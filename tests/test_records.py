"""The shared records (cpmp.records): what a producer leaves out keeps its documented default,
a transition's feature vector takes no part in equality or hashing, and kinds are checked."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from cpmp.errors import DataError
from cpmp.io import to_builtin
from cpmp.records import (
    CAUSE_REASONS,
    NOTE_KINDS,
    SWITCH_KINDS,
    BaselineFitReport,
    Divergence,
    FitReport,
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


# --- the fit's report -------------------------------------------------------------------------

OLD_KLR_KEYS = [  # the keys of a klr fit's summary dict, in the order the fit wrote them
    "loss",
    "loss_history",
    "val_loss",
    "val_mae",
    "val_mae_final",
    "lr_history",
    "epochs",
    "max_epochs",
    "stopped_early",
    "monitor",
    "device",
    "seconds",
    "solver",
    "kind",
    "n_nodes",
    "n_parameters",
    "support_counts",
    "n_support_total",
    "newton_iterations",
    "newton_grad_max",
    "newton_converged",
    "n_demos",
    "label_glitches",
    "warnings",
    "stay_choices",
    "entry_scale",
]


def test_a_fit_report_round_trips_through_its_dict_in_the_fits_key_order(
    fitted_klr, train_demos
) -> None:
    report = fitted_klr.fit_summary
    assert isinstance(report, FitReport)
    data = report.to_dict()
    assert list(data) == OLD_KLR_KEYS
    assert FitReport.from_dict(data) == report
    # as a checkpoint holds it (plain builtins) and as report.json holds it (JSON)
    assert FitReport.from_dict(to_builtin(data)) == report
    assert FitReport.from_dict(json.loads(json.dumps(to_builtin(data)))) == report
    assert report.kind == "klr" and report.solver == "newton" and report.epochs == 1
    assert report.newton is not None and report.newton.converged
    assert report.n_support_total == sum(report.support_counts.values()) > 0
    assert report.n_demos == len(train_demos)
    assert isinstance(report.loss_history, tuple) and report.loss == report.loss_history[-1]


def test_predictor_facts_keep_their_place_in_the_dict() -> None:
    report = FitReport(
        loss=0.5,
        loss_history=[0.7, 0.5],
        val_loss=[],
        val_mae=[],
        val_mae_final=None,
        lr_history=[1e-3, 1e-3],
        epochs=2,
        max_epochs=10,
        stopped_early=True,
        monitor="train/loss",
        device="cpu",
        seconds=1.25,
        solver="adam",
        kind="mlp",
        n_nodes=3,
        n_parameters=40,
        predictor_facts={"hidden": [8, 8]},
        n_demos=2,
        warnings=["w"],
    )
    data = report.to_dict()
    assert list(data)[13:17] == ["kind", "n_nodes", "n_parameters", "hidden"]
    assert "support_counts" not in data and "newton_iterations" not in data
    assert data["loss_history"] == [0.7, 0.5] and data["warnings"] == ["w"]
    assert FitReport.from_dict(data) == report
    assert report.loss_history == (0.7, 0.5)  # kept as a tuple
    with pytest.raises(DataError, match="fields of the fit report"):
        dataclasses.replace(report, predictor_facts={"loss": 1.0})


def test_a_fit_report_is_frozen(fitted_klr) -> None:
    report = fitted_klr.fit_summary
    with pytest.raises(dataclasses.FrozenInstanceError):
        report.loss = 0.0  # type: ignore[misc]
    with pytest.raises(dataclasses.FrozenInstanceError):
        report.newton.converged = False  # type: ignore[union-attr,misc]
    with pytest.raises(dataclasses.FrozenInstanceError):
        BaselineFitReport("bc", 3, 10, 0.1).seconds = 0.0  # type: ignore[misc]


def test_a_fit_report_from_an_older_fit_takes_the_documented_defaults(fitted_klr) -> None:
    old = {
        k: v
        for k, v in fitted_klr.fit_summary.to_dict().items()
        if k
        not in {
            "val_loss",
            "val_mae",
            "val_mae_final",
            "lr_history",
            "max_epochs",
            "stopped_early",
            "monitor",
            "device",
            "label_glitches",
            "stay_choices",
            "entry_scale",
        }
    }
    report = FitReport.from_dict(old)
    assert (report.loss, report.epochs, report.max_epochs) == (old["loss"], 1, 1)
    assert (report.val_mae, report.val_mae_final, report.lr_history) == ((), None, ())
    assert (report.monitor, report.device, report.stopped_early) == ("", "", False)
    assert (report.label_glitches, report.stay_choices, report.entry_scale) == ((), (), {})
    assert report.support_counts == old["support_counts"]
    with pytest.raises(DataError, match="not a fit report"):
        FitReport.from_dict({k: v for k, v in old.items() if k != "loss"})
    with pytest.raises(DataError, match="not a fit report"):
        FitReport.from_dict({**old, "warnings": "not a list"})


def test_a_baseline_fit_report_round_trips_in_the_baselines_key_order() -> None:
    report = BaselineFitReport(
        "bc", 4, 12, 0.5, nodes={"v/a": {"iterations": 3, "converged": True}}, warnings=["x"]
    )
    data = report.to_dict()
    assert list(data) == ["kind", "n_demos", "n_support_total", "seconds", "nodes", "warnings"]
    assert BaselineFitReport.from_dict(data) == report
    plain = BaselineFitReport("goal_nearest", 4, None, 0.5)
    assert list(plain.to_dict()) == ["kind", "n_demos", "n_support_total", "seconds", "warnings"]
    # a checkpoint keeps no warnings
    saved = {k: v for k, v in plain.to_dict().items() if k != "warnings"}
    assert BaselineFitReport.from_dict(saved) == plain
