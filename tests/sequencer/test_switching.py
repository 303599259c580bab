"""Switching rules, learned coupling between graphs, stall recovery and non-finite progress."""

import itertools
import math
from typing import ClassVar

import numpy as np
import pytest
import torch
from progress_doubles import FirstColumnsAreProgress, chain_graphs

from cpmp.config import SequencerConfig
from cpmp.data.demonstration import Demonstration
from cpmp.errors import DataError
from cpmp.graph import SequenceGraph
from cpmp.predictors import PredictorConfig, ProgressPredictor
from cpmp.sequencer.motion import without_ambient
from cpmp.sequencer.sequencer import ConcurrentSequencer
from cpmp.sequencer.switching import (
    Candidate,
    Coupling,
    JointPartner,
    PaperRule,
    PeakRule,
    recovery_choice,
)

DT = 0.01


class FeatureIsProgress(ProgressPredictor):
    """Test double: node k's progress is feature k; a feature above 1.5 gives a NaN φ."""

    kind: ClassVar[str] = "feature_is_progress"

    def logits(self, z: torch.Tensor) -> torch.Tensor:
        out = torch.logit(z.clamp(1e-9, 1 - 1e-9))
        return torch.where(z > 1.5, torch.full_like(z, math.nan), out)


def _run(rule, stream):
    """Feed ``stream`` (one p per tick, one successor) to ``rule``; index of the firing tick."""
    for k, p in enumerate(stream, start=1):
        if rule.update(round(k * DT, 10), [p], [True]) is not None:
            return k
    return None


def _paper():
    return PaperRule(threshold=0.65, patience=0.05, min_improvement=1e-3)


def test_paper_rule_fires_after_a_peak_that_declines():
    rise = list(np.linspace(0.5, 0.8, 31))  # 0.01 per tick up to 0.8
    stream = rise + [0.8 - 0.004 * k for k in range(1, 40)]  # then falls back, slowly
    k = _run(_paper(), stream)
    # first tick whose p is not above p 50 ms (5 ticks) earlier + 1e-3, and above 0.65
    want = next(
        i + 1
        for i in range(5, len(stream))
        if stream[i] > 0.65 and stream[i] <= stream[i - 5] + 1e-3
    )
    assert k == want
    assert stream[k - 1] < max(stream)  # it fired on the way down, after the peak
    # a fast decline too:
    fast = rise + [0.8 - 0.03 * k for k in range(1, 10)]
    assert _run(_paper(), fast) is not None


def test_paper_rule_fires_on_a_creep_below_tolerance():
    creep = [0.7 + 1e-4 * k for k in range(30)]  # +5e-4 per 50 ms < 1e-3
    assert _run(_paper(), creep) == 6  # the first tick with a reference 50 ms back


def test_paper_rule_waits_while_rising_and_before_patience():
    rising = [0.66 + 0.003 * k for k in range(60)]  # +0.015 per 50 ms
    assert _run(_paper(), rising) is None
    below = [0.6] * 30
    assert _run(_paper(), below) is None
    rule = _paper()
    for k in range(1, 5):  # constant 0.9 but the node is younger than 50 ms
        assert rule.update(k * DT, [0.9], [True]) is None
    assert rule.update(5 * DT, [0.9], [True]) is None  # reference would be t = 0
    assert rule.update(6 * DT, [0.9], [True]) == 0


def _peak():
    return PeakRule(threshold=0.65, patience=0.05, min_improvement=1e-3)


def test_peak_rule_fires_on_a_spike_shorter_than_patience():
    # an event: p jumps within one tick, then falls as the running MPs carry the state away
    spike = [0.01] * 20 + [0.81, 0.77, 0.71, 0.66, 0.6, 0.54, 0.48] + [0.4] * 20
    assert _run(_paper(), spike) is None  # still "improving" on 50 ms ago until below 0.65
    assert _run(_peak(), spike) == 22  # the first tick below the peak
    # a spike that never reaches the threshold, or a p that only wobbles below it, never fires
    assert _run(_peak(), [0.01] * 20 + [0.64, 0.6, 0.5] + [0.4] * 20) is None
    # a fall of no more than the tolerance is not a fall
    assert _run(_peak(), [0.01] * 20 + [0.81, 0.8095] + [0.1] * 5) is None


