"""The concurrent sequencer: transition rule, replay, closed loop, persistence, bad input."""

import dataclasses
from pathlib import Path
from typing import ClassVar

import numpy as np
import pytest
import torch
from progress_doubles import FirstColumnsAreProgress, chain_graphs

from cpmp.config import SequencerConfig
from cpmp.errors import ConfigError, CpmpFileError, DataError, NotFittedError
from cpmp.evaluation.offline import replay_demonstrations
from cpmp.graph import SequenceGraph
from cpmp.predictors import PredictorConfig, ProgressPredictor
from cpmp.sequencer.sequencer import ConcurrentSequencer
from cpmp.sequencer.switching import Coupling, JointPartner
from cpmp.worlds.two_point import SyntheticTask, make_demonstrations


def _chain_sequencer(**config):
    """One variable with nodes A -> B, B -> C; features are (φ_A, φ_B, φ_C)."""
    g = SequenceGraph("v")
    for mp in "ABC":
        g.add_node(mp)
    g.initial_nodes = {"A", "B"}
    g.edges = {("A", "B"), ("B", "C")}
    model = FirstColumnsAreProgress([("v", "A"), ("v", "B"), ("v", "C")], 3, PredictorConfig())
    return ConcurrentSequencer({"v": g}, model, ["pa", "pb", "pc"], SequencerConfig(**config))


def test_initial_node_is_highest_entry_probability():
    seq = _chain_sequencer()
    assert seq.reset(0.0, [0.3, 0.1, 0.0]) == {"v": "B"}  # entry 0.9 > 0.7
    assert seq.reset(0.0, [0.05, 0.1, 0.0]) == {"v": "A"}
    # C has the highest entry probability but is not an initial node
    assert seq.reset(0.0, [0.5, 0.6, 0.0]) == {"v": "A"}


def test_switch_once_p_has_not_improved_for_patience():
    seq = _chain_sequencer(threshold=0.65, patience=0.05, min_improvement=1e-3)  # peak rule
    seq.reset(0.0, [0.0, 0.0, 0.0])
    # p = φ_A (1 - φ_B) = 0.7 > threshold from t = 0.01 on, constant, each tick a new
    # measurement (its stamp; an unchanged vector without one adds no evidence)
    for k in range(1, 5):
        t = 0.01 * k
        assert seq.step(t, [0.7, 0.0, 0.0], stamp=t) == {"v": "A"}  # 0.01 .. 0.04 s: waiting
    # at 0.05 s, p 50 ms earlier (at the start) was 0: still an improvement
    assert seq.step(0.05, [0.7, 0.0, 0.0], stamp=0.05) == {"v": "A"}
    assert seq.step(0.06, [0.7, 0.0, 0.0], stamp=0.06) == {"v": "B"}  # 50 ms, no improvement
    (event,) = seq.events
    assert (event.t, event.source, event.target) == (0.06, "A", "B")
    assert event.probability == pytest.approx(0.7)
    np.testing.assert_allclose(event.state, [0.7, 0.0, 0.0])


@pytest.mark.parametrize("rule", ["paper", "peak"])
def test_an_improving_probability_delays_the_switch(rule):
    seq = _chain_sequencer(switch_rule=rule, patience=0.05, min_improvement=1e-3)
    seq.reset(0.0, [0.0, 0.0, 0.0])
    t, p = 0.0, 0.66
    while p < 0.95:  # rises 0.01 per tick: always improving, so no switch
        t = round(t + 0.01, 10)
        assert seq.step(t, [p, 0.0, 0.0]) == {"v": "A"}
        p += 0.01
    flat = p - 0.01  # the last value stepped
    for _ in range(4):  # then flat: p 50 ms earlier was still lower
        t = round(t + 0.01, 10)
        assert seq.step(t, [flat, 0.0, 0.0], stamp=t) == {"v": "A"}
    t = round(t + 0.01, 10)
    assert seq.step(t, [flat, 0.0, 0.0], stamp=t) == {"v": "B"}


