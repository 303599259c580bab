"""Baseline progress predictors (issue 14): sklearn_klr, regression_clip, time_phase, dtw."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch
from hydra import compose, initialize_config_dir

from cpmp.config import predictor_config
from cpmp.data.demonstration import Demonstration
from cpmp.errors import ConfigError, DataError
from cpmp.evaluation.offline import activation_progress, progress_errors, stream_progress
from cpmp.experiment.config import predictor_options
from cpmp.graph import build_graphs
from cpmp.predictors import make_predictor
from cpmp.progress import time_labels
from cpmp.sequencer.fit_data import node_training_data
from cpmp.sequencer.sequencer import ConcurrentSequencer
from cpmp.worlds.two_point import make_demonstrations

BASELINES = ["sklearn_klr", "regression_clip", "time_phase", "dtw"]
CONF = Path(__file__).resolve().parents[2] / "conf"

# Held-out MAE bound against eq. 1 (seed 0 train / seed 1 test), test_predictors' bound: about
# twice the worst baseline's on this data (see docs/benchmarks.md).
MAE_BOUND = 0.06


@pytest.fixture(scope="module")
def fitted(train_demos):
    return {
        kind: ConcurrentSequencer.fit(train_demos, predictor=kind, seed=0, logger=None)
        for kind in ["klr", *BASELINES]
    }


# ----------------------------------------------------------------------------- all baselines
@pytest.mark.parametrize("kind", BASELINES)
def test_fits_and_predicts_progress_that_moves(fitted, test_demos, kind):
    seq = fitted[kind]
    phi = stream_progress(seq, test_demos[0].features)
    assert phi.shape == (test_demos[0].n_samples, len(seq.node_keys))
    assert np.isfinite(phi).all()
    assert np.ptp(phi, axis=0).max() > 0.5  # progress moves along the demonstration


@pytest.mark.parametrize("kind", BASELINES)
def test_save_load_gives_identical_outputs(fitted, test_demos, tmp_path, kind):
    seq = fitted[kind]
    loaded = ConcurrentSequencer.load(seq.save(tmp_path / f"{kind}.pt"))
    assert type(loaded.predictor) is type(seq.predictor)
    x = test_demos[1].features
    assert np.array_equal(stream_progress(loaded, x), stream_progress(seq, x))
    demo = test_demos[2]
    seqs, events = seq.replay(demo.time, demo.features)
    seqs_loaded, events_loaded = loaded.replay(demo.time, demo.features)
    assert seqs_loaded == seqs
    assert [(e.t, e.variable, e.target) for e in events_loaded] == [
        (e.t, e.variable, e.target) for e in events
    ]


@pytest.mark.parametrize("kind", ["sklearn_klr", "regression_clip", "dtw"])
def test_held_out_progress_mae(fitted, test_demos, kind):
    errors = progress_errors(activation_progress(fitted[kind], test_demos))
    assert errors["mae"] < MAE_BOUND, errors


@pytest.mark.parametrize("kind", BASELINES)
def test_yaml_holds_the_dataclass_defaults(kind):
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfg = compose("experiment", overrides=[f"predictor={kind}"])
    name, options = predictor_options(cfg.predictor)
    assert name == kind
    assert predictor_config(kind, **options) == predictor_config(kind)


@pytest.mark.parametrize(
    ("kind", "option", "value"),
    [
        ("sklearn_klr", "sklearn_solver", "liblinear"),
        ("sklearn_klr", "sklearn_tol", 0.0),
        ("regression_clip", "l2", -1.0),
        ("time_phase", "gamma", float("nan")),
        ("dtw", "window", 0),
        ("dtw", "stride", 2.5),
        ("dtw", "max_reference", 1),
    ],
)
def test_bad_options_are_config_errors(kind, option, value):
    with pytest.raises(ConfigError, match=option):
        predictor_config(kind, **{option: value})


# ----------------------------------------------------------------------------- sklearn_klr
@pytest.mark.parametrize("options", [{}, {"l2": 1e-2, "bias": False, "feature_weighting": "none"}])
def test_sklearn_klr_reaches_klr_loss(train_demos, fitted, options):
    """An independent implementation of the soft-label loss (two weighted copies per sample,
    C = 1 / (n l2)) reaches klr's Newton optimum with the same supports and γ."""
    if options:
        klr = ConcurrentSequencer.fit(train_demos, "klr", seed=0, logger=None, **options)
        sk = ConcurrentSequencer.fit(train_demos, "sklearn_klr", seed=0, logger=None, **options)
    else:
        klr, sk = fitted["klr"], fitted["sklearn_klr"]
    assert torch.equal(sk.predictor.support, klr.predictor.support)
    assert torch.equal(sk.predictor.feature_weights(), klr.predictor.feature_weights())
    loss_klr, loss_sk = klr.fit_summary.loss, sk.fit_summary.loss
    # both solvers stop at gradient tolerances far below 1e-5 of the loss
    assert abs(loss_sk - loss_klr) <= 1e-5 * abs(loss_klr), (loss_sk, loss_klr)
    assert sk.fit_summary.newton.grad_max < 1e-6