def test_peak_rule_fires_like_the_paper_rule_on_a_p_that_rises_and_settles():
    streams = {
        "rise then decline": list(np.linspace(0.5, 0.8, 31))
        + [0.8 - 0.004 * k for k in range(1, 40)],
        "creep": [0.7 + 1e-4 * k for k in range(30)],
        "converging": [0.9 - 0.5 * np.exp(-k * DT / 0.2) for k in range(300)],
        "rising": [0.66 + 0.003 * k for k in range(60)],
    }
    for name, stream in streams.items():
        paper = _run(_paper(), stream)
        # a monotone p never falls from a peak: the same tick; the declining one falls from
        # its peak (0.8) by more than 1e-3 one tick after it, before the paper rule fires
        if name == "rise then decline":
            assert _run(_peak(), stream) == 32 < paper
        else:
            assert _run(_peak(), stream) == paper, name
    # the peak is the same successor's, and only an allowed one fires
    rule = _peak()
    for k, (a, b) in enumerate([(0.1, 0.1)] * 10 + [(0.9, 0.7), (0.85, 0.72)], start=1):
        fired = rule.update(k * DT, [a, b], [False, True])
    assert fired is None  # the allowed successor's p is still rising


def test_peak_rule_forgets_peaks_older_than_patience():
    rule = _peak()
    stream = [0.2] * 10 + [0.9] + [0.2] * 10 + [0.7, 0.71, 0.72]
    fired = [rule.update(k * DT, [p], [True]) for k, p in enumerate(stream, start=1)]
    assert fired[11] is None  # 0.2 after the 0.9 peak: below the threshold
    assert all(f is None for f in fired[-3:])  # rising again: the old peak is forgotten


def test_rules_only_fire_allowed_successors():
    rule = _paper()
    for k in range(1, 10):
        fired = rule.update(k * DT, [0.9, 0.7], [False, True])
        assert fired in (None, 1)
    assert fired == 1  # the allowed one, although the other is more probable


def _labels_demo(labels, n_features=1):
    n = len(next(iter(labels.values())))
    return Demonstration(
        time=np.arange(n) * DT,
        features=np.zeros((n, n_features)),
        labels={v: np.array(list(seq)) for v, seq in labels.items()},
        feature_names=[f"f{i}" for i in range(n_features)],
    )


def test_coupling_learns_contexts_of_switches():
    # w switches W1 -> W2 one tick after u switched U1 -> U2; at the end both switch together
    demo = _labels_demo(
        {"u": ["U1"] * 3 + ["U2"] * 4 + ["U3"] * 2, "w": ["W1"] * 4 + ["W2"] * 3 + ["W3"] * 2}
    )
    coupling = Coupling.learn([demo], ["u", "w"])
    assert coupling.contexts[("w", "W1", "W2")] == {"u": frozenset({"U2"})}
    assert coupling.contexts[("u", "U1", "U2")] == {"w": frozenset({"W1"})}
    # simultaneous switches: either order is allowed
    assert coupling.contexts[("u", "U2", "U3")] == {"w": frozenset({"W2", "W3"})}
    assert coupling.inconsistent(("w", "W1", "W2"), {"u": "U1", "w": "W1"}) == ["u runs U1"]
    assert coupling.inconsistent(("w", "W1", "W2"), {"u": "U2", "w": "W1"}) == []
    assert coupling.inconsistent(("w", "W9", "W2"), {"u": "U1"}) == []  # never seen: no rule
    assert Coupling.from_dict(coupling.to_dict()) == coupling