def test_creeping_improvement_below_tolerance_does_not_block():
    creeping = [0.7 + 1e-4 * k for k in range(20)]
    strict = _chain_sequencer(min_improvement=0.0)
    tolerant = _chain_sequencer(min_improvement=1e-3)
    for seq in (strict, tolerant):
        seq.reset(0.0, [0.0, 0.0, 0.0])
        for k, p in enumerate(creeping, start=1):
            seq.step(0.01 * k, [p, 0.0, 0.0])
    assert strict.active == {"v": "A"}  # strict comparison never fires on an asymptote
    assert tolerant.active == {"v": "B"}


def test_below_threshold_never_switches():
    seq = _chain_sequencer(threshold=0.65, patience=0.05)
    seq.reset(0.0, [0.0, 0.0, 0.0])
    for k in range(1, 30):
        seq.step(0.01 * k, [0.64, 0.0, 0.0])
    assert seq.active == {"v": "A"}


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"switch_rule": "plateau"}, r"'plateau' \(the plateau rule .* was removed .* use peak"),
        ({"min_exit": 0.9}, r"removed sequencer option\(s\) min_exit .*drop them"),
        ({"min_exit": 0.0}, r"removed sequencer option\(s\) min_exit"),
        (
            {"start_kernel": "isotropic"},
            r"removed sequencer option\(s\) start_kernel \(start_kernel: the isotropic start "
            r"heads .* were removed .*drop them$",
        ),
        ({"start_kernel": "shared"}, r"removed sequencer option\(s\) start_kernel .*learned start"),
    ],
)
def test_a_removed_option_is_named_as_removed(train_demos, options, message):
    with pytest.raises(ConfigError, match=message):
        ConcurrentSequencer.fit(train_demos, "klr", logger=None, **options)


def test_terminal_node_stays():
    seq = _chain_sequencer(patience=0.0)
    seq.reset(0.0, [0.95, 0.0, 0.0])
    assert seq.active == {"v": "B"}
    seq.step(0.01, [0.0, 0.9, 0.0])
    assert seq.active == {"v": "C"}
    for k in range(2, 10):
        assert seq.step(0.01 * k, [1.0, 1.0, 1.0]) == {"v": "C"}
    assert seq.last_tick.transition_probs == {"v": {}}


def test_replay_reproduces_held_out_sequences(fitted_klr, test_demos):
    result = replay_demonstrations(fitted_klr, test_demos)
    assert result["all_match"] == 1.0, result["per_demo"]
    # measured mean 0.035, std 0.012 (features span ~[0, 1]); a switch more than 0.1 away from
    # the demonstrated state would be a visibly early or late transition
    assert result["distance_mean"] < 0.1
    assert result["n_switches"] == sum(
        len(d.switch_indices(v)) for d in test_demos for v in d.variables
    )


def test_predict_progress_and_tick_info(fitted_klr, test_demos):
    x = test_demos[0].features[0]
    phi = fitted_klr.predict_progress(x)
    assert set(phi) == {"a", "b"}
    assert set(phi["b"]) == {"b_wait", "b_go", "b_back"}
    assert phi["a"]["a_go"] < 0.2  # an activation's start has low progress
    fitted_klr.reset(0.0, x)
    fitted_klr.step(0.01, test_demos[0].features[1])
    info = fitted_klr.last_tick
    assert info.active == fitted_klr.active and set(info.transition_probs) == {"a", "b"}


def test_closed_loop_synthetic_task(fitted_klr):
    task, rng = SyntheticTask(), np.random.default_rng(5)
    done = [task.rollout(task.sample_episode(rng), fitted_klr)[1] for _ in range(20)]
    assert sum(done) >= 18  # measured 20/20; allow two misses of an honest closed loop


def test_fit_is_reproducible(train_demos):
    a = ConcurrentSequencer.fit(train_demos, "mlp", seed=3, logger=None, epochs=20)
    b = ConcurrentSequencer.fit(train_demos, "mlp", seed=3, logger=None, epochs=20)
    c = ConcurrentSequencer.fit(train_demos, "mlp", seed=4, logger=None, epochs=20)
    x = train_demos[0].features
    assert np.array_equal(a.progress(x), b.progress(x))
    assert not np.array_equal(a.progress(x), c.progress(x))


