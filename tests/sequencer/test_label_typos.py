"""A mistyped MP name in one demonstration (``clsoe`` for ``close``) is a fit-summary warning
naming both spellings, not a silent node of one activation."""

from __future__ import annotations

import numpy as np
import pytest

from cpmp.data.demonstration import Demonstration
from cpmp.sequencer.fit_data import edit_distance
from cpmp.sequencer.sequencer import ConcurrentSequencer


@pytest.mark.parametrize(
    ("a", "b", "edits"),
    [("close", "clsoe", 1), ("close", "close", 0), ("close", "clos", 1), ("a_go", "b_back", 5)],
)
def test_edit_distance_counts_a_swap_as_one_edit(a, b, edits):
    assert edit_distance(a, b) == edits == edit_distance(b, a)


def test_a_typo_in_one_demonstration_is_a_fit_warning_naming_both(train_demos):
    victim = next(i for i, d in enumerate(train_demos) if "a_back" in set(d.labels["a"]))
    demo = train_demos[victim]
    labels = {
        **demo.labels,
        "a": np.where(demo.labels["a"] == "a_back", "a_bakc", demo.labels["a"]),
    }
    typo = Demonstration(demo.time, demo.features, labels, demo.feature_names, demo.name)
    demos = [*train_demos[:victim], typo, *train_demos[victim + 1 :]]
    seq = ConcurrentSequencer.fit(demos, "klr", seed=0, logger=None)
    warnings = [w for w in seq.fit_summary.warnings if "a_bakc" in w]
    assert len(warnings) == 1
    assert warnings[0].startswith(f"node a/a_bakc: its one activation (in {demo.name}")
    assert "named like a/a_back" in warnings[0] and "relabel it 'a_back'" in warnings[0]


def test_distinct_names_of_single_activations_are_not_typos(fitted_klr):
    """The synthetic task's MPs (a_go, a_wait, a_back, ...) are far apart: no warning."""
    assert fitted_klr.fit_summary.warnings == ()
