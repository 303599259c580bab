"""Newton (IRLS) solver of the convex KLR fit: same optimum as LBFGS, zero gradient, hard
nodes, trainer options; the kernel streamed in blocks of samples."""

import itertools

import numpy as np
import pytest
import torch

from cpmp.errors import ConfigError
from cpmp.predictors.newton import (
    bce_terms,
    block_bounds,
    newton_direction,
    newton_fit,
    newton_solve,
    newton_solve_blocks,
    penalised_loss,
)
from cpmp.predictors.training import TrainerConfig
from cpmp.sequencer.fit_data import node_training_data
from cpmp.sequencer.sequencer import ConcurrentSequencer


@pytest.fixture(scope="module")
def klr_fits(train_demos):
    return {
        solver: ConcurrentSequencer.fit(train_demos, "klr", seed=0, logger=None, solver=solver)
        for solver in ("newton", "lbfgs")
    }


def _gradient_max(kernel, target, w, b, l2, fit_bias=True):
    """Max-norm of the autograd gradient of the mean BCE + ½ l2 ||w||² at ``(w, b)``."""
    w = w.clone().requires_grad_(True)
    b = torch.tensor(b, dtype=torch.float64, requires_grad=fit_bias)
    logits = kernel @ w + b
    loss = torch.nn.functional.binary_cross_entropy_with_logits(logits, target)
    (loss + 0.5 * l2 * (w * w).sum()).backward()
    grads = [w.grad] + ([b.grad.reshape(1)] if fit_bias else [])
    return float(torch.cat(grads).abs().max())


def _rbf(x, s, gamma=4.0):
    return torch.exp(-gamma * torch.cdist(x, s) ** 2)


def test_newton_matches_lbfgs_loss_and_progress(klr_fits, test_demos):
    newton, lbfgs = klr_fits["newton"], klr_fits["lbfgs"]
    assert newton.fit_summary.solver == "newton" and newton.fit_summary.epochs == 1
    assert newton.fit_summary.newton.converged
    assert lbfgs.fit_summary.solver == "lbfgs" and lbfgs.fit_summary.newton is None
    loss_n, loss_l = newton.fit_summary.loss, lbfgs.fit_summary.loss
    assert loss_n == pytest.approx(loss_l, rel=1e-6)
    assert loss_n <= loss_l + 1e-12  # Newton's optimum is at least as low as LBFGS's
    x = np.concatenate([d.features for d in test_demos])
    np.testing.assert_allclose(newton.progress(x), lbfgs.progress(x), rtol=0, atol=1e-4)


def test_gradient_vanishes_at_the_newton_solution(klr_fits):
    seq = klr_fits["newton"]
    model = seq.predictor
    data = node_training_data(seq.graphs, model)
    model._cache = None
    model.zero_grad()
    with torch.enable_grad():
        model.training_loss(data).backward()
    grad = torch.cat([(model.weight.grad * model.support_mask).flatten(), model.bias.grad])
    assert float(grad.abs().max()) < 1e-9
    model.zero_grad()
    # the same check with LBFGS's stopping rule would not be near this small
    assert seq.fit_summary.newton.grad_max <= 1e-10


def test_random_problem_gradient_is_zero_and_weights_respected():
    gen = torch.Generator().manual_seed(0)
    x = torch.rand(60, 2, generator=gen, dtype=torch.float64)
    kernel = _rbf(x, x[::4])
    target = torch.sigmoid(3.0 * (x[:, 0] - x[:, 1]))
    w, b, info = newton_solve(kernel, target, 1e-3)
    assert info.converged and info.iterations < 20
    assert _gradient_max(kernel, target, w, b, 1e-3) < 1e-10
    # sample weights 1/n reproduce the default mean; doubled weights change the optimum
    w_same, _, _ = newton_solve(
        kernel, target, 1e-3, weight=torch.full((60,), 1 / 60, dtype=torch.float64)
    )
    torch.testing.assert_close(w_same, w, rtol=0, atol=1e-10)
    w_heavy, _, _ = newton_solve(
        kernel, target, 1e-3, weight=torch.full((60,), 2 / 60, dtype=torch.float64)
    )
    assert float((w_heavy - w).abs().max()) > 1e-3
    # a fixed bias stays fixed and the weight gradient still vanishes
    w_fixed, b_fixed, info = newton_solve(kernel, target, 1e-3, b0=0.25, fit_bias=False)
    assert b_fixed == 0.25 and info.converged
    assert _gradient_max(kernel, target, w_fixed, 0.25, 1e-3, fit_bias=False) < 1e-10


