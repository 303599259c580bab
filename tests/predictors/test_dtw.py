"""The ``dtw`` predictor (:mod:`cpmp.predictors.dtw`): progress along replayed activations,
independent streams, its window, interpolation between kept reference samples, batched episodes.
Its fit/save/load/MAE/option tests run with the other baselines (tests/test_baselines.py)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from cpmp.errors import ConfigError, DataError
from cpmp.evaluation.offline import stream_progress
from cpmp.predictors.dtw import interpolate_progress
from cpmp.progress import expected_progress
from cpmp.sequencer.sequencer import ConcurrentSequencer


@pytest.fixture(scope="module")
def fitted(train_demos):
    return {"dtw": ConcurrentSequencer.fit(train_demos, predictor="dtw", seed=0, logger=None)}


def _node_activation(seq: ConcurrentSequencer, variable: str, mp: str, j: int = 0):
    return seq.node_keys.index((variable, mp)), seq.graphs[variable].activations[mp][j].features


@pytest.mark.parametrize(("variable", "mp"), [("a", "a_go"), ("b", "b_back")])
def test_dtw_progress_increases_along_a_replayed_training_activation(fitted, variable, mp):
    seq = fitted["dtw"]
    k, features = _node_activation(seq, variable, mp)
    phi = stream_progress(seq, features)[:, k]
    expected = expected_progress(seq.predictor.scaler.transform(features))
    assert phi[0] < 0.1 and phi[-1] > 0.95
    # thinned references: φ moves in steps of about one kept sample; never back by more
    assert np.diff(phi).min() > -0.05, np.diff(phi).min()
    assert np.corrcoef(phi, expected)[0, 1] > 0.98


def test_dtw_streams_are_independent(fitted, test_demos):
    seq = fitted["dtw"]
    model = seq.predictor
    x1, x2 = test_demos[0].features[:80], test_demos[3].features[:80]
    single = [stream_progress(seq, x) for x in (x1, x2)]
    model.reset_state(2)
    with torch.no_grad():
        both = np.stack(
            [model(torch.as_tensor(np.stack([a, b]))).numpy() for a, b in zip(x1, x2, strict=True)]
        )
    assert both.shape[2] == len(seq.node_keys)
    # vectorised float ops over 2 rows and over 1 row may round the last bit differently
    np.testing.assert_allclose(both[:, 0], single[0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(both[:, 1], single[1], rtol=0, atol=1e-12)
    with pytest.raises(DataError, match="reset_state"):
        model(torch.as_tensor(x1[:3]))
    with pytest.raises(ConfigError, match="n_streams"):
        model.reset_state(0)


def test_dtw_window_forgets_old_ticks_and_reset_restarts(fitted, test_demos):
    seq = fitted["dtw"]
    model = seq.predictor
    demo_a, demo_b = test_demos[0], test_demos[4]
    window = model.config.window
    tail = demo_b.features[: window + 20]
    fresh = stream_progress(seq, tail)
    model.reset_state(1)
    for row in demo_a.features[:30]:
        seq.progress(row)
    after = np.concatenate([seq.progress(row[None]) for row in tail])
    assert not np.array_equal(after[0], fresh[0])  # the old ticks are in the window at first
    assert np.array_equal(after[window:], fresh[window:])  # ... and gone a window later
    first, _ = seq.replay(demo_a.time, demo_a.features)
    again, _ = seq.replay(demo_a.time, demo_a.features)  # reset() restarts the stream
    assert again == first


def test_dtw_interpolates_progress_between_kept_samples():
    # one activation along feature 0 (samples at 0, 1, 2; progress 0, 0.5, 1), a second one
    # elsewhere (samples 3, 4): nan step between them, so no interpolation across
    reference = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [5.0, 5.0], [6.0, 5.0]])
    progress = np.array([0.0, 0.5, 1.0, 0.0, 1.0])
    steps = np.array([1.0, 1.0, np.nan, 1.0, np.nan])

    def phi(point, matched):
        dist = np.linalg.norm(reference - np.asarray(point), axis=1)
        return interpolate_progress(np.array(matched), dist, steps, progress)

    # past the matched sample: towards the next one; off the line: by the projection
    np.testing.assert_allclose(phi([1.25, 0.0], [1]), [0.625])
    np.testing.assert_allclose(phi([0.5, 0.3], [1]), [0.25])  # before it: from the previous
    np.testing.assert_allclose(phi([1.0, 0.0], [1]), [0.5])
    np.testing.assert_allclose(phi([-1.0, 0.0], [0]), [0.0])  # clipped, no sample before
    np.testing.assert_allclose(phi([2.7, 0.0], [2]), [1.0])  # last sample: clipped at it
    np.testing.assert_allclose(phi([5.5, 5.0], [3, 1]), [0.5, 1.0])  # two activations at once
    np.testing.assert_allclose(phi([3.0, 0.0], [2]), [1.0])  # never into the next activation


def test_dtw_progress_keeps_rising_while_the_features_move(fitted, test_demos):
    """φ interpolates between kept samples: a staircase (the matched kept sample's progress,
    held for up to ``stride`` ticks while the MP moves) reads to the switching rule as "not
    improved for 50 ms" and fires mid-motion (see docs/benchmarks.md)."""
    seq = fitted["dtw"]
    lag = 5  # the rule's 50 ms patience at the synthetic task's 100 Hz
    keys = seq.node_keys
    rising = stalled = 0
    for demo in test_demos:
        phi = stream_progress(seq, demo.features)
        scaled = seq.predictor.scaler.transform(demo.features)
        for v in sorted(seq.graphs):
            for s in demo.segments(v):
                expected = expected_progress(scaled[s.start : s.stop], demo.time[s.start : s.stop])
                f = phi[s.start : s.stop, keys.index((v, s.mp))]
                moving = expected[lag:] - expected[:-lag] > 0.01
                rising += int(moving.sum())
                stalled += int((moving & (f[lag:] <= f[:-lag] + 1e-3)).sum())
    assert rising > 1000  # the count means something
    assert stalled / rising < 0.05, stalled / rising


def test_dtw_batched_episodes_decide_as_single_ones(fitted, test_demos):
    # two parallel-strategy replays: in the sequential ones dtw's p for a_go -> a_wait peaks
    # while p_a still moves faster than the switch's speed envelope allows, and has fallen
    # below the threshold by the time it settles (no switch; docs/benchmarks.md, session 19)
    seq = fitted["dtw"]
    demos = [test_demos[1], test_demos[3]]
    n = min(d.n_samples for d in demos)
    single = []
    for demo in demos:
        seq.reset(float(demo.time[0]), demo.features[0])
        for t, x in zip(demo.time[1:n], demo.features[1:n], strict=True):
            seq.step(float(t), x)
        single.append([(e.t, e.variable, e.target, e.kind) for e in seq.events])
    batch = seq.batched(2)
    batch.reset(0.0, np.stack([d.features[0] for d in demos]))
    for k in range(1, n):
        batch.step(float(demos[0].time[k]), np.stack([d.features[k] for d in demos]))
    for episode, events in zip(batch.episodes, single, strict=True):
        assert [(e.t, e.variable, e.target, e.kind) for e in episode.events] == events
    assert all(single)  # both episodes switch at all