def test_save_load_bit_exact(fitted_klr, test_demos, tmp_path):
    path = fitted_klr.save(tmp_path / "model.pt")
    loaded = ConcurrentSequencer.load(path)
    x = test_demos[2].features
    assert np.array_equal(loaded.progress(x), fitted_klr.progress(x))
    for v, g in fitted_klr.graphs.items():
        h = loaded.graphs[v]
        assert (h.nodes, h.initial_nodes, h.edges) == (g.nodes, g.initial_nodes, g.edges)
    assert loaded.config == fitted_klr.config
    assert loaded.feature_names == fitted_klr.feature_names
    assert (
        replay_demonstrations(loaded, test_demos[:2])["per_demo"]
        == replay_demonstrations(fitted_klr, test_demos[:2])["per_demo"]
    )


@pytest.mark.parametrize(
    ("kind", "options"), [("klr_sparse", {"refine_iter": 5}), ("mlp", {"epochs": 30})]
)
def test_save_load_other_predictors(train_demos, tmp_path, kind, options):
    seq = ConcurrentSequencer.fit(train_demos, kind, seed=0, logger=None, **options)
    loaded = ConcurrentSequencer.load(seq.save(tmp_path / "m.pt"))
    x = train_demos[1].features
    assert np.array_equal(loaded.progress(x), seq.progress(x))


def test_failed_save_leaves_no_partial_file(fitted_klr, tmp_path, monkeypatch):
    path = tmp_path / "model.pt"
    fitted_klr.save(path)
    before = path.read_bytes()

    def broken(obj, f, *args, **kwargs):
        with open(f, "wb") as fh:
            fh.write(b"partial")
        raise OSError("disk full")

    monkeypatch.setattr(torch, "save", broken)
    with pytest.raises(OSError, match="disk full"):
        fitted_klr.save(path)
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["model.pt"]


def test_load_errors(tmp_path):
    with pytest.raises(CpmpFileError, match="does not exist"):
        ConcurrentSequencer.load(tmp_path / "missing.pt")
    garbage = tmp_path / "garbage.pt"
    garbage.write_bytes(b"not a checkpoint")
    with pytest.raises(CpmpFileError, match="not a readable cpmp sequencer checkpoint"):
        ConcurrentSequencer.load(garbage)
    other = tmp_path / "other.pt"
    torch.save({"format": "something-else"}, other)
    with pytest.raises(CpmpFileError, match="not a cpmp sequencer checkpoint"):
        ConcurrentSequencer.load(other)
    hostile = tmp_path / "hostile.pt"
    torch.save({"format": "cpmp-sequencer", "payload": Path("/etc/passwd")}, hostile)
    with pytest.raises(CpmpFileError, match="not a trusted cpmp sequencer checkpoint") as info:
        ConcurrentSequencer.load(hostile)
    assert "weights_only=False" not in str(info.value)


def test_bad_inputs(fitted_klr, train_demos):
    with pytest.raises(ConfigError, match="unknown predictor"):
        ConcurrentSequencer.fit(train_demos, predictor="forest")
    with pytest.raises(ConfigError, match="unknown option 'treshold'"):
        ConcurrentSequencer.fit(train_demos, treshold=0.5)
    with pytest.raises(ConfigError, match="threshold must be in"):
        ConcurrentSequencer.fit(train_demos, threshold=1.5)
    with pytest.raises(ConfigError, match="patience"):
        SequencerConfig(patience=-0.1)
    with pytest.raises(DataError, match="at least one demonstration"):
        ConcurrentSequencer.fit([])
    with pytest.raises(DataError, match="3 entries"):
        fitted_klr.predict_progress(np.zeros(4))
    with pytest.raises(DataError, match="NaN"):
        fitted_klr.reset(0.0, np.array([0.0, np.nan, 0.0]))
    fresh = ConcurrentSequencer(fitted_klr.graphs, fitted_klr.predictor, fitted_klr.feature_names)
    with pytest.raises(NotFittedError, match="reset"):
        fresh.step(0.0, np.zeros(3))
    fresh.reset(1.0, np.zeros(3))
    with pytest.raises(DataError, match="time went backwards"):
        fresh.step(0.5, np.zeros(3))


