"""Progress predictors: accuracy on held-out synthetic trajectories, batching, options."""

import numpy as np
import pytest
import torch

from cpmp.data.demonstration import Demonstration
from cpmp.errors import ConfigError, DataError
from cpmp.evaluation.offline import activation_progress, progress_errors
from cpmp.predictors import make_predictor, predictor_from_spec
from cpmp.progress import path_length
from cpmp.sequencer.sequencer import ConcurrentSequencer

# Held-out MAE measured on this data (seed 0 train / seed 1 test): klr 0.031, klr_full 0.017,
# klr_sparse 0.023, mlp 0.013. The bound is about twice the worst of them: a regression that
# doubles the error fails, platform-level float noise does not.
MAE_BOUND = 0.06


@pytest.fixture(scope="module")
def fitted(fit_on_train):
    return {kind: fit_on_train(kind) for kind in ("klr", "klr_full", "klr_sparse", "mlp")}


@pytest.mark.parametrize("kind", ["klr", "klr_full", "klr_sparse", "mlp"])
def test_the_banks_columns_are_its_nodes_own_logits(fitted, test_demos, kind):
    """The batched call over every node (packed supports, one einsum per layer) gives each
    column as the node's own logits do (as the fit scores it)."""
    model = fitted[kind].predictor
    x = torch.as_tensor(test_demos[0].features[:6])
    with torch.no_grad():
        z = model.scaler(x.to(model.dtype_))
        logits = model.logits(z)
        assert logits.shape == (6, model.n_nodes)
        for i in range(model.n_nodes):
            np.testing.assert_allclose(logits[:, i], model.node_logits(z, i), rtol=0, atol=1e-9)
        np.testing.assert_array_equal(model(x), torch.sigmoid(logits))


@pytest.mark.parametrize("kind", ["klr", "klr_full", "klr_sparse", "mlp"])
def test_held_out_progress_mae(fitted, test_demos, kind):
    errors = progress_errors(activation_progress(fitted[kind], test_demos))
    assert errors["n_activations"] == 30
    assert errors["mae"] < MAE_BOUND, errors
    # progress near the ends decides transitions; it must be predicted well there too
    assert errors["mae_last"] < MAE_BOUND, errors


def test_klr_uses_stated_support_count(fitted, train_demos):
    seq = fitted["klr"]
    scale, minimum = seq.predictor.config.support_scale, seq.predictor.config.min_support
    counts = seq.fit_summary.support_counts
    for v, graph in seq.graphs.items():
        for mp in graph.nodes:
            expected = sum(
                max(minimum, int(np.ceil(scale * path_length(a.features))))
                for a in graph.activations[mp]
            )
            assert counts[f"{v}/{mp}"] == expected


def test_klr_full_uses_every_sample(fitted, train_demos):
    counts = fitted["klr_full"].fit_summary.support_counts
    n_a_go = sum(s.n_samples for d in train_demos for s in d.segments("a") if s.mp == "a_go")
    assert counts["a/a_go"] == n_a_go


def test_batched_equals_single_and_shapes(fitted, test_demos):
    seq = fitted["klr"]
    x = test_demos[0].features[:7]
    batch = seq.progress(x)
    assert batch.shape == (7, len(seq.node_keys))
    single = np.stack([seq.progress(row) for row in x])
    np.testing.assert_allclose(batch, single, rtol=0, atol=1e-12)
    assert seq.progress(x.reshape(7, 1, 3)).shape == (7, 1, len(seq.node_keys))
    # a batch's rows do not depend on the batch they are in
    whole = seq.progress(test_demos[0].features)
    np.testing.assert_allclose(batch, whole[:7], rtol=0, atol=1e-12)


def _padded_logits(model, z):
    """Reference: logits from the dense padded kernel ``(B, K, S)``."""
    return torch.einsum("bks,ks->bk", model.kernel(z), model.weight) + model.bias


@pytest.mark.parametrize("kind", ["klr", "klr_full", "klr_sparse"])
def test_packed_logits_equal_padded_kernel(fitted, test_demos, kind):
    model = fitted[kind].predictor
    z = torch.as_tensor(test_demos[0].features)
    with torch.no_grad():
        np.testing.assert_allclose(model.logits(z), _padded_logits(model, z), atol=1e-10)


def test_packed_cache_follows_parameter_changes(fit_on_train, test_demos):
    seq = fit_on_train("klr_sparse")  # refined: moved supports
    model = seq.predictor
    z = torch.as_tensor(test_demos[0].features[:5])
    before = seq.progress(z.numpy())
    with torch.no_grad():
        model.weight.mul_(-1.0)
        model.log_feature_scale.add_(0.3)  # an older checkpoint's per-feature factors
        np.testing.assert_allclose(model.logits(z), _padded_logits(model, z), atol=1e-10)
    assert not np.allclose(seq.progress(z.numpy()), before)
    with torch.no_grad():  # edits through .data bypass the version counter: clear_cache
        cached = model.logits(z)
        model.weight.data[:, 0] = 0.0
        model.support.data = model.support.data + 0.1
        model.clear_cache()
        np.testing.assert_allclose(model.logits(z), _padded_logits(model, z), atol=1e-10)
        assert not np.allclose(model.logits(z), cached)
    clone = predictor_from_spec(model.spec())
    clone.load_state_dict(model.state_dict())
    with torch.no_grad():
        np.testing.assert_allclose(clone.logits(z), model.logits(z), atol=1e-12)


