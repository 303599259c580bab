"""Damped Newton (IRLS) solver for L2-penalised soft-label kernel logistic regression.

For a fixed kernel, each node's loss is convex in its weights and bias:

``f(w, b) = Σ_i c_i [softplus(z_i) - y_i z_i] + ½ l2 ||w||²``,  ``z = K w + b``

with ``K (n, S)`` the node's kernel matrix, soft labels ``y ∈ [0, 1]``, sample weights ``c``
(``1/n`` each: the mean binary cross-entropy) and an unpenalised bias. Its gradient and Hessian
in ``θ = (w, b)`` are ``Xᵀ c(p - y) + l2 w`` and ``Xᵀ diag(c p (1 - p)) X + l2 I_w`` with
``X = [K, 1]`` and ``p = σ(z)``. The nodes are independent problems, solved one after the other;
each Newton step costs one ``(S+1)²`` Cholesky factorisation, and a few steps reach the optimum
to float64 precision.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from cpmp.config.trainer import TrainerConfig

NEWTON_TOL = TrainerConfig.newton_tol
"""Default stopping tolerance on the gradient's max-norm and on the Newton decrement (the
trainer's ``newton_tol``)."""
NEWTON_MAX_ITER = TrainerConfig.newton_max_iter
"""Default cap on Newton iterations per node (the trainer's ``newton_max_iter``)."""

_ARMIJO = 1e-4
_MAX_HALVINGS = 60
_EPS = torch.finfo(torch.float64).eps


@dataclass(frozen=True)
class NewtonInfo:
    """Outcome of one node's Newton solve.

    Attributes:
        iterations: Newton steps taken.
        grad_max: max-norm of the gradient at the returned point.
        decrement: Newton decrement ``λ`` at the returned point (``λ²/2`` estimates the gap
            to the optimal loss); ``nan`` when the solve stopped on the gradient test.
        loss: the node's penalised loss at the returned point.
        converged: a stopping test held (else the iteration cap or the line search ended it).
    """

    iterations: int
    grad_max: float
    decrement: float
    loss: float
    converged: bool