def test_coupling_progress_is_read_before_the_switch_acts():
    """A switch's first sample already holds one step of its new MP. Here w's first W2 sample
    moves u's feature by a jump (a gripper's first opening step drops the object: the arm's
    contact and load features jump): the demonstrator decided on the sample before, at a
    third of U2's path, and that is what a w switch asks of U2, not the whole path."""
    demo = _labels_demo(
        {"u": ["U1"] * 3 + ["U2"] * 4 + ["U3"] * 2, "w": ["W1"] * 6 + ["W2"] * 1 + ["W3"] * 2}
    )
    demo.features[3:7, 0] = [0.0, 0.5, 1.0, 3.0]  # the jump in sample 6, w's first under W2
    demo.features[7:, 0] = 3.0
    coupling = Coupling.learn([demo], ["u", "w"])
    assert coupling.progress[("w", "W1", "W2")] == {"u": {"U2": pytest.approx(1 / 3)}}
    edge, active = ("w", "W1", "W2"), {"u": "U2", "w": "W1"}
    # u's U2 as far as when the demonstrator let go: consistent, with no margin at all
    assert coupling.inconsistent(edge, active, {"u": 0.34}, margin=0.0) == []


def test_coupling_progress_is_in_the_predictors_label_units():
    """The thresholds use the predictor's label kind: with time labels, w switched when U2 had
    run 1 of its 3 intervals, whatever distance u's feature had covered by then (w decided on
    sample 4, its last under W1)."""
    demo = _labels_demo(
        {"u": ["U1"] * 3 + ["U2"] * 4 + ["U3"] * 2, "w": ["W1"] * 5 + ["W2"] * 2 + ["W3"] * 2}
    )
    demo.features[3:7, 0] = [0.0, 2.5, 2.8, 3.0]  # most of the distance in the first step
    demo.features[7:, 0] = 3.0
    path = Coupling.learn([demo], ["u", "w"])
    timed = Coupling.learn([demo], ["u", "w"], labels="time")
    assert path.progress[("w", "W1", "W2")] == {"u": {"U2": pytest.approx(2.5 / 3)}}
    assert timed.progress[("w", "W1", "W2")] == {"u": {"U2": pytest.approx(1 / 3)}}


def test_coupling_learns_how_far_the_others_had_progressed():
    # u's feature moves 0 -> 1 during U2 (4 samples); w switched when U2 was 1/3 done (on
    # sample 4, its last under W1), so a w switch needs U2 at >= 1/3 - margin; U1 -> U2 and
    # the simultaneous end carry no progress
    demo = _labels_demo(
        {"u": ["U1"] * 3 + ["U2"] * 4 + ["U3"] * 2, "w": ["W1"] * 5 + ["W2"] * 2 + ["W3"] * 2}
    )
    demo.features[3:7, 0] = [0.0, 1.0, 2.0, 3.0]
    demo.features[7:, 0] = 3.0
    coupling = Coupling.learn([demo], ["u", "w"])
    assert coupling.progress[("w", "W1", "W2")] == {"u": {"U2": pytest.approx(1 / 3)}}
    assert ("u", "U2", "U3") not in coupling.progress  # w switched in the same tick
    edge, active = ("w", "W1", "W2"), {"u": "U2", "w": "W1"}
    assert coupling.inconsistent(edge, active, {"u": 0.05}, margin=0.2) == [
        "u has U2 at progress 0.05 (demonstrated >= 0.33)"
    ]
    assert coupling.inconsistent(edge, active, {"u": 0.2}, margin=0.2) == []
    assert coupling.inconsistent(edge, active, {"u": 0.05}, margin=None) == []
    assert "u in {U2} (U2 >= 0.33)" in "\n".join(coupling.describe("w"))
    assert Coupling.from_dict(coupling.to_dict()) == coupling
    # checkpoints written before progress was learned hold a plain list of switches
    old = [
        {k: r[k] for k in ("variable", "source", "target", "context")}
        for r in coupling.to_dict()["switches"]
    ]
    assert Coupling.from_dict(old).contexts == coupling.contexts


