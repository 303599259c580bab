"""Damped Newton (IRLS) solver for L2-penalised soft-label kernel logistic regression.

For a fixed kernel, each node's loss is convex in its weights and bias:

``f(w, b) = Σ_i c_i [softplus(z_i) - y_i z_i] + ½ l2 ||w||²``,  ``z = K w + b``

with ``K (n, S)`` the node's kernel matrix, soft labels ``y ∈ [0, 1]``, sample weights ``c``
(``1/n`` each: the mean binary cross-entropy) and an unpenalised bias. Its gradient and Hessian
in ``θ = (w, b)`` are ``Xᵀ c(p - y) + l2 w`` and ``Xᵀ diag(c p (1 - p)) X + l2 I_w`` with
``X = [K, 1]`` and ``p = σ(z)``. The nodes are independent problems, solved one after the other;
each Newton step costs one ``(S+1)²`` Cholesky factorisation, and a few steps reach the optimum
to float64 precision. The loss, gradient and Hessian are sums over samples:
:func:`newton_solve_blocks` accumulates them over blocks of kernel rows, so that memory does
not grow with the samples (:func:`newton_solve` is its one-block case).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
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


KernelRows = Callable[[int, int], torch.Tensor]
"""``rows(start, stop)``: the kernel ``(stop - start, S)`` of samples ``start:stop`` against the
supports (any float dtype and device; it is detached and taken to float64)."""


def block_bounds(n: int, rows: int | None) -> list[tuple[int, int]]:
    """``[(start, stop), ...]`` covering ``range(n)`` in blocks of at most ``rows`` samples.

    Args:
        n: the number of samples (>= 0).
        rows: samples per block at most (``None``: one block).

    Returns:
        The blocks in order; one block ``(0, n)`` when ``rows`` is ``None`` or ``>= n`` (also
        for ``n == 0``).
    """
    if rows is None or rows >= n:
        return [(0, n)]
    step = max(int(rows), 1)
    return [(a, min(a + step, n)) for a in range(0, n, step)]


class _Design:
    """The design matrix ``X = [K, 1]`` (``K`` alone without a bias) in blocks of rows.

    With one block the block is built once and kept (it *is* the whole kernel, as a plain
    solve holds it); with several, each pass rebuilds every block from ``rows``, so at most
    one block of ``(rows, S + 1)`` entries (and a few temporaries of that size) is alive.
    """

    def __init__(
        self,
        kernel_rows: KernelRows,
        bounds: list[tuple[int, int]],
        fit_bias: bool,
        device: torch.device,
    ) -> None:
        self.kernel_rows = kernel_rows
        self.bounds = bounds
        self.fit_bias = fit_bias
        self.f64 = {"dtype": torch.float64, "device": device}
        self._kept: torch.Tensor | None = None

    def _build(self, start: int, stop: int) -> torch.Tensor:
        k = self.kernel_rows(start, stop).detach().to(**self.f64)
        if not self.fit_bias:
            return k
        return torch.cat([k, torch.ones(stop - start, 1, **self.f64)], 1)

    def blocks(self) -> Iterator[tuple[slice, torch.Tensor]]:
        """Each block's rows ``slice(start, stop)`` and its design rows ``(stop - start, S')``."""
        if len(self.bounds) == 1:
            if self._kept is None:
                self._kept = self._build(*self.bounds[0])
            yield slice(*self.bounds[0]), self._kept
            return
        for start, stop in self.bounds:
            yield slice(start, stop), self._build(start, stop)


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
    n, s = kernel.shape
    return newton_solve_blocks(
        lambda start, stop: kernel[start:stop],
        n,
        s,
        target,
        l2,
        weight=weight,
        w0=w0,
        b0=b0,
        fit_bias=fit_bias,
        tol=tol,
        max_iter=max_iter,
        device=kernel.device,
    )


def newton_solve_blocks(
    kernel_rows: KernelRows,
    n: int,
    n_support: int,
    target: torch.Tensor,
    l2: float,
    weight: torch.Tensor | None = None,
    w0: torch.Tensor | None = None,
    b0: float = 0.0,
    fit_bias: bool = True,
    tol: float = NEWTON_TOL,
    max_iter: int = NEWTON_MAX_ITER,
    block_rows: int | None = None,
    device: torch.device | str | None = None,
) -> tuple[torch.Tensor, float, NewtonInfo]:
    """:func:`newton_solve` with the kernel streamed in blocks of rows (float64).

    The loss, gradient and Hessian are sums over samples, so each is accumulated block by
    block: ``g = Σ_b X_bᵀ c_b (p_b - y_b) + reg θ``, ``H = Σ_b X_bᵀ diag(c_b p_b (1 - p_b)) X_b
    + diag(reg)``. Memory is ``O(block_rows · S + S²)`` whatever ``n`` is; each Newton step
    costs one pass over the blocks (the full step's loss, gradient and Hessian together), a
    halving of the step one more. With one block (``block_rows`` ``None`` or ``>= n``) the
    block is built once and every number is the one a solve on the whole kernel gives, to
    the bit.

    Args:
        kernel_rows: ``rows(start, stop)`` -> the kernel ``(stop - start, n_support)`` of
            those samples (see :data:`KernelRows`).
        n: the number of samples.
        n_support: the kernel's columns ``S``.
        target: ``(n,)`` soft labels in [0, 1].
        l2: weight of ``½ l2 ||w||²`` (the bias is not penalised).
        weight: ``(n,)`` per-sample weights ``c``; ``None``: ``1/n`` each (mean BCE).
        w0: ``(S,)`` starting weights (``None``: zeros).
        b0: starting bias, kept fixed when ``fit_bias`` is off.
        fit_bias: optimise the bias too.
        tol: stop when ``max|g| <= tol`` or the Newton decrement ``λ <= tol``.
        max_iter: Newton steps at most.
        block_rows: samples per block at most (``None``: one block).
        device: where the solve runs (``None``: ``target``'s device).

    Returns:
        ``(w (S,), b, info)``, ``w`` in float64 on ``device``.
    """
    on = torch.device(device) if device is not None else target.device
    f64 = {"dtype": torch.float64, "device": on}
    s = n_support
    y = target.detach().to(**f64)
    c = torch.full((n,), 1.0 / max(n, 1), **f64) if weight is None else weight
    c = c.detach().to(**f64)
    design = _Design(kernel_rows, block_bounds(n, block_rows), fit_bias, on)
    width = s + 1 if fit_bias else s
    reg = torch.full((width,), float(l2), **f64)
    if fit_bias:
        reg[-1] = 0.0
    theta = torch.zeros(width, **f64)
    if w0 is not None:
        theta[:s] = w0.detach().to(**f64)
    offset = 0.0 if fit_bias else float(b0)
    if fit_bias:
        theta[-1] = float(b0)

    def evaluate(
        t: torch.Tensor, derivatives: bool
    ) -> tuple[float, torch.Tensor | None, torch.Tensor | None]:
        """The penalised loss at ``t`` and (``derivatives``) its gradient and Hessian, one pass."""
        total = torch.zeros((), **f64)
        g: torch.Tensor | None = None
        h: torch.Tensor | None = None
        for rows, x in design.blocks():
            z = x @ t + offset
            total = total + (c[rows] * bce_terms(z, y[rows])).sum()
            if derivatives:
                p = torch.sigmoid(z)
                g_part = x.T @ (c[rows] * (p - y[rows]))
                h_part = (x.T * (c[rows] * p * torch.sigmoid(-z))) @ x
                g = g_part if g is None else g + g_part
                h = h_part if h is None else h + h_part
        loss = float(total + 0.5 * (reg * t * t).sum())
        if not derivatives:
            return loss, None, None
        g = (torch.zeros(width, **f64) if g is None else g) + reg * t
        h = (torch.zeros(width, width, **f64) if h is None else h) + torch.diag(reg)
        return loss, g, h

    loss, grad, hessian = evaluate(theta, True)
    grad_max, decrement, converged, iterations = float("inf"), float("nan"), False, 0
    for it in range(max_iter + 1):
        assert grad is not None and hessian is not None
        grad_max = float(grad.abs().max()) if grad.numel() else 0.0
        decrement = float("nan")
        if grad_max <= tol:
            converged = True
            break
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
            # the full step is nearly always taken: its pass brings the next step's derivatives
            new_loss, new_grad, new_hessian = evaluate(candidate, step == 1.0)
            if new_loss <= loss + _ARMIJO * step * slope + slack:
                break
            step *= 0.5
        else:
            break
        if new_grad is None:  # a shortened step: its derivatives in one more pass
            _, new_grad, new_hessian = evaluate(candidate, True)
        theta, loss, grad, hessian, iterations = (
            candidate, new_loss, new_grad, new_hessian, it + 1,
        )  # fmt: skip
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
