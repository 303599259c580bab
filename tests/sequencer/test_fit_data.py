"""What a fit trains on and what it reports (cpmp.sequencer.fit_data): the per-node training data,
the subsample stride, still nodes and label glitches."""

import logging

import numpy as np
import pytest
import torch

from cpmp import progress
from cpmp.data.augment import add_feature_noise
from cpmp.data.demonstration import Demonstration
from cpmp.errors import ConfigError
from cpmp.progress import demo_labels, denoise_trajectory, tv_denoise
from cpmp.sequencer.fit_data import _stride, demo_progress, initial_combinations, node_training_data
from cpmp.sequencer.sequencer import ConcurrentSequencer
from cpmp.sequencer.switching import Coupling


def test_subsample_keeps_every_kth_and_last(train_demos, test_demos):
    from cpmp.evaluation.offline import activation_progress, progress_errors

    np.testing.assert_array_equal(_stride(10, 3), [0, 3, 6, 9])
    np.testing.assert_array_equal(_stride(11, 3), [0, 3, 6, 9, 10])
    full = ConcurrentSequencer.fit(train_demos, "klr", seed=0, logger=None)
    sub = ConcurrentSequencer.fit(train_demos, "klr", seed=0, logger=None, subsample=4)
    # same supports (placed on the full trajectories), fewer loss samples, a fit as good:
    # held-out MAE 0.031 with all samples; 0.06 is the bound of tests/test_predictors.py
    assert sub.fit_summary.support_counts == full.fit_summary.support_counts
    assert progress_errors(activation_progress(sub, test_demos))["mae"] < 0.06
    with pytest.raises(ConfigError, match="subsample"):
        ConcurrentSequencer.fit(train_demos, "klr", subsample=0)


def test_still_node_is_reported_in_the_fit_summary(train_demos, caplog):
    """A node during whose activations no feature changes cannot be predicted: a warning
    naming it, in the log and in the fit summary; a healthy fit has none."""
    still = [
        Demonstration(
            d.time,
            np.repeat(d.features[:1], d.n_samples, axis=0),
            {**d.labels, "c": np.array(["wait"] * d.n_samples)},
            d.feature_names,
            d.name,
        )
        for d in train_demos
    ]
    with caplog.at_level(logging.WARNING, logger="cpmp.sequencer.sequencer"):
        seq = ConcurrentSequencer.fit(still, "klr", seed=0, logger=None, variables=["c"])
    warnings = seq.fit_summary.warnings
    assert len(warnings) == 1 and warnings[0].startswith("node c/wait:")
    assert "do not change" in caplog.text
    assert (
        ConcurrentSequencer.fit(train_demos, "klr", seed=0, logger=None).fit_summary.warnings == ()
    )


def test_one_sample_label_glitch_is_reported(train_demos):
    demo = train_demos[0]
    labels = {v: lab.copy() for v, lab in demo.labels.items()}
    a = labels["a"].astype(object)
    switch = int(np.flatnonzero(a[1:] != a[:-1])[0]) + 1
    a[switch] = "a_glitch"  # A...A, glitch, B...B
    labels["a"] = a.astype(str)
    glitched = Demonstration(demo.time, demo.features, labels, demo.feature_names, demo.name)
    seq = ConcurrentSequencer.fit([glitched, *train_demos[1:]], "klr", seed=0, logger=None)
    warnings = [w for w in seq.fit_summary.warnings if "a_glitch" in w]
    assert warnings[0].startswith("node a/a_glitch: its activation in demo_0 lasts 1 sample(s)")
    assert not [w for w in seq.fit_summary.warnings if "a_glitch" not in w]