def _two_chains(**config):
    """Variables u: U1 -> U2 and w: W1 -> W2; features are (φ_U1, φ_U2, φ_W1, φ_W2); w's switch
    was demonstrated only while u ran U2, decided when U2 had run a third of its time."""
    graphs = chain_graphs({"u": ("U1", "U2"), "w": ("W1", "W2")})
    keys = [("u", "U1"), ("u", "U2"), ("w", "W1"), ("w", "W2")]
    model = FeatureIsProgress(keys, 4, PredictorConfig())
    demo = _labels_demo({"u": ["U1"] * 3 + ["U2"] * 4, "w": ["W1"] * 5 + ["W2"] * 2})
    coupling = Coupling.learn([demo], ["u", "w"])
    return ConcurrentSequencer(
        graphs, model, ["a", "b", "c", "d"], SequencerConfig(**config), None, None, coupling
    )


def test_coupling_holds_a_transition_until_its_context_is_demonstrated():
    coupled = _two_chains(patience=0.0)
    free = _two_chains(patience=0.0, coupling="none")
    for seq in (coupled, free):
        seq.reset(0.0, [0.0, 0.0, 0.0, 0.0])
    # w is ready (p = 0.9) while u is still in U1 (p_u = 0.3): only the free sequencer switches
    for k in range(1, 6):
        free.step(k * DT, [0.3, 0.0, 0.9, 0.0])
        coupled.step(k * DT, [0.3, 0.0, 0.9, 0.0])
    assert free.active == {"u": "U1", "w": "W2"}
    assert coupled.active == {"u": "U1", "w": "W1"}
    assert coupled.last_tick.held == {"w": "W2"}
    (note,) = coupled.notes  # logged once per hold, not every tick
    assert note.kind == "hold" and "u runs U1" in note.text
    coupled.step(6 * DT, [0.9, 0.0, 0.9, 0.0])  # u switches to U2 ...
    assert coupled.active == {"u": "U2", "w": "W1"}  # ... w decides on the tick's context
    coupled.step(7 * DT, [0.9, 0.0, 0.9, 0.0])  # U2 at φ = 0: less than demonstrated (1/3)
    assert coupled.active == {"u": "U2", "w": "W1"}
    assert coupled.last_tick.held == {"w": "W2"}  # the same hold: no second note
    assert len(coupled.notes) == 1
    coupled.step(8 * DT, [0.9, 0.5, 0.9, 0.0])
    assert coupled.active == {"u": "U2", "w": "W2"}
    assert [e.variable for e in coupled.events] == ["u", "w"]


def test_describe_shows_the_coupling_and_checkpoint_keeps_it(tmp_path, train_demos):
    seq = ConcurrentSequencer.fit(train_demos, "klr", seed=0, logger=None)
    text = seq.describe()
    # b starts moving in the sequential strategy only once a waits
    assert "b_wait -> b_go when a in {a_wait}" in text
    loaded = ConcurrentSequencer.load(seq.save(tmp_path / "m.pt"))
    assert loaded.coupling == seq.coupling
    np.testing.assert_array_equal(loaded.feature_range, seq.feature_range)
    assert text.split("b: switch contexts")[1] == loaded.describe().split("b: switch contexts")[1]


def _stalled_chain(**config):
    g = SequenceGraph("v")
    for mp in "AB":
        g.add_node(mp)
    g.initial_nodes = {"A"}
    g.edges = {("A", "B")}
    model = FeatureIsProgress([("v", "A"), ("v", "B")], 2, PredictorConfig())
    return ConcurrentSequencer({"v": g}, model, ["a", "b"], SequencerConfig(**config))


def test_recovery_resolves_a_constructed_stall():
    # p = 0.5 (1 - 0) stays below the threshold: the paper's rule deadlocks
    on = _stalled_chain(stall_time=0.5, recovery_threshold=0.3)
    off = _stalled_chain(recovery=False)
    for seq in (on, off):
        seq.reset(0.0, [0.5, 0.0])
        for k in range(1, 100):
            seq.step(k * DT, [0.5, 0.0])
    assert off.active == {"v": "A"} and not off.events
    (event,) = on.events
    assert event.kind == "recovery" and event.target == "B"
    assert event.t == pytest.approx(0.5)  # no switch and no motion for stall_time
    assert [n.kind for n in on.notes] == ["recovery"]