def test_mismatched_feature_names_rejected(train_demos):
    from cpmp.data.demonstration import Demonstration

    d = train_demos[0]
    renamed = Demonstration(d.time, d.features, d.labels, ["x", "y", "z"], "demo_x")
    with pytest.raises(DataError, match="all must match"):
        ConcurrentSequencer.fit([train_demos[1], renamed])


def test_synthetic_demos_are_reproducible():
    a, b = make_demonstrations(2, seed=7), make_demonstrations(2, seed=7)
    assert all(np.array_equal(x.features, y.features) for x, y in zip(a, b, strict=True))


def _two_graph_sequencer(start_rule):
    """Variables u (initial U1, U2) and w (initial W1, W2); demonstrated starts: (U1, W1) and
    (U2, W2). Features are the four nodes' φ in order U1, U2, W1, W2."""
    graphs = {}
    for v, names in (("u", ["U1", "U2"]), ("w", ["W1", "W2"])):
        g = SequenceGraph(v)
        for mp in names:
            g.add_node(mp)
        g.initial_nodes = set(names)
        graphs[v] = g
    keys = [("u", "U1"), ("u", "U2"), ("w", "W1"), ("w", "W2")]
    model = FirstColumnsAreProgress(keys, 4, PredictorConfig())
    combos = [{"u": "U1", "w": "W1"}, {"u": "U2", "w": "W2"}]
    return ConcurrentSequencer(
        graphs, model, ["a", "b", "c", "d"], SequencerConfig(start_rule=start_rule), None, combos
    )


def _joint_pair_sequencer(carried: bool) -> ConcurrentSequencer:
    """u: A -> B and v: W -> X, always demonstrated in the same sample; v's switch carries u's
    when ``carried``. Features are the four nodes' φ in order A, B, W, X, then a clock."""
    graphs = chain_graphs({"u": ("A", "B"), "v": ("W", "X")})
    keys = [("u", "A"), ("u", "B"), ("v", "W"), ("v", "X")]
    model = FirstColumnsAreProgress(keys, 5, PredictorConfig())
    coupling = Coupling(
        contexts={
            ("u", "A", "B"): {"v": frozenset({"W", "X"})},
            ("v", "W", "X"): {"u": frozenset({"A", "B"})},
        },
        joint={
            ("u", "A", "B"): {"v": JointPartner(("W",), "X")},
            ("v", "W", "X"): {"u": JointPartner(("A",), "B", carried)},
        },
    )
    return ConcurrentSequencer(
        graphs, model, ["a", "b", "w", "x", "clock"], SequencerConfig(), None, None, coupling
    )


@pytest.mark.parametrize("carried", [True, False])
def test_a_joint_switch_takes_a_carried_partner_along_and_waits_for_the_others(carried):
    seq = _joint_pair_sequencer(carried)
    assert seq.reset(0.0, np.array([0.1, 0.9, 0.1, 0.9, 0.0])) == {"u": "A", "v": "W"}
    # v's p = 1 from here on, u's p = 0.5 * (1 - 0.2) = 0.4: below the threshold throughout
    for i in range(1, 21):
        active = seq.step(i * 0.01, np.array([0.5, 0.2, 1.0, 0.0, i * 0.01]))
    if carried:
        assert active == {"u": "B", "v": "X"}
        ev_v, ev_u = sorted(seq.events, key=lambda e: e.variable, reverse=True)
        assert (ev_v.variable, ev_v.t) == ("v", ev_u.t)  # in the same tick
        assert ev_u.probability == pytest.approx(0.4)
    else:
        assert active == {"u": "A", "v": "W"}
        assert any("waits for u: A -> B" in n.text for n in seq.notes)
    assert "(taken along)" in seq.describe() if carried else "(taken along)" not in seq.describe()


def test_joint_start_never_mixes_strategies():
    # independently, u prefers U1 (entry 0.9 vs 0.8) and w prefers W2 (0.85 vs 0.8): a mixture
    x = np.array([0.1, 0.2, 0.2, 0.15])
    assert _two_graph_sequencer("independent").reset(0.0, x) == {"u": "U1", "w": "W2"}
    # jointly: log 0.9 + log 0.8 = -0.328 beats log 0.8 + log 0.85 = -0.386
    joint = _two_graph_sequencer("joint").reset(0.0, x)
    assert joint == {"u": "U1", "w": "W1"}
    x2 = np.array([0.1, 0.05, 0.3, 0.05])  # U2 and W2 clearly better
    assert _two_graph_sequencer("joint").reset(0.0, x2) == {"u": "U2", "w": "W2"}