# ----------------------------------------------------------------------------- regression_clip
def test_regression_clip_far_from_the_data_is_its_clipped_intercept(fitted, train_demos):
    seq = fitted["regression_clip"]
    model = seq.predictor
    far = np.array(
        [[1e6, -1e6, 1e6], [-1e6, -1e6, -1e6], [1e3, 5.0, -40.0], [0.5, 1e9, 0.5]],
        dtype=np.float64,
    )
    phi = seq.progress(far)
    # far from every support point the kernel vanishes: the clipped intercept remains
    intercept = model.bias.detach().clamp(0, 1).numpy()[: phi.shape[1]]
    np.testing.assert_allclose(phi, np.broadcast_to(intercept, phi.shape), atol=1e-12)
    # on the training data the ridge fit overshoots at the ends; the clip makes that exact
    on_data = seq.progress(np.concatenate([d.features for d in train_demos]))
    assert ((on_data == 0.0) | (on_data == 1.0)).any()


# ----------------------------------------------------------------------------- time_phase
def _warped(demo: Demonstration) -> Demonstration:
    """The same demonstration on a non-uniform clock (``t + t²``), so that time and sample
    index differ."""
    t = demo.time - demo.time[0]
    return Demonstration(
        time=t + t * t,
        features=demo.features,
        labels=demo.labels,
        feature_names=demo.feature_names,
        name=demo.name,
    )


def test_time_labels_are_normalised_elapsed_time():
    t = np.array([0.5, 0.6, 0.9, 1.7, 2.5])
    np.testing.assert_allclose(time_labels(t), (t - 0.5) / 2.0, atol=1e-15)
    assert time_labels(np.array([3.0])).tolist() == [1.0]
    with pytest.raises(DataError, match="time"):
        time_labels(np.array([0.0, np.nan]))


def test_time_phase_labels_are_linear_in_time(train_demos):
    demos = [_warped(d) for d in train_demos]
    graphs = build_graphs(demos)
    keys = [(v, mp) for v in sorted(graphs) for mp in graphs[v].ordered_nodes()]
    time_model = make_predictor("time_phase", keys, 3)
    path_model = make_predictor("klr", keys, 3)
    time_data = node_training_data(graphs, time_model)
    path_data = node_training_data(graphs, path_model)
    nonlinear = 0
    for key, t_node, p_node in zip(keys, time_data, path_data, strict=True):
        acts = graphs[key[0]].activations[key[1]]
        bounds = np.cumsum([0] + [a.n_samples for a in acts])
        for a, lo, hi in zip(acts, bounds[:-1], bounds[1:], strict=True):
            if a.n_samples < 2:
                continue
            y = t_node.target[lo:hi].numpy()
            elapsed = (a.time - a.time[0]) / (a.time[-1] - a.time[0])
            np.testing.assert_allclose(y, elapsed, atol=1e-12)
            slope, intercept = np.polyfit(a.time, y, 1)
            np.testing.assert_allclose(slope * a.time + intercept, y, atol=1e-9)
            # on the warped clock, linear in time is not linear in the sample index
            assert np.abs(y - np.linspace(0.0, 1.0, len(y))).max() > 1e-3 or len(y) < 3
            path = p_node.target[lo:hi].numpy()
            nonlinear += np.abs(path - elapsed).max() > 0.1
    assert nonlinear > 0  # eq. 1's labels are not linear in time: the ablation changes them


def test_stateless_predictors_ignore_reset_state(fitted, test_demos):
    seq = fitted["regression_clip"]
    x = test_demos[0].features[:20]
    before = seq.progress(x)
    seq.predictor.reset_state(5)
    assert not seq.predictor.stateful
    assert np.array_equal(seq.progress(x), before)


@pytest.mark.parametrize("kind", ["sklearn_klr", "regression_clip", "time_phase", "dtw"])
def test_baseline_fits_with_the_lbfgs_trainer(kind: str) -> None:
    """``trainer.solver=lbfgs`` works for every predictor and reaches the default solver's
    progress (dtw has nothing to optimise and keeps its own fit)."""
    demos = make_demonstrations(2, seed=0)
    seq = ConcurrentSequencer.fit(demos, predictor=kind, seed=0, solver="lbfgs", logger=None)
    default = ConcurrentSequencer.fit(demos, predictor=kind, seed=0, logger=None)
    x = demos[0].features[::20]
    # the same convex loss; LBFGS stops at a looser gradient tolerance than the exact solvers
    np.testing.assert_allclose(seq.progress(x), default.progress(x), rtol=0, atol=1e-3)