def test_no_recovery_while_moving_or_below_the_relaxed_threshold():
    moving = _stalled_chain(stall_time=0.5)
    low = _stalled_chain(stall_time=0.5, recovery_threshold=0.6)
    moving.reset(0.0, [0.5, 0.0])
    low.reset(0.0, [0.5, 0.0])
    for k in range(1, 100):
        moving.step(k * DT, [0.5, 0.1 * (k % 2)])  # φ_B oscillates: the state is not at rest
        low.step(k * DT, [0.5, 0.0])
    assert moving.active == {"v": "A"} and low.active == {"v": "A"}


def test_recovery_takes_demonstrated_switches_consistent_then_probable():
    cands = [
        Candidate("u", "A", "B", 0.6, 1),
        Candidate("w", "C", "D", 0.4, 0),
        Candidate("w", "C", "E", 0.5, 0),
        Candidate("x", "F", "G", 0.9, 0, demonstrated=False),
    ]
    assert recovery_choice(cands, 0.3) is cands[2]  # consistent first, then the most probable
    assert recovery_choice(cands, 0.55) is cands[0]  # the only demonstrated one at the threshold
    assert recovery_choice(cands, 0.7) is None  # never one the demonstrator did not make here
    # equal inconsistency and p: the variable, then the target decide
    tied = [Candidate("w", "C", "E", 0.5, 0), Candidate("u", "A", "B", 0.5, 0)]
    assert recovery_choice(tied, 0.3) is tied[1]


def test_nonfinite_progress_never_switches():
    hold = _stalled_chain(patience=0.0)
    hold.reset(0.0, [0.0, 0.0])
    for k in range(1, 5):
        assert hold.step(k * DT, [2.0, 0.0]) == {"v": "A"}  # φ_A is NaN
    assert not hold.events
    assert [n.kind for n in hold.notes] == ["nonfinite"]
    strict = _stalled_chain(nonfinite="raise")
    strict.reset(0.0, [0.0, 0.0])
    with pytest.raises(DataError, match="non-finite"):
        strict.step(DT, [2.0, 0.0])
    with pytest.raises(DataError, match="finite"):
        hold.step(math.nan, [0.0, 0.0])
    with pytest.raises(DataError, match="finite"):
        hold.reset(math.inf, [0.0, 0.0])


def test_indicator_features_and_jitter_are_not_motion():
    from cpmp.sequencer.switching import StallDetector, indicator_features

    x = np.array([[0.0, 0.1, 5.0], [1.0, 0.4, 5.0], [0.0, 0.2, 5.0]])
    assert indicator_features(x).tolist() == [True, False, True]
    # range 1 per feature; band = rest_speed * stall_time = 0.01
    det = StallDetector(np.array([1.0, 1.0]), stall_time=1.0, rest_speed=0.01)
    det.reset(0.0, np.zeros(2))
    for k in range(1, 301):  # 3 s of contact jitter of +-0.004: never motion
        det.observe(k * DT, np.array([0.004 * (-1) ** k, 0.0]))
    assert det.last_motion == 0.0 and det.stalled(3.0)
    drift = StallDetector(np.array([1.0, 1.0]), stall_time=1.0, rest_speed=0.01)
    drift.reset(0.0, np.zeros(2))
    for k in range(1, 301):  # a slow drift of 0.02 range/s is motion
        drift.observe(k * DT, np.array([0.0002 * k, 0.0]))
    assert drift.last_motion > 2.4 and not drift.stalled(3.0)
    ambient = StallDetector(  # an episode's detector: the ambient features' ranges at 0
        without_ambient(np.array([1.0, 1.0]), np.array([True, False])),
        stall_time=1.0,
        rest_speed=0.01,
    )
    ambient.reset(0.0, np.zeros(2))
    for k in range(1, 301):  # the same drift on an ambient feature is not motion
        ambient.observe(k * DT, np.array([0.0002 * k, 0.0]))
    assert ambient.last_motion == 0.0 and ambient.stalled(3.0)