def test_nodes_with_equal_labels_and_two_samples():
    gen = torch.Generator().manual_seed(1)
    x = torch.rand(30, 2, generator=gen, dtype=torch.float64)
    kernel = _rbf(x, x[:5])
    tiny_x = torch.tensor([[0.1, 0.2], [0.8, 0.7]], dtype=torch.float64)
    tiny_target = torch.tensor([0.2, 0.9], dtype=torch.float64)
    solutions, infos = newton_fit(
        [kernel, kernel, kernel, _rbf(tiny_x, tiny_x)],
        [torch.full((30,), 0.3), torch.zeros(30), torch.ones(30), tiny_target],
        1e-4,
    )
    for (w, b), info in zip(solutions, infos, strict=True):
        assert torch.isfinite(w).all() and np.isfinite(b) and np.isfinite(info.loss)
        assert info.converged
    # constant soft labels: the bias alone fits them, the penalty keeps w at zero
    w, b = solutions[0]
    assert float(w.abs().max()) < 1e-8 and torch.sigmoid(torch.tensor(b)) == pytest.approx(0.3)
    # all-0 / all-1 labels have no finite optimum; the loss is driven to ~0 without overflow
    assert infos[1].loss < 1e-8 and infos[2].loss < 1e-8
    assert solutions[1][1] < 0 < solutions[2][1]
    w, b = solutions[3]
    assert _gradient_max(_rbf(tiny_x, tiny_x), tiny_target, w, b, 1e-4) < 1e-10


@pytest.mark.parametrize("l2", [1e-4, 0.0])
def test_duplicated_supports_stay_finite(l2):
    gen = torch.Generator().manual_seed(2)
    x = torch.rand(40, 2, generator=gen, dtype=torch.float64)
    target = 0.1 + 0.8 * torch.rand(40, generator=gen, dtype=torch.float64)
    unique = x[:6]
    duplicated = torch.cat([unique, unique, unique[:2] + 1e-12])
    w_u, b_u, info_u = newton_solve(_rbf(x, unique), target, l2)
    w_d, b_d, info_d = newton_solve(_rbf(x, duplicated), target, l2)
    assert torch.isfinite(w_d).all() and np.isfinite(b_d) and info_d.converged
    assert _gradient_max(_rbf(x, duplicated), target, w_d, b_d, l2) < 1e-9
    if l2 == 0.0:
        # unpenalised, duplicating supports does not change the optimal logits and loss
        assert info_d.loss == pytest.approx(info_u.loss, rel=1e-9)
        logits_u = _rbf(x, unique) @ w_u + b_u
        logits_d = _rbf(x, duplicated) @ w_d + b_d
        torch.testing.assert_close(logits_d, logits_u, rtol=0, atol=1e-5)
    else:
        # penalised, splitting a weight over copies halves its penalty: a lower optimum
        assert info_d.loss < info_u.loss
    direct = penalised_loss(
        _rbf(x, duplicated), target, torch.full((40,), 1 / 40, dtype=torch.float64), w_d, b_d, l2
    )
    assert float(direct) == pytest.approx(info_d.loss, rel=1e-12)


def test_float32_predictor_uses_newton(train_demos, klr_fits):
    seq = ConcurrentSequencer.fit(train_demos, "klr", seed=0, logger=None, dtype="float32")
    assert seq.predictor.weight.dtype == torch.float32
    assert seq.fit_summary.loss == pytest.approx(klr_fits["newton"].fit_summary.loss, 1e-5)


def test_bad_solver_option_stops_a_fit(train_demos):
    with pytest.raises(ConfigError, match="solver"):
        ConcurrentSequencer.fit(train_demos, "klr", logger=None, solver="bfgs")
    assert TrainerConfig(newton_max_iter=5.0).newton_max_iter == 5


def test_newton_iteration_cap_is_reported(train_demos):
    seq = ConcurrentSequencer.fit(train_demos, "klr", seed=0, logger=None, newton_max_iter=1)
    assert seq.fit_summary.newton.iterations == 1
    assert not seq.fit_summary.newton.converged
    assert seq.fit_summary.newton.grad_max > 1e-10


def _problem(n=300, s=25, seed=3):
    """A random RBF problem ``(kernel (n, s), soft labels (n,))`` in float64."""
    gen = torch.Generator().manual_seed(seed)
    x = torch.rand(n, 2, generator=gen, dtype=torch.float64)
    support = torch.rand(s, 2, generator=gen, dtype=torch.float64)
    target = torch.sigmoid(3.0 * (x[:, 0] - x[:, 1]) + 0.3 * torch.randn(n, generator=gen))
    return _rbf(x, support), target.double()