def test_node_training_data_follows_the_predictor_node_order(fitted_klr, train_demos):
    data = node_training_data(fitted_klr.graphs, fitted_klr.predictor)
    assert [node.key for node in data] == fitted_klr.predictor.node_keys
    for node in data:
        v, mp = node.key
        acts = fitted_klr.graphs[v].activations[mp]
        assert len(node.activations) == len(acts)
        assert node.x.shape == (sum(a.n_samples for a in acts), len(fitted_klr.feature_names))
        assert node.target.shape == (node.x.shape[0],)
        # each activation starts at progress 0 and ends at 1 (eq. 1 normalised per activation)
        ends = np.cumsum([a.n_samples for a in acts])
        starts = ends - [a.n_samples for a in acts]
        np.testing.assert_allclose(node.target.numpy()[starts], 0.0, atol=1e-12)
        np.testing.assert_allclose(node.target.numpy()[ends - 1], 1.0, atol=1e-12)


@pytest.fixture(scope="module")
def noisy_demos(train_demos):
    """:func:`train_demos` with 1 % white noise on every feature: a fit denoises them."""
    return add_feature_noise(train_demos, 0.01, seed=0)


def test_each_activation_is_denoised_once_per_fit(noisy_demos, monkeypatch):
    """node_training_data denoises every activation once and hands the result on as
    ``paths``; with path_noise none the paths are the scaled activations themselves."""
    seq = ConcurrentSequencer.fit(noisy_demos, "klr", seed=0, logger=None)
    graphs, predictor = seq.graphs, seq.predictor
    denoised = []

    def counting_denoise(x: np.ndarray) -> np.ndarray:
        denoised.append(x)
        return denoise_trajectory(x)

    monkeypatch.setattr(progress, "denoise_trajectory", counting_denoise)
    data = node_training_data(graphs, predictor)
    monkeypatch.undo()
    n_activations = sum(len(acts) for g in graphs.values() for acts in g.activations.values())
    assert len(denoised) == n_activations
    for node in data:
        assert len(node.paths) == len(node.activations)
        for scaled, path in zip(node.activations, node.paths, strict=True):
            np.testing.assert_array_equal(path, denoise_trajectory(scaled))
            assert np.abs(path - scaled).max() > 0.0  # the noise was there and was removed
    raw = ConcurrentSequencer.fit(noisy_demos, "klr", seed=0, logger=None, path_noise="none")
    for node in node_training_data(raw.graphs, raw.predictor):
        assert all(p is a for p, a in zip(node.paths, node.activations, strict=True))


def test_fitting_twice_repeats_the_work_and_the_result(noisy_demos, monkeypatch):
    """No denoised trajectory is kept from one fit to the next: the second fit denoises as
    much as the first, and comes out identical."""
    calls = []

    def counting_tv_denoise(signal: np.ndarray, lam: float) -> np.ndarray:
        calls.append(lam)
        return tv_denoise(signal, lam)

    monkeypatch.setattr(progress, "tv_denoise", counting_tv_denoise)
    fits, counts = [], []
    for _ in range(2):
        fits.append(ConcurrentSequencer.fit(noisy_demos, "klr", seed=0, logger=None))
        counts.append(len(calls))
    first, second = fits
    n = counts[0]
    assert n > 0 and counts[1] == 2 * n
    assert calls[:n] == calls[n:]
    a, b = first.predictor.state_dict(), second.predictor.state_dict()
    assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)
    assert first.fit_summary.support_counts == second.fit_summary.support_counts


def test_initial_combinations_are_distinct_and_in_order(train_demos):
    combos = initial_combinations(train_demos, ["a", "b"])
    expected = []
    for demo in train_demos:
        combo = {"a": str(demo.labels["a"][0]), "b": str(demo.labels["b"][0])}
        if combo not in expected:
            expected.append(combo)
    assert combos == expected and len(combos) == 2