def _finished_relay(**config):
    """u: U1 -> U2; w: W1 -> W2 -> W3, where W2 -> W3 was demonstrated only while u ran U1 and
    one demonstration ends in (U2, W2): there W2 is final. Features (φ_U1, φ_U2, φ_W1, φ_W2,
    φ_W3)."""
    demos = [
        _labels_demo({"u": ["U1"] * 6 + ["U2"] * 4, "w": ["W1"] * 2 + ["W2"] * 2 + ["W3"] * 6}),
        _labels_demo({"u": ["U1"] * 3 + ["U2"] * 7, "w": ["W1"] * 2 + ["W2"] * 8}),
    ]
    graphs = {}
    for v, chain in {"u": ["U1", "U2"], "w": ["W1", "W2", "W3"]}.items():
        g = SequenceGraph(v)
        for mp in chain:
            g.add_node(mp)
        g.initial_nodes = {chain[0]}
        g.edges = set(itertools.pairwise(chain))
        graphs[v] = g
    keys = [("u", "U1"), ("u", "U2"), ("w", "W1"), ("w", "W2"), ("w", "W3")]
    model = FeatureIsProgress(keys, 5, PredictorConfig())
    coupling = Coupling.learn(demos, ["u", "w"])
    options = {"stall_time": 0.5, "recovery_threshold": 0.3, **config}
    return ConcurrentSequencer(
        graphs, model, list("abcde"), SequencerConfig(**options), None, None, coupling
    )


def _run_to(seq, x, until, t=0.0):
    """Step ``seq`` every DT with features ``x`` (each tick a new measurement) until ``until``."""
    while t < until - 1e-9:
        t = round(t + DT, 10)
        seq.step(t, x, stamp=t)
    return t


def test_a_final_node_never_recovers():
    """At (U2, W2) the task is done: W2 -> W3 (p = 0.5 >= the recovery threshold) was never
    demonstrated while u ran U2, and U2 has no successor. A stall there is the demonstrated
    end: no recovery, no give-up. (The earlier recovery took W2 -> W3, the only candidate.)"""
    seq = _finished_relay()
    seq.reset(0.0, [0.0] * 5)
    t = _run_to(seq, [0.5, 0.0, 0.9, 0.0, 0.0], 0.2)  # w: W1 -> W2 (p = 0.9, U1 at 0.5)
    t = _run_to(seq, [0.9, 0.0, 1.0, 0.1, 0.0], 0.4, t)  # u: U1 -> U2 (p = 0.9, w in W2)
    assert [(e.variable, e.target) for e in seq.events] == [("w", "W2"), ("u", "U2")]
    _run_to(seq, [1.0, 0.5, 1.0, 0.5, 0.0], 3.0, t)  # then at rest: a stall
    assert seq.active == {"u": "U2", "w": "W2"}
    assert [e.kind for e in seq.events] == ["switch", "switch"]
    assert [n.kind for n in seq.notes if n.kind != "hold"] == []
    # the same stall while u still runs U1 (where W2 -> W3 was demonstrated) recovers
    seq.reset(0.0, [0.0] * 5)
    t = _run_to(seq, [0.5, 0.0, 0.9, 0.0, 0.0], 0.2)
    _run_to(seq, [0.62, 0.0, 1.0, 0.64, 0.0], 0.9, t)  # p_u = 0.62, p_w = 0.64 < 0.65
    assert [(e.variable, e.target, e.kind) for e in seq.events] == [
        ("w", "W2", "switch"),
        ("w", "W3", "recovery"),  # the most probable of the two demonstrated here
    ]


def test_by_default_a_stall_takes_the_demonstrated_switch_however_low_its_p():
    """A stall is a state nothing will change: with the default recovery_threshold (0) the
    demonstrated A -> B fires at p = 0.1 (a re-align whose φ reads "done" at its start)."""
    assert SequencerConfig().recovery_threshold == 0.0
    seq = _stalled_chain(stall_time=0.5)
    seq.reset(0.0, [0.1, 0.0])
    _run_to(seq, [0.1, 0.0], 1.0)
    (event,) = seq.events
    assert (event.kind, event.target, event.t) == ("recovery", "B", pytest.approx(0.5))
    assert event.probability == pytest.approx(0.1) and seq._episode.gave_up is None


