"""The behaviour-cloning baseline (cpmp.baselines.bc): training data, classifier, the switching
and start rules, replay and closed loop on the synthetic worlds, batching, checkpoints, and the
main job with ``sequencer=bc``."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch
from hydra import compose, initialize_config_dir

from cpmp.baselines import BCSequencer
from cpmp.baselines.bc import STAY, class_weights, fit_multinomial, rbf, support_rows
from cpmp.errors import ConfigError, CpmpFileError, DataError, NotFittedError
from cpmp.evaluation.checkpoints import load_sequencer
from cpmp.worlds import relay, two_point

CONF = Path(__file__).resolve().parents[2] / "conf"


@pytest.fixture(scope="module")
def two_point_demos():
    return two_point.make_demonstrations(6, seed=0)


@pytest.fixture(scope="module")
def two_point_bc(two_point_demos):
    return BCSequencer.fit(two_point_demos)


def demonstrated(demo, variables):
    """The MP sequence of each variable in ``demo``."""
    return {v: [s.mp for s in demo.segments(v)] for v in variables}


def test_training_data_has_one_switch_tick_per_left_activation(two_point_bc, two_point_demos):
    nodes = two_point_bc.fit_summary.nodes
    assert set(nodes) == {"a/a_go", "a/a_wait", "b/b_go", "b/b_wait"}  # terminals: none
    for key, fit in nodes.items():
        v, mp = key.split("/")
        activations = [
            s for d in two_point_demos for s in d.segments(v) if s.mp == mp
        ]  # each activation is left once (no demonstration ends in a non-terminal MP)
        assert fit["n_switches"] == len(activations)
        assert fit["n_samples"] == sum(s.stop - s.start for s in activations)
        assert fit["converged"] and fit["switch_recall"] == 1.0
    assert two_point_bc.fit_summary.n_support_total == sum(
        len(c.supports) for c in two_point_bc.classifiers.values()
    )


def test_classifier_pieces():
    z = np.array([[0.0, 0.0], [1.0, 0.0]])
    assert np.allclose(rbf(z, z, 2.0), [[1.0, np.exp(-2.0)], [np.exp(-2.0), 1.0]])
    y = np.array([0, 0, 0, 0, 0, 1, 0, 0, 2])
    assert support_rows(y, 3).tolist() == [0, 4, 5, 8]  # evenly spaced, plus every switch
    c = class_weights(y, 3, "balanced")
    assert np.isclose(c[y == 0].sum(), c[y == 1].sum()) and np.isclose(c[y == 1].sum(), 3.0)
    assert class_weights(y, 3, "none").tolist() == [1.0] * 9
    # separable classes on a line: the fit converges and classifies every sample
    x = np.linspace(0.0, 1.0, 30)[:, None]
    labels = np.where(x[:, 0] > 0.7, 1, 0)
    k = rbf(x, x[::3], 8.0)
    w, b, steps, converged, loss = fit_multinomial(k, labels, np.ones(30), 2, l2=1e-4, max_iter=50)
    p1 = 1.0 / (1.0 + np.exp(-(k @ w + b)[:, 0]))
    assert converged and steps < 50 and np.isfinite(loss)
    assert ((p1 > 0.5) == (labels == 1)).all()


def test_replay_reproduces_the_training_demonstrations(two_point_bc, two_point_demos):
    """On the training feature streams every demonstrated MP sequence comes out (measured: 6 of
    6 on two_point and 6 of 6 on relay at D = 6); the switch fires within a few ticks of the
    demonstrator's, mostly before it (balanced class weights favour switching)."""
    for seq, demos in (
        (two_point_bc, two_point_demos),
        (BCSequencer.fit(relay.make_demonstrations(6, seed=0)), relay.make_demonstrations(6)),
    ):
        matched = 0
        for demo in demos:
            result = seq.replay(demo.time, demo.features)
            matched += result.sequences == demonstrated(demo, seq.graphs)
            assert all(e.probability > seq.config.threshold for e in result.events)
        assert matched == len(demos)


def test_closed_loop_on_two_point_is_what_was_measured(two_point_bc):
    """Closed loop, 20 held-out episodes: measured 1 complete, 0 wrong starts, 19 incomplete
    (the variables' switches desynchronise: one variable fires a tick before the other, moves
    on, and the state the other waits for never comes back). The floor guards against
    regressions of the start rule and of the fit, not a claim of quality."""
    counts = two_point.evaluate(two_point_bc, n_episodes=20, seed=1000)
    assert sum(counts.values()) == 20
    assert counts["wrong_start"] == 0
    assert counts["complete"] >= 1


