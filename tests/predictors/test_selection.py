"""Greedy forward selection along a sparsity path (cpmp.predictors.selection): nested models,
one support per node first, and the exact Newton solution once every candidate is in."""

from __future__ import annotations

import itertools

import pytest
import torch

from cpmp.predictors.newton import newton_solve
from cpmp.predictors.selection import NodeProblem, forward_selection_path


def _problem(seed: int, n_candidates: int, n: int, n_val: int = 0) -> NodeProblem:
    """A 1-D ramp: samples along [0, 1] labelled by their position, RBF candidates."""
    g = torch.Generator().manual_seed(seed)
    x = torch.rand(n, generator=g, dtype=torch.float64).sort().values
    centres = torch.linspace(0.0, 1.0, n_candidates, dtype=torch.float64)
    xv = torch.rand(n_val, generator=g, dtype=torch.float64)

    def kernel(z: torch.Tensor) -> torch.Tensor:
        return torch.exp(-20.0 * (centres[:, None] - z[None, :]) ** 2)

    return NodeProblem(kernel(x), x.clone(), kernel(xv), xv.clone())


def test_path_is_nested_and_reaches_the_full_newton_solution():
    problems = [_problem(0, 6, 200, 50), _problem(1, 9, 250, 0)]
    points = forward_selection_path(problems, [2, 5, 15], l2=1e-4)
    assert [p.n_support for p in points] == [2, 5, 15]
    assert [len(m.support) for m in points[0].models] == [1, 1]  # one support per node first
    for early, late in itertools.pairwise(points):
        for a, b in zip(early.models, late.models, strict=True):
            assert torch.equal(b.support[: len(a.support)], a.support)
    assert points[1].train_loss < points[0].train_loss
    assert points[0].val_loss is not None and points[0].val_mae is not None
    # every candidate in: the weights are the Newton solution on the scored samples (here
    # all of them), to the checkpoint tolerance
    for problem, model in zip(problems, points[-1].models, strict=True):
        assert sorted(model.support.tolist()) == list(range(problem.kernel.shape[0]))
        w, b, _ = newton_solve(problem.kernel[model.support].T, problem.target, 1e-4)
        torch.testing.assert_close(model.weight, w, rtol=0, atol=1e-6)
        assert model.bias == pytest.approx(b, abs=1e-6)


def test_candidates_running_out_end_the_path():
    points = forward_selection_path([_problem(0, 3, 100)], [2, 10, 20], l2=1e-4)
    assert [p.n_support for p in points] == [2, 3]
    assert points[-1].val_loss is None and points[-1].val_mae is None