def test_a_stall_no_demonstrated_transition_resolves_is_a_noted_give_up():
    """A -> B is demonstrated, but its p = 0.1 stays below the recovery threshold: the
    sequencer does not guess; it gives up once, with a note, and switches no more."""
    seq = _stalled_chain(stall_time=0.5, recovery_threshold=0.3)
    seq.reset(0.0, [0.1, 0.0])
    t = _run_to(seq, [0.1, 0.0], 1.0)
    assert seq._episode.gave_up == pytest.approx(0.5)
    (note,) = seq.notes
    assert note.kind == "give_up" and "v: A -> B" in note.text
    _run_to(seq, [0.9, 0.0], 2.0, t)  # p = 0.9 now, flat: the rule would fire; it has stopped
    assert seq.active == {"v": "A"} and not seq.events
    assert [n.kind for n in seq.notes] == ["give_up"]


def test_recovery_never_takes_a_transition_inconsistent_with_the_coupling():
    """w's W1 -> W2 was demonstrated only while u ran U2: with u stalled in U1, the old
    recovery took it (the most probable, 0.9); now nothing demonstrated fits: give up."""
    seq = _two_chains(stall_time=0.5, recovery_threshold=0.3)
    seq.reset(0.0, [0.0, 0.0, 0.0, 0.0])
    _run_to(seq, [0.1, 0.0, 0.9, 0.0], 1.5)  # u: p = 0.1 < 0.3; w: p = 0.9, held
    assert seq.active == {"u": "U1", "w": "W1"} and not seq.events
    assert [n.kind for n in seq.notes] == ["hold", "give_up"]


def test_recovery_goes_where_the_demonstrator_went_from_the_nearest_state():
    """A -> B was demonstrated with much left to do (amount 1), A -> C with nothing left (0):
    at a stall with nothing left, C, although B is more probable (the repetition world's
    'scoop again' after the last pour)."""
    demos = []
    for target, amount in (("B", 1.0), ("C", 0.0)):
        features = np.zeros((10, 4))
        features[:, 3] = amount
        demos.append(
            Demonstration(
                time=np.arange(10) * DT,
                features=features,
                labels={"v": np.array(["A"] * 5 + [target] * 5)},
                feature_names=["a", "b", "c", "amount"],
            )
        )
    g = SequenceGraph("v")
    for mp in "ABC":
        g.add_node(mp)
    g.initial_nodes = {"A"}
    g.edges = {("A", "B"), ("A", "C")}
    coupling = Coupling.learn(demos, ["v"])
    assert coupling.nearest_target("v", "A", np.array([0.5, 0.2, 0.4, 0.05]), {"v": "A"}) == "C"
    assert coupling.nearest_target("v", "A", np.array([0.5, 0.2, 0.4, 0.95]), {"v": "A"}) == "B"
    assert coupling.nearest_target("v", "B", np.zeros(4), {"v": "B"}) is None  # none out of B
    model = FirstColumnsAreProgress([("v", "A"), ("v", "B"), ("v", "C")], 4, PredictorConfig())
    for amount, want in ((0.05, "C"), (0.95, "B")):
        seq = ConcurrentSequencer(
            {"v": g},
            model,
            ["a", "b", "c", "amount"],
            SequencerConfig(stall_time=0.5, recovery_threshold=0.3),
            None,
            None,
            coupling,
        )
        seq.reset(0.0, [0.0, 0.0, 0.0, amount])
        _run_to(seq, [0.5, 0.2, 0.4, amount], 1.0)  # p_B = 0.4 > p_C = 0.3: both below 0.65
        (event,) = seq.events
        assert (event.target, event.kind) == (want, "recovery")