def test_fit_hands_its_labels_to_the_coupling(noisy_demos):
    """demo_progress lays the fit's own labels out along the demonstrations: the coupling a
    fit learns from them equals one that labels every activation again."""
    seq = ConcurrentSequencer.fit(noisy_demos, "klr", seed=0, logger=None)
    graphs, predictor = seq.graphs, seq.predictor
    data = node_training_data(graphs, predictor)
    laid_out = demo_progress(graphs, data, [d.n_samples for d in noisy_demos])
    for demo, per_variable in zip(noisy_demos, laid_out, strict=True):
        again = demo_labels(demo, sorted(graphs), predictor.scaler.transform, predictor.labels)
        assert per_variable.keys() == again.keys()
        for v, labels in per_variable.items():
            np.testing.assert_array_equal(labels, again[v])
            for seg in demo.segments(v):  # each activation runs 0 -> 1 (eq. 1 normalised)
                assert (labels[seg.start], labels[seg.stop - 1]) == (0.0, 1.0)
    relearned = Coupling.learn(
        noisy_demos,
        sorted(graphs),
        predictor.scaler.transform,
        predictor.labels,
        feature_range=seq.feature_range,
    )
    assert seq.coupling == relearned
    # the noise moves every feature under every MP; the positions still count as stalls' motion
    assert not seq.coupling.ambient[:2].any()
    assert seq.coupling.progress  # progress thresholds were learned at all


def _drifting_demos() -> list[Demonstration]:
    """An arm out (0 -> 1) and back under ``go`` and ``back`` (first-order attractors), a light
    level drifting at the same rate under both from a different start per demonstration, a
    constant context."""
    out = []
    for k, (light0, context) in enumerate([(1.0, 0.2), (1.1, 0.4), (1.2, 0.3)]):
        t = np.arange(200) * 0.01
        s = 1.0 - np.exp(-5.0 * np.linspace(0.0, 1.0, 100))  # fast, then slowing down
        arm = np.concatenate([s, s[-1] - s]) / s[-1]
        x = np.stack([arm, light0 + 0.5 * t, np.full(200, context)], axis=1)
        labels = {"arm": np.array(["go"] * 100 + ["back"] * 100)}
        out.append(Demonstration(t, x, labels, ["arm", "light", "context"], f"demo_{k}"))
    return out


def test_an_ambient_drift_is_no_progress():
    """The light level drifts alike under both MPs and is ambient: eq. 1 holds it still along
    every activation (labels from the arm alone, the nodes mark it ignored), the path-weighted
    kernel weighs it 0, and φ reads the arm whatever the light; the context, which does not
    move, keeps the floor weight. The paper's labels keep every feature."""
    demos = _drifting_demos()
    seq = ConcurrentSequencer.fit(demos, "klr", seed=0, logger=None, variables=["arm"])
    assert seq.coupling.ambient.tolist() == [False, True, False]
    data = node_training_data(seq.graphs, seq.predictor, ambient=seq.coupling.ambient)
    drifting = node_training_data(seq.graphs, seq.predictor)
    for node, with_drift in zip(data, drifting, strict=True):
        assert node.ignored.tolist() == [False, True, False] and with_drift.ignored is None
        for path, labels, scaled in zip(node.paths, node.labels, node.activations, strict=True):
            assert np.ptp(path[:, 1]) == 0.0 and np.ptp(scaled[:, 1]) > 0.0
            arm_only = progress.expected_progress(scaled[:, :1], np.arange(len(scaled)) * 0.01)
            np.testing.assert_allclose(labels, arm_only, atol=0.02)
        # counted, the drift (steady while the arm slows down) would move the labels
        moved = [np.abs(a - b).max() for a, b in zip(node.labels, with_drift.labels, strict=True)]
        assert max(moved) > 0.05
    weights = seq.predictor.feature_scale[: len(seq.nodes.keys)]
    assert (weights[:, 1] == 0).all() and (weights[:, 2] >= 0.1).all()
    x = np.array([[0.5, 0.2, 0.3], [0.5, 3.0, 0.3]])  # the light far outside the demos
    phi = seq.progress(x)
    np.testing.assert_allclose(phi[0], phi[1])
    go = seq.nodes.index[("arm", "go")]
    assert (
        seq.progress(np.array([0.1, 0.2, 0.3]))[go]
        < 0.3
        < 0.7
        < seq.progress(np.array([0.9, 3.0, 0.3]))[go]
    )
    paper = ConcurrentSequencer.fit(
        demos, "klr", seed=0, logger=None, variables=["arm"], path_noise="none"
    )
    for node in node_training_data(paper.graphs, paper.predictor, ambient=seq.coupling.ambient):
        assert node.ignored is None and all(np.ptp(p[:, 1]) > 0 for p in node.paths)