def bce_terms(z: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
    """Per-sample soft-label BCE ``(n,)`` from logits ``z (n,)`` and labels ``y (n,)``.

    Computed as :func:`torch.nn.functional.binary_cross_entropy_with_logits` does (no
    softplus cut-off).
    """
    return z.clamp_min(0.0) - z * y + torch.log1p(torch.exp(-z.abs()))


def penalised_loss(
    kernel: torch.Tensor,
    target: torch.Tensor,
    weight: torch.Tensor,
    w: torch.Tensor,
    b: torch.Tensor | float,
    l2: float,
) -> torch.Tensor:
    """``Σ c_i BCE(K w + b, y)_i + ½ l2 ||w||²`` for ``K (n, S)``, ``y, c (n,)``, ``w (S,)``."""
    z = kernel @ w + b
    return (weight * bce_terms(z, target)).sum() + 0.5 * l2 * (w @ w)


def newton_direction(hessian: torch.Tensor, grad: torch.Tensor) -> torch.Tensor:
    """The Newton direction ``-H⁻¹ g``.

    By Cholesky; if ``H`` is not numerically positive definite, with growing diagonal
    jitter, and as a last resort by least squares.
    """
    chol, info = torch.linalg.cholesky_ex(hessian)
    if int(info) == 0:
        return -torch.cholesky_solve(grad[:, None], chol)[:, 0]
    eye = torch.eye(hessian.shape[0], dtype=hessian.dtype, device=hessian.device)
    jitter = 1e-12 * max(float(hessian.diagonal().abs().max()), 1.0)
    for _ in range(8):
        chol, info = torch.linalg.cholesky_ex(hessian + jitter * eye)
        if int(info) == 0:
            return -torch.cholesky_solve(grad[:, None], chol)[:, 0]
        jitter *= 100.0
    return -torch.linalg.lstsq(hessian, grad[:, None], driver="gelsd").solution[:, 0]


def newton_solve(
    kernel: torch.Tensor,
    target: torch.Tensor,
    l2: float,
    weight: torch.Tensor | None = None,
    w0: torch.Tensor | None = None,
    b0: float = 0.0,
    fit_bias: bool = True,
    tol: float = NEWTON_TOL,
    max_iter: int = NEWTON_MAX_ITER,
) -> tuple[torch.Tensor, float, NewtonInfo]:
    """Minimise one node's penalised loss by damped Newton steps (float64).

    Args:
        kernel: ``(n, S)`` kernel matrix of the node's samples against its supports.
        target: ``(n,)`` soft labels in [0, 1].
        l2: weight of ``½ l2 ||w||²`` (the bias is not penalised).
        weight: ``(n,)`` per-sample weights ``c``; ``None``: ``1/n`` each (mean BCE).
        w0: ``(S,)`` starting weights (``None``: zeros).
        b0: starting bias, kept fixed when ``fit_bias`` is off.
        fit_bias: optimise the bias too.
        tol: stop when ``max|g| <= tol`` or the Newton decrement ``λ <= tol``.
        max_iter: Newton steps at most.

    Returns:
        ``(w (S,), b, info)``, ``w`` in float64.
    """
    k = kernel.detach().to(torch.float64)
    n, s = k.shape
    f64 = {"dtype": torch.float64, "device": k.device}
    y = target.detach().to(**f64)
    c = torch.full((n,), 1.0 / max(n, 1), **f64) if weight is None else weight
    c = c.detach().to(**f64)
    x = torch.cat([k, torch.ones(n, 1, **f64)], 1) if fit_bias else k
    reg = torch.full((x.shape[1],), float(l2), **f64)
    if fit_bias:
        reg[-1] = 0.0
    theta = torch.zeros(x.shape[1], **f64)
    if w0 is not None:
        theta[:s] = w0.detach().to(**f64)
    offset = 0.0 if fit_bias else float(b0)
    if fit_bias:
        theta[-1] = float(b0)

    def loss_at(t: torch.Tensor) -> float:
        z = x @ t + offset
        return float((c * bce_terms(z, y)).sum() + 0.5 * (reg * t * t).sum())

    loss = loss_at(theta)
    grad_max, decrement, converged, iterations = float("inf"), float("nan"), False, 0
    for it in range(max_iter + 1):
        z = x @ theta + offset
        p = torch.sigmoid(z)
        grad = x.T @ (c * (p - y)) + reg * theta
        grad_max = float(grad.abs().max()) if grad.numel() else 0.0
        decrement = float("nan")
        if grad_max <= tol:
            converged = True
            break
        curvature = c * p * torch.sigmoid(-z)
        hessian = (x.T * curvature) @ x + torch.diag(reg)
        direction = newton_direction(hessian, grad)
        slope = float(grad @ direction)
        decrement = max(-slope, 0.0) ** 0.5
        if decrement <= tol:
            converged = True
            break
        if it == max_iter or slope >= 0.0:
            break
        step, slack = 1.0, 16.0 * _EPS * abs(loss)
        for _ in range(_MAX_HALVINGS):
            candidate = theta + step * direction
            new_loss = loss_at(candidate)
            if new_loss <= loss + _ARMIJO * step * slope + slack:
                break
            step *= 0.5
        else:
            break
        theta, loss, iterations = candidate, new_loss, it + 1
    w = theta[:s].clone()
    b = float(theta[-1]) if fit_bias else float(b0)
    info = NewtonInfo(iterations, grad_max, decrement, loss, converged)
    return w, b, info


def newton_fit(
    kernels: list[torch.Tensor],
    targets: list[torch.Tensor],
    l2: float,
    weights: list[torch.Tensor] | None = None,
    init: list[tuple[torch.Tensor, float]] | None = None,
    fit_bias: bool = True,
    tol: float = NEWTON_TOL,
    max_iter: int = NEWTON_MAX_ITER,
) -> tuple[list[tuple[torch.Tensor, float]], list[NewtonInfo]]:
    """Solve every node's problem (see :func:`newton_solve`) independently.

    Args:
        kernels: per node ``(n_k, S_k)`` kernel matrices (real supports only, no padding).
        targets: per node ``(n_k,)`` soft labels.
        l2: L2 weight on ``w``, shared by all nodes.
        weights: per node ``(n_k,)`` sample weights (``None``: the mean over samples).
        init: per node starting ``(w (S_k,), b)`` (``None``: zeros).
        fit_bias: optimise the biases too (as in :func:`newton_solve`).
        tol: the stopping tolerance (as in :func:`newton_solve`).
        max_iter: Newton steps per node at most.

    Returns:
        Per node ``(w (S_k,) float64, b)`` and a :class:`NewtonInfo`.
    """
    solutions: list[tuple[torch.Tensor, float]] = []
    infos: list[NewtonInfo] = []
    for i, (kernel, target) in enumerate(zip(kernels, targets, strict=True)):
        w0, b0 = init[i] if init is not None else (None, 0.0)
        w, b, info = newton_solve(
            kernel,
            target,
            l2,
            None if weights is None else weights[i],
            w0,
            b0,
            fit_bias,
            tol,
            max_iter,
        )
        solutions.append((w, b))
        infos.append(info)
    return solutions, infos