def _retry_with_holder(**config) -> ConcurrentSequencer:
    """v tries (T), undoes after a jam (U) and tries again, then goes on (N); u holds (H) and
    retreats (R) in the sample v's try succeeds (T -> N), in every demonstration: a joint
    switch. Features: the five nodes' φ (H, R, N, T, U: sorted per variable, the predictor's
    order), then a force that rises in a jam."""
    demos = []
    for v_labels, jam in (("TTTUUTTTNNNN", (2, 5)), ("TTTTNNN", None)):
        n = len(v_labels)
        first_n = v_labels.index("N")
        features = np.zeros((n, 6))
        if jam is not None:
            features[jam[0] : jam[1], 5] = 1.0
        demos.append(
            Demonstration(
                time=np.arange(n) * DT,
                features=features,
                labels={
                    "u": np.array(["H"] * first_n + ["R"] * (n - first_n)),
                    "v": np.array(list(v_labels)),
                },
                feature_names=["h", "r", "n", "t", "u", "force"],
            )
        )
    graphs = chain_graphs({"u": ("H", "R"), "v": ("T", "N")})
    graphs["v"].add_node("U")
    graphs["v"].edges |= {("T", "U"), ("U", "T")}
    keys = [("u", "H"), ("u", "R"), ("v", "N"), ("v", "T"), ("v", "U")]
    model = FirstColumnsAreProgress(keys, 6, PredictorConfig())
    coupling = Coupling.learn(demos, ["u", "v"])
    assert coupling.joint[("u", "H", "R")] == {"v": JointPartner(("T",), "N")}
    return ConcurrentSequencer(
        graphs,
        model,
        ["h", "r", "n", "t", "u", "force"],
        SequencerConfig(stall_time=0.5, **config),
        None,
        None,
        coupling,
    )


def test_a_recovery_never_carries_a_joint_partner_the_demonstrator_did_not_make_here():
    """Jammed (force 1), v's nearest demonstrated state went T -> U. u's H -> R is the most
    probable switch, but it was always made with v's T -> N, which is not what the
    demonstrator did here: the recovery takes v's T -> U, not the pair."""
    seq = _retry_with_holder()
    seq.reset(0.0, [0.0, 0.0, 0.0, 0.0, 0.0, 1.0])
    # p(u: H -> R) = 0.5; p(v: T -> N) = 0.03; p(v: T -> U) = 0.09: none fires, a stall
    _run_to(seq, [0.5, 0.0, 0.9, 0.3, 0.7, 1.0], 1.0)
    (event,) = seq.events
    assert (event.variable, event.target, event.kind) == ("v", "U", "recovery")
    assert seq.active == {"u": "H", "v": "U"}
    (note,) = seq.notes  # it says which pair it passed over, and why
    assert note.kind == "recovery" and note.text.endswith(
        "resolved: v: T -> U (p=0.09); not u: H -> R (p=0.50), which would take v: T -> N "
        "along, not the demonstrator's switch here"
    )


def test_a_recovery_carries_its_joint_partner_where_the_demonstrator_made_both():
    """Not jammed (force 0): the nearest demonstrated state of v went T -> N, so the
    recovery takes u's H -> R with v's T -> N along, as demonstrated."""
    seq = _retry_with_holder()
    seq.reset(0.0, [0.0] * 6)
    _run_to(seq, [0.5, 0.0, 0.9, 0.3, 0.7, 0.0], 1.0)
    assert [(e.variable, e.target, e.kind) for e in seq.events] == [
        ("u", "R", "recovery"),
        ("v", "N", "recovery"),
    ]
    (note,) = seq.notes
    assert "not u:" not in note.text and "with v: T -> N" in note.text


def test_a_give_up_says_which_joint_switch_it_passed_over():
    """With a recovery threshold above v's p(T -> U) = 0.09, nothing demonstrated resolves the
    jam: the give-up note names the pair it did not take, and why."""
    seq = _retry_with_holder(recovery_threshold=0.3)
    seq.reset(0.0, [0.0, 0.0, 0.0, 0.0, 0.0, 1.0])
    _run_to(seq, [0.5, 0.0, 0.9, 0.3, 0.7, 1.0], 1.0)
    assert not seq.events
    (note,) = seq.notes
    assert note.kind == "give_up" and note.text.endswith(
        "not u: H -> R (p=0.50), which would take v: T -> N along, not the demonstrator's "
        "switch here"
    )