def test_fit_records_initial_combinations_and_checkpoint_keeps_them(fit_on_train, tmp_path):
    seq = fit_on_train("klr", start_rule="joint")
    assert sorted(c["b"] for c in seq.initial_combinations) == ["b_go", "b_wait"]
    assert all(c["a"] == "a_go" for c in seq.initial_combinations)
    loaded = ConcurrentSequencer.load(seq.save(tmp_path / "m.pt"))
    assert loaded.initial_combinations == seq.initial_combinations
    assert loaded.config.start_rule == "joint"
    with pytest.raises(ConfigError, match="start_rule"):
        SequencerConfig(start_rule="vote")


def test_the_predictor_has_one_head_per_graph_node(fit_on_train, train_demos):
    """Whatever the start rule, the bank's heads are the graph nodes: the ``independent`` and
    ``joint`` rules read the nodes' own progress predictors."""
    for rule in ("independent", "joint", "learned"):
        seq = fit_on_train("klr", start_rule=rule)
        assert seq.predictor.node_keys == seq.node_keys
        x0 = train_demos[1].features[0]
        assert seq.predictor(torch.as_tensor(x0)).shape == (len(seq.node_keys),)


def test_synthetic_evaluate_classifies_outcomes(fitted_klr):
    from cpmp.worlds.two_point import evaluate

    class Frozen:
        def __init__(self, start):
            self.start = start

        def reset(self, t, x):
            return dict(self.start)

        def step(self, t, x):
            return dict(self.start)

    task = SyntheticTask(max_time=1.0)
    assert evaluate(Frozen({"a": "a_back", "b": "b_back"}), task, 4, seed=0) == {
        "complete": 0,
        "wrong_start": 4,
        "incomplete": 0,
    }
    parallel = evaluate(Frozen({"a": "a_go", "b": "b_go"}), task, 6, seed=0)
    assert parallel["complete"] == 0 and parallel["incomplete"] >= 1
    assert parallel["incomplete"] + parallel["wrong_start"] == 6
    counts = evaluate(fitted_klr, None, 10, seed=5)
    assert sum(counts.values()) == 10 and counts["complete"] >= 8


def test_with_config_shares_the_fit_and_changes_only_the_rule(fitted_klr, test_demos):
    """``with_config`` is the way to try other transition-rule options without refitting."""
    paper = fitted_klr.with_config(threshold=0.9, coupling="none")
    assert paper.predictor is fitted_klr.predictor and paper.graphs == fitted_klr.graphs
    assert paper.config == dataclasses.replace(fitted_klr.config, threshold=0.9, coupling="none")
    assert fitted_klr.config.threshold != 0.9  # the original is untouched
    x = test_demos[0].features
    np.testing.assert_array_equal(paper.progress(x), fitted_klr.progress(x))
    with pytest.raises(ConfigError, match="threshold must be in"):
        fitted_klr.with_config(threshold=1.5)


@pytest.mark.parametrize("rule", ["paper", "peak"])
def test_a_scaled_entry_is_read_the_same_from_the_node_s_first_measurement(rule):
    """A switch whose entry the fit scaled times like an unscaled switch of the same ``p``:
    the rule's history starts at the node's first measurement with the scaled ``p`` too, so a
    ``p`` that is constant from there fires ``patience`` after it, not a tick later."""
    from cpmp.sequencer.branches import BranchChoices

    graphs = chain_graphs({"v": ("B", "C")})
    model = FirstColumnsAreProgress([("v", "B"), ("v", "C")], 3, PredictorConfig())
    config = SequencerConfig(switch_rule=rule)
    plain = ConcurrentSequencer(graphs, model, ["b", "c", "clock"], config)
    scaled = plain._with_branches(BranchChoices({}, None, {("v", "B", "C"): 4.0}))
    fired = []
    # p = 1 * (1 - 0.2) = 0.8 unscaled; 1 * min(1, (1 - 0.8) * 4) = 0.8 scaled
    for seq, phi_c in ((plain, 0.2), (scaled, 0.8)):
        assert seq.reset(0.0, np.array([1.0, phi_c, 0.0])) == {"v": "B"}
        for i in range(1, 11):  # a clock feature: each tick a new measurement
            seq.step(i * 0.01, np.array([1.0, phi_c, i * 0.01]))
        assert [(e.source, e.target) for e in seq.events] == [("B", "C")]
        assert seq.events[0].probability == pytest.approx(0.8)
        fired.append(seq.events[0].t)
    assert fired[0] == pytest.approx(config.patience)
    assert fired[1] == pytest.approx(fired[0])