@pytest.mark.parametrize("n", [0, 1, 7, 64, 65])
def test_block_bounds_cover_the_samples_in_order(n):
    for rows in (None, 1, 8, 64, 1000):
        bounds = block_bounds(n, rows)
        assert bounds[0][0] == 0 and bounds[-1][1] == n
        assert all(a[1] == b[0] for a, b in itertools.pairwise(bounds))
        assert all(0 < stop - start <= (rows or n) for start, stop in bounds) or n == 0


def _reference_solve(kernel, target, l2, weight=None, b0=0.0, fit_bias=True, tol=1e-10):
    """The solver as it was before the kernel was streamed: one kernel, a pass per use."""
    n, s = kernel.shape
    y, c = target, torch.full((n,), 1.0 / n, dtype=torch.float64) if weight is None else weight
    x = torch.cat([kernel, torch.ones(n, 1, dtype=torch.float64)], 1) if fit_bias else kernel
    reg = torch.full((x.shape[1],), float(l2), dtype=torch.float64)
    if fit_bias:
        reg[-1] = 0.0
    theta = torch.zeros(x.shape[1], dtype=torch.float64)
    offset = 0.0 if fit_bias else float(b0)
    if fit_bias:
        theta[-1] = float(b0)

    def loss_at(t):
        z = x @ t + offset
        return float((c * bce_terms(z, y)).sum() + 0.5 * (reg * t * t).sum())

    loss = loss_at(theta)
    for _ in range(101):
        z = x @ theta + offset
        p = torch.sigmoid(z)
        grad = x.T @ (c * (p - y)) + reg * theta
        if float(grad.abs().max()) <= tol:
            break
        hessian = (x.T * (c * p * torch.sigmoid(-z))) @ x + torch.diag(reg)
        direction = newton_direction(hessian, grad)
        slope = float(grad @ direction)
        if max(-slope, 0.0) ** 0.5 <= tol:
            break
        step, slack = 1.0, 16.0 * torch.finfo(torch.float64).eps * abs(loss)
        while (new_loss := loss_at(theta + step * direction)) > loss + 1e-4 * step * slope + slack:
            step *= 0.5
        theta, loss = theta + step * direction, new_loss
    return theta[:s], (float(theta[-1]) if fit_bias else float(b0)), loss


@pytest.mark.parametrize("fit_bias", [True, False])
def test_one_block_gives_the_unstreamed_solvers_numbers_to_the_bit(fit_bias):
    kernel, target = _problem()
    w_ref, b_ref, loss_ref = _reference_solve(kernel, target, 1e-3, b0=0.2, fit_bias=fit_bias)
    w, b, info = newton_solve(kernel, target, 1e-3, b0=0.2, fit_bias=fit_bias)
    w1, b1, info1 = newton_solve_blocks(
        lambda a, c: kernel[a:c], *kernel.shape, target, 1e-3, b0=0.2, fit_bias=fit_bias,
        block_rows=len(target),
    )  # fmt: skip
    assert torch.equal(w, w_ref) and b == b_ref and info.loss == loss_ref
    assert torch.equal(w1, w_ref) and b1 == b_ref and info1.loss == loss_ref
    assert info1.iterations == info.iterations and info1.grad_max == info.grad_max


@pytest.mark.parametrize("fit_bias", [True, False])
@pytest.mark.parametrize("rows", [1, 7, 64, 299])
def test_blocks_reach_the_whole_kernel_optimum(rows, fit_bias):
    kernel, target = _problem()
    weight = torch.linspace(0.5, 1.5, len(target), dtype=torch.float64) / len(target)
    *_, info = newton_solve(kernel, target, 1e-3, weight=weight, b0=0.2, fit_bias=fit_bias)
    seen = []

    def rows_of(a, c):
        seen.append(c - a)
        return kernel[a:c].float().double()  # any dtype: taken to float64

    wb, bb, infob = newton_solve_blocks(
        rows_of, *kernel.shape, target, 1e-3, weight=weight, b0=0.2, fit_bias=fit_bias,
        block_rows=rows,
    )  # fmt: skip
    assert max(seen) <= rows  # no evaluation is larger than a block
    kernel32 = kernel.float().double()
    w32, b32, _ = newton_solve(kernel32, target, 1e-3, weight=weight, b0=0.2, fit_bias=fit_bias)
    # the same problem summed in another order: equal to rounding (1e-10 is 10^5 ulps of 1)
    assert torch.allclose(wb, w32, atol=1e-10, rtol=0) and abs(bb - b32) < 1e-10
    assert infob.converged and infob.iterations == info.iterations
