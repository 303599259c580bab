"""The inducing-point refinement (cpmp.predictors.inducing): its written-out gradient, that it
never ends worse than it started, and what it leaves alone."""

from __future__ import annotations

import dataclasses

import pytest
import torch

from cpmp.predictors.inducing import RefineProblem, _Objective, padded_samples, refine


@pytest.fixture
def problem() -> RefineProblem:
    """Three nodes, 1-D progress along a line in 2-D with the second feature irrelevant; the
    second node has one padded support slot, the third fewer samples (padded rows)."""
    gen = torch.Generator().manual_seed(0)
    k, p, s = 3, 40, 4
    t = torch.linspace(0.0, 1.0, p, dtype=torch.float64)
    x = torch.stack(
        [torch.stack([4.0 * t, torch.rand(p, generator=gen, dtype=torch.float64)], 1)] * k
    )
    weight = torch.full((k, p), 1.0 / p, dtype=torch.float64)
    weight[2, 30:] = 0.0
    weight[2, :30] = 1.0 / 30
    x[2, 30:] = 0.0
    mask = torch.ones(k, s, dtype=torch.bool)
    mask[1, 3] = False
    support = x[:, [2, 14, 26, 38]].clone() * mask[:, :, None]
    return RefineProblem(
        x=x,
        target=t.expand(k, p).clone() * (weight > 0),
        sample_weight=weight,
        support=support,
        mask=mask,
        base_weights=torch.tensor([[0.5, 0.5]] * k, dtype=torch.float64),
        weight=torch.zeros(k, s, dtype=torch.float64),
        bias=torch.zeros(k, dtype=torch.float64),
    )


def _reference_loss(problem, theta, l2, anchor):
    """The penalised loss written independently in torch (differences, torch's BCE)."""
    k, s, d = problem.support.shape
    sizes = [k * s * d, k * d, k * s, k]
    u, log_scale, weight, bias = torch.split(theta, sizes)
    a0 = problem.base_weights
    unit = torch.where(a0 > 0, a0.sqrt(), torch.ones_like(a0))[:, None, :]
    support = u.view(k, s, d) / unit
    a = problem.base_weights * torch.exp(log_scale.view(k, d).clamp_max(0.0))  # widen only
    diff = problem.x[:, :, None, :] - support[:, None, :, :]  # (K, P, S, d)
    kern = torch.exp(-(a[:, None, None, :] * diff * diff).sum(-1)) * problem.mask[:, None, :]
    w = weight.view(k, s) * problem.mask
    z = (kern * w[:, None, :]).sum(-1) + bias[:, None]
    bce = torch.nn.functional.binary_cross_entropy_with_logits(z, problem.target, reduction="none")
    u0 = (problem.support * unit).reshape(-1)
    return (
        (problem.sample_weight * bce).sum()
        + 0.5 * l2 * (w * w).sum()
        + anchor * ((u - u0) ** 2).sum()
    )


@pytest.mark.parametrize("weights", [(0.5, 0.5), (0.5, 0.0)], ids=["both", "one_weighed_0"])
def test_gradient_is_the_loss_derivative(problem, weights):
    """Also with a feature the kernel weighs 0 (no width to step the supports in)."""
    problem = dataclasses.replace(
        problem, base_weights=torch.tensor([weights] * 3, dtype=torch.float64)
    )
    objective = _Objective(problem, l2=1e-3, fit_bias=True, anchor=0.3)
    gen = torch.Generator().manual_seed(1)
    theta = objective.pack(
        problem.support
        + 0.1 * torch.randn(problem.support.shape, generator=gen, dtype=torch.float64),
        0.3 * torch.randn(3, 2, generator=gen, dtype=torch.float64),
        torch.randn(3, 4, generator=gen, dtype=torch.float64) * problem.mask,
        torch.randn(3, generator=gen, dtype=torch.float64),
    )
    loss, grad = objective(theta)
    leaf = theta.clone().requires_grad_(True)
    reference = _reference_loss(problem, leaf, l2=1e-3, anchor=0.3)
    (auto,) = torch.autograd.grad(reference, leaf)
    assert bool(torch.isfinite(loss)) and bool(torch.isfinite(grad).all())
    assert float(loss) == pytest.approx(float(reference.detach()), rel=1e-12)
    torch.testing.assert_close(grad, auto, rtol=1e-9, atol=1e-12)


