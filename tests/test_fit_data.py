"""What a fit trains on and what it reports (cpmp.fit_data): the per-node training data, the
subsample stride, still nodes and label glitches."""

import logging

import numpy as np
import pytest
import torch

from cpmp.data import Demonstration
from cpmp.errors import ConfigError
from cpmp.fit_data import _stride, initial_combinations, node_training_data
from cpmp.predictors import START_PREFIX
from cpmp.sequencer import ConcurrentSequencer


def test_subsample_keeps_every_kth_and_last(train_demos, test_demos):
    from cpmp.evaluation import activation_progress, progress_errors

    np.testing.assert_array_equal(_stride(10, 3), [0, 3, 6, 9])
    np.testing.assert_array_equal(_stride(11, 3), [0, 3, 6, 9, 10])
    full = ConcurrentSequencer.fit(train_demos, "klr", seed=0, logger=None)
    sub = ConcurrentSequencer.fit(train_demos, "klr", seed=0, logger=None, subsample=4)
    # same supports (placed on the full trajectories), fewer loss samples, a fit as good:
    # held-out MAE 0.031 with all samples; 0.06 is the bound of tests/test_predictors.py
    assert sub.fit_summary["support_counts"] == full.fit_summary["support_counts"]
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
    with caplog.at_level(logging.WARNING, logger="cpmp.sequencer"):
        seq = ConcurrentSequencer.fit(still, "klr", seed=0, logger=None, variables=["c"])
    warnings = seq.fit_summary["warnings"]
    assert len(warnings) == 1 and warnings[0].startswith("node c/wait:")
    assert "do not change" in caplog.text
    assert (
        ConcurrentSequencer.fit(train_demos, "klr", seed=0, logger=None).fit_summary["warnings"]
        == []
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
    warnings = [w for w in seq.fit_summary["warnings"] if "a_glitch" in w]
    assert warnings[0].startswith("node a/a_glitch: its activation in demo_0 lasts 1 sample(s)")
    assert not [w for w in seq.fit_summary["warnings"] if "a_glitch" not in w]


def test_node_training_data_follows_the_predictor_node_order(fitted_klr, train_demos):
    data = node_training_data(fitted_klr.graphs, fitted_klr.predictor)
    assert [node.key for node in data] == fitted_klr.predictor.node_keys
    by_key = {node.key: node for node in data}
    for node in data:
        v, mp = node.key
        if mp.startswith(START_PREFIX):  # a start head trains on its node's own samples
            own = by_key[(v, mp.removeprefix(START_PREFIX))]
            assert torch.equal(node.x, own.x) and torch.equal(node.target, own.target)
            continue
        acts = fitted_klr.graphs[v].activations[mp]
        assert len(node.activations) == len(acts)
        assert node.x.shape == (sum(a.n_samples for a in acts), len(fitted_klr.feature_names))
        assert node.target.shape == (node.x.shape[0],)
        # each activation starts at progress 0 and ends at 1 (eq. 1 normalised per activation)
        ends = np.cumsum([a.n_samples for a in acts])
        starts = ends - [a.n_samples for a in acts]
        np.testing.assert_allclose(node.target.numpy()[starts], 0.0, atol=1e-12)
        np.testing.assert_allclose(node.target.numpy()[ends - 1], 1.0, atol=1e-12)


def test_initial_combinations_are_distinct_and_in_order(train_demos):
    combos = initial_combinations(train_demos, ["a", "b"])
    expected = []
    for demo in train_demos:
        combo = {"a": str(demo.labels["a"][0]), "b": str(demo.labels["b"][0])}
        if combo not in expected:
            expected.append(combo)
    assert combos == expected and len(combos) == 2