class _BumpProgress(ProgressPredictor):
    """Test double: node B's φ is a bump around feature 0 = 0.5 (width 0.2), node C's φ 0: the
    transition ``B -> C`` peaks (p = 1) halfway from 0 to 1 and is about 0 at both ends."""

    kind: ClassVar[str] = "bump"

    def logits(self, z: torch.Tensor) -> torch.Tensor:
        bump = torch.exp(-(((z[:, 0] - 0.5) / 0.2) ** 2))
        phi = torch.stack([bump, torch.zeros_like(bump)], dim=1)
        return torch.logit(phi.clamp(1e-9, 1 - 1e-9))


@pytest.mark.parametrize("stamped", [True, False])
def test_a_peak_between_two_samples_of_a_slow_sensor_fires(stamped):
    """A 10 Hz sensor read by a 100 Hz loop sees feature 0 at 0, then at 1: ``p`` is about 0
    at both samples and peaks in between. With stamps, the sequencer reads the way between the
    two samples (states 10 ms apart) and fires at the tick of the second sample; without them
    the ticks between repeat the first sample, when the state changed is not known, and
    nothing fires."""
    graphs = chain_graphs({"v": ("B", "C")})
    model = _BumpProgress([("v", "B"), ("v", "C")], 2, PredictorConfig())
    seq = ConcurrentSequencer(graphs, model, ["u", "clock"], SequencerConfig())
    assert seq.reset(0.0, np.array([0.0, 0.0])) == {"v": "B"}
    for i in range(1, 31):
        t = i * 0.01
        sample = 10 * (i // 10) * 0.01  # the last 10 Hz sample: 0, 0.1, 0.2, 0.3 s
        x = np.array([min(sample / 0.1, 1.0), sample])
        seq.step(t, x, stamp=sample if stamped else None)
    if stamped:
        assert [(e.source, e.target) for e in seq.events] == [("B", "C")]
        assert seq.events[0].t == pytest.approx(0.1)
        assert 0.65 < seq.events[0].probability < 1.0  # fallen back from the peak
        # C runs from this tick on: its activation starts at the second sample, not between
        assert seq._episode._since["v"] == pytest.approx(0.1)
    else:
        assert seq.events == []


def test_a_long_gap_between_measurements_is_read_at_most_max_between_times():
    from cpmp.sequencer.episode import MAX_BETWEEN

    graphs = chain_graphs({"v": ("B", "C")})
    model = _BumpProgress([("v", "B"), ("v", "C")], 2, PredictorConfig())
    seq = ConcurrentSequencer(graphs, model, ["u", "clock"], SequencerConfig())
    rows = []
    progress = seq.progress

    def counted(x):
        rows.append(len(np.atleast_2d(x)))
        return progress(x)

    seq.reset(0.0, np.array([0.0, 0.0]))
    seq.progress = counted  # the steps' rows
    seq.step(0.01, np.array([0.0, 0.01]), stamp=0.01)
    assert rows == [1]  # 10 ms after the last: nothing in between
    seq.step(0.04, np.array([0.1, 0.04]), stamp=0.04)
    assert rows[1:] == [1, 2]  # 30 ms after the last: the two states 10 and 20 ms after it
    for i in range(5, 205):  # a sensor gone for 2 s: its last sample again, 100 Hz ticks
        seq.step(i * 0.01, np.array([0.1, 0.04]), stamp=0.04)
    seq.step(2.05, np.array([0.2, 2.05]), stamp=2.05)
    assert rows[-2:] == [1, MAX_BETWEEN]