def test_refinement_lowers_the_loss_and_leaves_padding_alone(problem):
    result = refine(problem, l2=1e-4, max_iter=40)
    assert result.evaluations > 0
    assert result.loss < 0.9 * result.loss_start
    # the padded slot keeps its place and a zero weight
    assert torch.equal(result.support[1, 3], problem.support[1, 3])
    assert float(result.weight[1, 3]) == 0.0
    # the irrelevant second feature's kernel widens, more than the first's
    assert bool((result.log_scale[:, 1] < result.log_scale[:, 0]).all())
    assert bool((result.log_scale <= 0.0).all())


def test_a_kernel_is_widened_but_never_narrowed(problem):
    """With a kernel far too wide for the progress along the first feature, the loss asks to
    narrow it: the factor stays at 1 (ℓ = 0) and the supports and weights learn instead."""
    wide = dataclasses.replace(
        problem, base_weights=torch.tensor([[0.005, 0.5]] * 3, dtype=torch.float64)
    )
    objective = _Objective(wide, l2=1e-4, fit_bias=True)
    k, s, d = wide.support.shape
    log_scale = torch.zeros(k, d, dtype=torch.float64)
    weight = torch.full((k, s), 0.5, dtype=torch.float64) * wide.mask
    _, grad = objective(objective.pack(wide.support, log_scale, weight, wide.bias))
    g_l = objective.unpack(grad)[1]  # the gradient's ℓ part, (K, d)
    assert bool((g_l[:, 0] < 0).all())  # a narrower kernel in the first feature lowers the loss
    result = refine(wide, l2=1e-4, max_iter=40)
    assert result.loss < result.loss_start
    assert torch.count_nonzero(result.log_scale[:, 0]) == 0  # held at the fixed rule's width
    assert bool((result.log_scale <= 0.0).all())


def test_a_feature_weighed_zero_is_left_alone_and_the_rest_refined(problem):
    """A path weight of 0 (a feature constant along a node's activations) gives that feature
    no kernel width: the refinement still runs (it once divided by the width, 0, and its
    loss was NaN from the start, so it silently kept the start) and leaves the feature's
    support coordinates and kernel scale where they were."""
    ignored = dataclasses.replace(
        problem, base_weights=torch.tensor([[0.5, 0.0]] * 3, dtype=torch.float64)
    )
    result = refine(ignored, l2=1e-4, max_iter=40)
    assert result.loss < 0.9 * result.loss_start  # refined, not the start kept
    torch.testing.assert_close(result.support[..., 1], ignored.support[..., 1], rtol=0, atol=0)
    assert torch.count_nonzero(result.log_scale[:, 1]) == 0
    assert bool((result.support[..., 0] != ignored.support[..., 0]).any())


def test_no_iterations_return_the_start(problem):
    result = refine(problem, l2=1e-4, max_iter=0)
    assert result.evaluations == 0 and result.loss == result.loss_start
    assert torch.equal(result.support, problem.support)
    assert torch.count_nonzero(result.log_scale) == 0


def test_fixed_bias_stays(problem):
    result = refine(problem, l2=1e-4, max_iter=20, fit_bias=False)
    assert torch.count_nonzero(result.bias) == 0


def test_padded_samples_stride_and_weights():
    xs = [torch.arange(10.0).reshape(5, 2), torch.arange(4.0).reshape(2, 2)]
    ys = [torch.linspace(0, 1, 5), torch.tensor([0.0, 1.0])]
    x, y, c = padded_samples(xs, ys, per_node=3)
    assert x.shape == (2, 3, 2) and x.dtype == torch.float64
    torch.testing.assert_close(x[0], xs[0][::2].double())  # every 2nd of 5: 3 rows
    torch.testing.assert_close(y[0], ys[0][::2].double())
    torch.testing.assert_close(c[0], torch.full((3,), 1.0 / 3, dtype=torch.float64))
    assert c[1].tolist() == [0.5, 0.5, 0.0]  # two rows and a padded one


def test_anchor_pulls_the_supports_back(problem):
    free = refine(problem, l2=1e-4, max_iter=40)
    held = refine(problem, l2=1e-4, max_iter=40, anchor=100.0)
    moved_free = (free.support - problem.support).abs().max()
    moved_held = (held.support - problem.support).abs().max()
    assert moved_held < 0.1 * moved_free
    assert held.loss < held.loss_start  # the weights and scales still learn