def test_keep_supports_drops_exactly_the_other_terms(fit_on_train, test_demos):
    model = fit_on_train("klr").predictor
    z = torch.as_tensor(test_demos[0].features[:9])
    with torch.no_grad():
        kernel, weight, bias = model.kernel(z), model.weight.clone(), model.bias.clone()
        model(z)  # the packed cache is built, and must not outlive the repacking
        mask = model.support_mask
        keep = mask & (torch.arange(mask.shape[1]) % 3 == 1)  # every third slot ...
        keep |= mask & (torch.cumsum(mask.long(), 1) == 1)  # ... and each node's first
        expected = torch.einsum("bks,ks->bk", kernel * keep, weight) + bias
        model.keep_supports(keep)
        assert model.support_mask.sum(1).tolist() == keep.sum(1).tolist()
        np.testing.assert_allclose(model.logits(z), expected, rtol=0, atol=1e-10)
        np.testing.assert_allclose(_padded_logits(model, z), expected, rtol=0, atol=1e-10)
    mask = model.support_mask
    assert not bool(mask.all())  # the nodes keep different counts: there is padding
    for bad, match in [
        (mask[:, :-1], "shape"),
        (torch.ones_like(mask), "padded"),
        (mask & (torch.arange(len(mask))[:, None] > 0), "without supports"),
    ]:
        with pytest.raises(DataError, match=match):
            model.keep_supports(bad)


def test_klr_gradients_flow_through_packed_logits(fitted, test_demos):
    model = fitted["klr"].predictor
    x = torch.as_tensor(test_demos[0].features[:4]).requires_grad_(True)
    model(x).sum().backward()
    assert model.weight.grad is not None and torch.isfinite(x.grad).all()
    assert x.grad.abs().sum() > 0
    model.zero_grad()


def test_klr_mlp_gradients_flow():
    model = make_predictor("mlp", [("v", "m")], 2)
    model.initialize([], torch.Generator().manual_seed(0))
    out = model(torch.ones(3, 2, dtype=torch.float64)).sum()
    out.backward()
    assert all(p.grad is not None for p in model.parameters())


def test_spec_round_trip(fitted):
    for seq in fitted.values():
        clone = predictor_from_spec(seq.predictor.spec())
        clone.load_state_dict(seq.predictor.state_dict())
        x = torch.rand(5, 3, dtype=torch.float64)
        assert torch.equal(clone(x), seq.predictor(x))


def test_feature_scaling_minmax_is_affine_invariant(train_demos, test_demos):
    shifted = [
        Demonstration(d.time, d.features * 50.0 + 3.0, d.labels, d.feature_names, d.name)
        for d in train_demos
    ]
    a = ConcurrentSequencer.fit(shifted, "klr", seed=0, logger=None, feature_scaling="minmax")
    b = ConcurrentSequencer.fit(train_demos, "klr", seed=0, logger=None, feature_scaling="minmax")
    lo = a.predictor.scaler.transform(shifted[0].features).min(0)
    assert lo.min() >= -1e-12
    np.testing.assert_allclose(
        a.progress(test_demos[0].features * 50.0 + 3.0),
        b.progress(test_demos[0].features),
        atol=1e-6,  # same problem up to float rounding of the affine map
    )


def test_bad_options():
    with pytest.raises(ConfigError, match="unknown predictor 'svm'"):
        make_predictor("svm", [("v", "m")], 2)
    with pytest.raises(ConfigError, match="unknown option"):
        make_predictor("klr", [("v", "m")], 2, gama=3.0)
    with pytest.raises(ConfigError, match="gamma must be > 0"):
        make_predictor("klr", [("v", "m")], 2, gamma=-1.0)
    with pytest.raises(ConfigError, match="max_support"):
        make_predictor("klr", [("v", "m")], 2, min_support=5, max_support=2)
    with pytest.raises(ConfigError, match="activation"):
        make_predictor("mlp", [("v", "m")], 2, activation="gelu2")
    model = make_predictor("klr", [("v", "m")], 2)
    with pytest.raises(DataError, match="2 entries"):
        model(torch.zeros(4, 3))


def test_path_feature_weighting(train_demos, test_demos):
    # add a nuisance feature, constant within each demo and different across demos
    rng = np.random.default_rng(0)
    noisy = [
        Demonstration(
            d.time,
            np.column_stack([d.features, np.full(d.n_samples, rng.uniform())]),
            d.labels,
            [*d.feature_names, "nuisance"],
            d.name,
        )
        for d in train_demos
    ]
    seq = ConcurrentSequencer.fit(
        noisy, "klr", seed=0, logger=None, feature_weighting="path", weight_floor=0.1
    )
    scale = seq.predictor.feature_scale
    a_go = seq.node_keys.index(("a", "a_go"))
    assert scale[a_go, 3] == pytest.approx(0.1)  # the nuisance never moves: floor weight
    assert scale[a_go, 2] == pytest.approx(0.1)  # nor does the context
    assert scale[a_go, 0] > 1.0  # p_a drives a_go's progress
    held_out = [
        Demonstration(
            d.time,
            np.column_stack([d.features, np.full(d.n_samples, 0.5)]),
            d.labels,
            [*d.feature_names, "nuisance"],
            d.name,
        )
        for d in test_demos
    ]
    assert progress_errors(activation_progress(seq, held_out))["mae"] < MAE_BOUND
    with pytest.raises(ConfigError, match="feature_weighting"):
        make_predictor("klr", [("v", "m")], 2, feature_weighting="auto")