def test_step_records_the_successors_probabilities(two_point_bc, two_point_demos):
    seq = two_point_bc.batched(1).episodes[0]
    demo = two_point_demos[0]
    seq.reset(demo.time[0], demo.features[0])
    assert seq.last_tick.transition_probs == {"a": {}, "b": {}}
    seq.step(demo.time[1], demo.features[1])
    probs = seq.last_tick.transition_probs
    assert set(probs["a"]) == {"a_back", "a_wait"} and set(probs["b"]) == set(
        seq.graphs["b"].successors(seq.active["b"])
    )
    p = seq.switch_probabilities("a", "a_go", demo.features[1])
    assert p.shape == (1, 3) and np.isclose(p.sum(), 1.0)
    assert np.isclose(probs["a"]["a_back"], p[0, 1]) and np.isclose(probs["a"]["a_wait"], p[0, 2])
    assert seq.classifiers[("a", "a_go")].successors == ("a_back", "a_wait")
    assert STAY == "(stay)"


def test_start_is_the_nearest_demonstrated_first_sample(two_point_bc, two_point_demos):
    for demo in two_point_demos:
        start = two_point_bc.reset(0.0, demo.features[0])
        assert start == {v: str(demo.labels[v][0]) for v in ("a", "b")}


def test_terminal_mps_stay(two_point_bc, two_point_demos):
    demo = two_point_demos[1]
    seq = two_point_bc
    seq.replay(demo.time, demo.features)
    assert seq.active == {"a": "a_back", "b": "b_back"}
    seq.step(demo.time[-1] + 1.0, demo.features[0])
    assert seq.active == {"a": "a_back", "b": "b_back"}


def test_batched_equals_one_at_a_time(two_point_bc, two_point_demos):
    streams = [(d.time, d.features) for d in two_point_demos[:3]]
    single = [two_point_bc.replay(t, x).events for t, x in streams]
    n = min(len(t) for t, _ in streams)
    batch = two_point_bc.batched(len(streams))
    batch.reset(0.0, np.stack([x[0] for _, x in streams]))
    for i in range(1, n):
        batch.step(streams[0][0][i], np.stack([x[i] for _, x in streams]))
    for episode, events in zip(batch.episodes, single, strict=True):
        cut = [e for e in events if e.t <= streams[0][0][n - 1] + 1e-9]
        assert episode.events == cut


def test_save_load_round_trip_gives_identical_decisions(two_point_bc, two_point_demos, tmp_path):
    path = two_point_bc.save(tmp_path / "bc.pt")
    loaded = BCSequencer.load(path)
    assert isinstance(load_sequencer(path), BCSequencer)
    assert loaded.config == two_point_bc.config
    assert loaded.fit_summary.nodes == two_point_bc.fit_summary.nodes
    for demo in two_point_demos:
        a = two_point_bc.replay(demo.time, demo.features)
        b = loaded.replay(demo.time, demo.features)
        assert a.sequences == b.sequences
        assert [(e.t, e.variable, e.target, e.probability) for e in a.events] == [
            (e.t, e.variable, e.target, e.probability) for e in b.events
        ]
    x = two_point_demos[0].features
    assert np.array_equal(loaded.progress(x), two_point_bc.progress(x))
    assert "a_go: " in loaded.describe() and "always stays" in loaded.describe()


def test_bad_options_inputs_and_files(two_point_demos, tmp_path):
    with pytest.raises(ConfigError, match="bc threshold must be in"):
        BCSequencer.fit(two_point_demos, threshold=1.5)
    with pytest.raises(ConfigError, match=r"unknown option.*hold_time"):
        BCSequencer.fit(two_point_demos, hold_time=0.1)
    with pytest.raises(DataError, match="at least one demonstration"):
        BCSequencer.fit([])
    seq = BCSequencer.fit(two_point_demos[:2])
    with pytest.raises(NotFittedError, match="reset"):
        seq.step(0.0, np.zeros(3))
    seq.reset(0.1, np.zeros(3))
    with pytest.raises(DataError, match="time went backwards"):
        seq.step(0.0, np.zeros(3))
    with pytest.raises(DataError, match="expected features with 3"):
        seq.step(0.2, np.zeros(2))
    (tmp_path / "junk.pt").write_bytes(b"not a checkpoint")
    with pytest.raises(CpmpFileError, match="bc checkpoint"):
        BCSequencer.load(tmp_path / "junk.pt")
    torch.save({"format": "x", "obj": BCSequencer}, tmp_path / "evil.pt")
    with pytest.raises(CpmpFileError, match="not a trusted bc checkpoint"):
        BCSequencer.load(tmp_path / "evil.pt")


@pytest.mark.slow
def test_main_job_runs_with_sequencer_bc(tmp_path):
    """``experiment=tiny sequencer=bc``: collection, fit, offline evaluation, reproduction and
    report, as with ``sequencer=goal_nearest`` (about 20 s on 2 cores)."""
    from cpmp.experiment.jobs import run_experiment

    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfg = compose(
            "experiment", overrides=["experiment=tiny", "experiment.record=none", "sequencer=bc"]
        )
    report = json.loads(Path(run_experiment(cfg, tmp_path)).read_text())
    assert report["sequencer"]["kind"] == "bc"
    assert report["predictor"]["kind"] == "none"
    assert "sequencer=bc" in report["predictor"]["note"]
    assert isinstance(load_sequencer(tmp_path / "seed_0" / "model_D3.pt"), BCSequencer)
    text = (tmp_path / "report.md").read_text()
    assert "Sequencer `bc` (behaviour cloning" in text
