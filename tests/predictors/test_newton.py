"""Newton (IRLS) solver of the convex KLR fit: same optimum as LBFGS, zero gradient, hard
nodes, trainer options."""

import numpy as np
import pytest
import torch

from cpmp.errors import ConfigError
from cpmp.predictors.newton import newton_fit, newton_solve, penalised_loss
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
    assert newton.fit_summary["solver"] == "newton" and newton.fit_summary["epochs"] == 1
    assert newton.fit_summary["newton_converged"]
    assert lbfgs.fit_summary["solver"] == "lbfgs" and "newton_iterations" not in lbfgs.fit_summary
    loss_n, loss_l = newton.fit_summary["loss"], lbfgs.fit_summary["loss"]
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
    assert seq.fit_summary["newton_grad_max"] <= 1e-10


def test_newton_refit_of_sparse_klr_matches_lbfgs(train_demos):
    fits = {
        solver: ConcurrentSequencer.fit(
            train_demos,
            "klr_sparse",
            seed=0,
            logger=None,
            epochs=30,
            solver=solver,
            method="l1",
            l2=1e-4,  # the L1 variant of klr_sparse, at klr's L2 weight
        )
        for solver in ("newton", "lbfgs")
    }
    newton, lbfgs = fits["newton"], fits["lbfgs"]
    assert newton.fit_summary["solver"] == "adam"  # the L1 phase stays on Adam
    assert newton.fit_summary["support_counts"] == lbfgs.fit_summary["support_counts"]
    assert newton.predictor.refit_info and all(i.converged for i in newton.predictor.refit_info)
    # the re-fit objective: the penalised loss without the L1 term, on the kept supports
    refit_loss = {}
    for solver, seq in fits.items():
        data = node_training_data(seq.graphs, seq.predictor)
        with torch.no_grad():
            refit_loss[solver] = float(seq.predictor._penalised_loss(data, seq.predictor._cache))
    assert refit_loss["newton"] == pytest.approx(refit_loss["lbfgs"], rel=1e-6)
    assert refit_loss["newton"] <= refit_loss["lbfgs"] + 1e-12


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
    assert seq.fit_summary["loss"] == pytest.approx(klr_fits["newton"].fit_summary["loss"], 1e-5)


def test_bad_solver_option_stops_a_fit(train_demos):
    with pytest.raises(ConfigError, match="solver"):
        ConcurrentSequencer.fit(train_demos, "klr", logger=None, solver="bfgs")
    assert TrainerConfig(newton_max_iter=5.0).newton_max_iter == 5


def test_newton_iteration_cap_is_reported(train_demos):
    seq = ConcurrentSequencer.fit(train_demos, "klr", seed=0, logger=None, newton_max_iter=1)
    assert seq.fit_summary["newton_iterations"] == 1
    assert not seq.fit_summary["newton_converged"]
    assert seq.fit_summary["newton_grad_max"] > 1e-10
