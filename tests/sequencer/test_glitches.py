"""Label glitches (cpmp.sequencer.glitches): one or two samples of another MP between two
samples of the same MP are repaired before the graphs are built, and reported."""

import dataclasses

import numpy as np

from cpmp.data.demonstration import Demonstration
from cpmp.graph import build_graphs
from cpmp.sequencer import ConcurrentSequencer
from cpmp.sequencer.glitches import find_glitches, repair_glitches


def _demo(labels, name=None):
    n = len(next(iter(labels.values())))
    return Demonstration(
        time=np.arange(n) * 0.01,
        features=np.arange(n, dtype=float)[:, None],
        labels={v: np.array(list(seq)) for v, seq in labels.items()},
        name=name,
    )


def test_find_glitches_takes_short_runs_between_equal_labels_only():
    labels = np.array(list("AAAXAAYYAAZZZAABAC"))
    # X (1), YY (2) and B (1) between As; ZZZ is three samples long; C is at the end
    assert find_glitches(labels) == [(3, 4), (6, 8), (15, 16)]
    assert find_glitches(np.array(list("AXBBB"))) == []  # between different MPs: not a glitch
    assert find_glitches(np.array(list("XAAAX"))) == []  # at the ends: not between two labels
    assert find_glitches(labels, max_samples=3) == [(3, 4), (6, 8), (10, 13), (15, 16)]


def test_repair_relabels_and_says_what_keeping_would_have_added():
    clean = _demo({"u": "AAAABBBB", "w": "CCCCDDDD"}, "clean")
    glitchy = _demo({"u": "AAAABBXB", "w": "CCDCDDDD"}, "glitchy")
    repaired, glitches = repair_glitches([clean, glitchy])
    assert repaired[0] is clean  # nothing to repair: the same object
    assert "".join(repaired[1].labels["u"]) == "AAAABBBB"
    assert "".join(repaired[1].labels["w"]) == "CCCCDDDD"
    assert "".join(glitchy.labels["u"]) == "AAAABBXB"  # the input is not changed
    by_variable = {g.variable: g for g in glitches}
    assert by_variable["u"].to_dict() == {
        "demo": "glitchy",
        "variable": "u",
        "start": 6,
        "stop": 7,
        "glitch": "X",
        "around": "B",
        "would_add": ["X", "B -> X", "X -> B"],
    }
    # C D C D D: one glitch (the D at 2), after which the C at 3 is no glitch; D is a node
    # and C -> D an edge anyway, D -> C is not
    assert by_variable["w"].would_add == ("D -> C",)
    assert (
        "relabelled B; kept, it would have added X, B -> X, X -> B" in by_variable["u"].describe()
    )
    graphs = build_graphs(repaired)
    assert graphs["u"].nodes == {"A", "B"} and ("D", "C") not in graphs["w"].edges


def test_repair_only_the_given_variables():
    glitchy = _demo({"u": "AAXAA", "w": "CCDCC"})
    repaired, glitches = repair_glitches([glitchy], variables=["w"])
    assert "".join(repaired[0].labels["u"]) == "AAXAA"
    assert [(g.demo, g.variable) for g in glitches] == [("demonstration 0", "w")]


def test_fit_repairs_a_glitch_by_default_and_keeps_it_on_request(train_demos):
    """One sample of a_go late in a_back of one demonstration (the issue's example: it gave the
    final MP a successor, and closed loop restarted it once the task was done)."""
    demos = [dataclasses.replace(d, labels=dict(d.labels)) for d in train_demos]
    labels = demos[1].labels["a"].copy()
    labels[-5] = "a_go"
    demos[1].labels["a"] = labels
    seq = ConcurrentSequencer.fit(demos, seed=0, logger=None)
    (glitch,) = seq.fit_summary.label_glitches
    assert (glitch["demo"], glitch["variable"], glitch["glitch"], glitch["around"]) == (
        demos[1].name,
        "a",
        "a_go",
        "a_back",
    )
    assert glitch["would_add"] == ["a_back -> a_go"]  # a_go -> a_back is demonstrated
    assert seq.graphs["a"].successors("a_back") == []  # a_back stays final
    clean = ConcurrentSequencer.fit(train_demos, seed=0, logger=None)
    assert seq.graphs["a"].edges == clean.graphs["a"].edges
    kept = ConcurrentSequencer.fit(demos, seed=0, logger=None, repair_glitches=False)
    assert kept.fit_summary.label_glitches == ()
    assert kept.graphs["a"].successors("a_back") == ["a_go"]
    assert any("a_go" in text for text in kept.fit_summary.warnings)
