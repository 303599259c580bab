"""Inducing-point refinement of a sparse kernel model (``klr_sparse``'s second stage).

Forward selection (:mod:`cpmp.predictors.selection`) keeps a subset of the fixed rule's
support points at their places and with the default kernel. A quarter of the supports placed
along the activations then leaves gaps the default kernel width was never meant to bridge.
Here every node's kept supports are *moved* and its kernel's per-feature weights are
*widened* (one factor ``exp(ℓ_kj)``, ``ℓ_kj ≤ 0``, per node and feature: an ARD kernel that
may only widen) together with the weights and bias, by LBFGS on the same loss as the fit's
(mean soft-label BCE + ``½ l2 ||w||²`` per node), as inducing points of a sparse Gaussian
process are optimised (Snelson & Ghahramani 2006). Widening bridges the gaps between few
supports. Narrowing is not allowed: on a few demonstrations it fitted their contexts (at peg
D = 6 the holder's ``hold`` came to weigh the inserter's ``x`` 12 times more, and its φ read
0.44 at a hole just outside the demonstrated ones; docs/benchmarks.md). The factors enter as
``ℓ = min(θ, 0)``: a ``θ`` the loss pushes above 0 stops there. The loss is no longer convex
in the positions; the forward path's supports are the starting point, and the trainer's
convex solver then re-solves the weights on every sample with the moved supports fixed.

All nodes are refined in one batched problem: ``K`` nodes, their samples padded to ``P`` and
their supports to ``S``. The loss and its gradient are written out (no autograd graph), which
keeps an evaluation to a dozen tensor calls: the problems are small and an evaluation's cost
is mostly per call. With ``a = a₀ ⊙ exp(ℓ)`` a node's kernel weights,
``q_ps = Σ_j a_j (x_pj - s_sj)²``, ``k_ps = exp(-q_ps)``, ``z_p = Σ_s w_s k_ps + b`` and
``r_p = c_p (σ(z_p) - y_p)`` (``c_p`` the sample weights), ``G_ps = r_p w_s k_ps`` gives

``∂f/∂w_s = Σ_p r_p k_ps + l2 w_s``, ``∂f/∂b = Σ_p r_p``,
``∂f/∂s_sj = 2 a_j (Σ_p G_ps x_pj - s_sj Σ_p G_ps)``,
``∂f/∂θ_j = -a_j Σ_ps G_ps (x_pj - s_sj)²`` where ``θ_j ≤ 0``, else 0.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from cpmp.predictors.newton import bce_terms


@dataclass(frozen=True)
class RefineProblem:
    """Every node's samples and starting model, padded into batched tensors.

    Attributes:
        x: ``(K, P, d)`` samples (scaled features); padded rows are 0.
        target: ``(K, P)`` soft labels in [0, 1].
        sample_weight: ``(K, P)`` each sample's weight in its node's loss (``1/P_k`` for the
            mean; 0 on padded rows).
        support: ``(K, S, d)`` the starting supports; padded slots are 0.
        mask: ``(K, S)`` real supports.
        base_weights: ``(K, d)`` the kernel's per-feature weights before rescaling (γ times
            the node's path weights).
        weight: ``(K, S)`` starting weights (0 on padded slots).
        bias: ``(K,)`` starting intercepts.
    """

    x: torch.Tensor
    target: torch.Tensor
    sample_weight: torch.Tensor
    support: torch.Tensor
    mask: torch.Tensor
    base_weights: torch.Tensor
    weight: torch.Tensor
    bias: torch.Tensor


@dataclass(frozen=True)
class RefineResult:
    """The refined model.

    Attributes:
        support: ``(K, S, d)`` the moved supports (padded slots unchanged).
        log_scale: ``(K, d)`` ``ℓ ≤ 0``: the kernel weights are ``base_weights * exp(ℓ)``.
        weight: ``(K, S)`` weights.
        bias: ``(K,)`` intercepts.
        loss_start: Σ over nodes of the penalised loss at the start.
        loss: ... at the end.
        evaluations: loss and gradient evaluations spent.
    """

    support: torch.Tensor
    log_scale: torch.Tensor
    weight: torch.Tensor
    bias: torch.Tensor
    loss_start: float
    loss: float
    evaluations: int


def padded_samples(
    xs: list[torch.Tensor], targets: list[torch.Tensor], per_node: int
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Every k-th sample of each node (at most ``per_node``), padded: ``x``, target, weight.

    Consecutive samples of an activation are nearly alike, so a stride keeps the loss's shape
    at a fraction of the cost.

    Args:
        xs: per node its samples ``(P_k, d)``.
        targets: per node its labels ``(P_k,)``.
        per_node: samples kept per node at most (>= 1).

    Returns:
        ``x (K, P, d)``, ``target (K, P)`` and ``sample_weight (K, P)`` (``1/n_k`` on the
        ``n_k`` kept rows, 0 on padding), float64.
    """
    strides = [max(1, math.ceil(x.shape[0] / per_node)) for x in xs]
    sizes = [math.ceil(x.shape[0] / k) for x, k in zip(xs, strides, strict=True)]
    k_nodes, p, d = len(xs), max(max(sizes), 1), xs[0].shape[1]
    x_out = torch.zeros(k_nodes, p, d, dtype=torch.float64)
    y_out = torch.zeros(k_nodes, p, dtype=torch.float64)
    c_out = torch.zeros(k_nodes, p, dtype=torch.float64)
    for i, (x, y, k, n) in enumerate(zip(xs, targets, strides, sizes, strict=True)):
        x_out[i, :n] = x[::k].double()
        y_out[i, :n] = y[::k].double()
        c_out[i, :n] = 1.0 / max(n, 1)
    return x_out, y_out, c_out


class _Objective:
    """The batched penalised loss and its gradient in one flat parameter vector."""

    def __init__(
        self, problem: RefineProblem, l2: float, fit_bias: bool, anchor: float = 0.0
    ) -> None:
        self.x = problem.x.double()
        self.x_sq = self.x * self.x
        self.target = problem.target.double()
        self.c = problem.sample_weight.double()
        self.mask = problem.mask.double()
        self.a0 = problem.base_weights.double()
        # (K, 1, d): a position step of one kernel width. A feature the node's kernel weighs 0
        # (a path weight of 0) has no width: it steps in its own units, and with a = 0 neither
        # the loss nor its gradient reads it, so its coordinate stays where it started.
        self.unit = torch.where(self.a0 > 0, self.a0.sqrt(), 1.0)[:, None, :]
        self.l2 = float(l2)
        self.fit_bias = fit_bias
        k, s, d = problem.support.shape
        self.shapes = ((k, s, d), (k, d), (k, s), (k,))
        self.sizes = [math.prod(shape) for shape in self.shapes]
        self.anchor = float(anchor)
        self.u0 = (problem.support.double() * self.unit).reshape(-1)

    def pack(
        self,
        support: torch.Tensor,
        log_scale: torch.Tensor,
        weight: torch.Tensor,
        bias: torch.Tensor,
    ) -> torch.Tensor:
        """The flat vector ``(u, ℓ, weight, bias)``.

        The positions are optimised in units of the starting kernel's width, ``u = s ⊙ √a₀``,
        so that a unit step moves a support as far in every feature (LBFGS converges in far
        fewer steps than on raw positions, whose features' widths differ by orders of
        magnitude); a feature of ``a₀ = 0`` keeps its own units.
        """
        parts = (support.double() * self.unit, log_scale, weight, bias)
        return torch.cat([p.double().reshape(-1) for p in parts])

    def unpack(self, theta: torch.Tensor) -> list[torch.Tensor]:
        """The four parameter tensors of a flat vector: supports (in feature units), ℓ, w, b."""
        out, start = [], 0
        for shape, size in zip(self.shapes, self.sizes, strict=True):
            out.append(theta[start : start + size].view(shape))
            start += size
        out[0] = out[0] / self.unit
        return out

    def __call__(self, theta: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Loss (a 0-d tensor) and gradient (flat, in :meth:`pack`'s units) at ``theta``."""
        support, log_scale, weight, bias = self.unpack(theta)
        a = self.a0 * torch.exp(log_scale.clamp_max(0.0))  # (K, d): ℓ = min(θ, 0)
        w = weight * self.mask
        weighted = support * a[:, None, :]  # (K, S, d)
        s_term = (weighted * support).sum(-1)  # (K, S)
        x_term = torch.bmm(self.x_sq, a[:, :, None])  # (K, P, 1)
        cross = torch.bmm(self.x, weighted.transpose(1, 2))  # (K, P, S)
        q = (x_term - 2.0 * cross + s_term[:, None, :]).clamp_min(0.0)
        kern = torch.exp(-q) * self.mask[:, None, :]
        z = torch.bmm(kern, w[:, :, None])[:, :, 0] + bias[:, None]
        loss = (self.c * bce_terms(z, self.target)).sum() + 0.5 * self.l2 * (w * w).sum()
        r = self.c * (torch.sigmoid(z) - self.target)  # (K, P)
        g_w = (torch.bmm(r[:, None, :], kern)[:, 0] + self.l2 * w) * self.mask
        g_b = r.sum(1) if self.fit_bias else torch.zeros_like(bias)
        big_g = r[:, :, None] * kern * w[:, None, :]  # (K, P, S)
        col = big_g.sum(1)  # (K, S)
        gx = torch.bmm(big_g.transpose(1, 2), self.x)  # (K, S, d)
        g_s = 2.0 * a[:, None, :] * (gx - support * col[:, :, None]) / self.unit
        row = big_g.sum(2)  # (K, P)
        # Σ_ps G (x - s)² = Σ_p row x² - 2 Σ_s s ⊙ gx + Σ_s col s²
        spread = (
            torch.bmm(row[:, None, :], self.x_sq)[:, 0]
            - 2.0 * (support * gx).sum(1)
            + (col[:, :, None] * support * support).sum(1)
        )
        g_l = -a * spread * (log_scale <= 0.0)
        g_u = g_s.reshape(-1)
        if self.anchor > 0.0:  # ½·2λ: the pull back to the starting points, in kernel widths
            du = theta[: self.sizes[0]] - self.u0
            loss = loss + self.anchor * (du * du).sum()
            g_u = g_u + 2.0 * self.anchor * du
        return loss, torch.cat([g_u, g_l.reshape(-1), g_w.reshape(-1), g_b])


def refine(
    problem: RefineProblem,
    l2: float,
    max_iter: int,
    fit_bias: bool = True,
    anchor: float = 0.0,
) -> RefineResult:
    """Move the supports and widen the kernels of every node (LBFGS, strong Wolfe).

    Args:
        problem: the nodes' samples and starting models.
        l2: weight of ``½ l2 ||w||²`` per node.
        max_iter: LBFGS iterations at most.
        fit_bias: learn the intercepts (else they stay as given).
        anchor: weight ``λ`` of ``λ Σ ||u - u₀||²``, which pulls each support back to its
            starting point (``u``: positions in units of the starting kernel's width); 0:
            free.

    Returns:
        The refined model; never worse in loss than the start (LBFGS's line search only
        accepts decreases).
    """
    objective = _Objective(problem, l2, fit_bias, anchor)
    k, _, d = problem.support.shape
    log_scale = torch.zeros(k, d, dtype=torch.float64)
    theta = objective.pack(problem.support, log_scale, problem.weight, problem.bias)
    start, _ = objective(theta)
    param = torch.nn.Parameter(theta.clone())
    opt = torch.optim.LBFGS(
        [param],
        max_iter=max_iter,
        history_size=10,
        line_search_fn="strong_wolfe",
        tolerance_grad=1e-9,
        tolerance_change=1e-12,
    )

    def closure() -> torch.Tensor:
        loss, grad = objective(param.detach())
        param.grad = grad
        return loss

    if max_iter > 0:
        opt.step(closure)
    evaluations = int(opt.state[param].get("func_evals", 0)) if max_iter > 0 else 0
    loss, _ = objective(param.detach())
    if not bool(torch.isfinite(loss)) or float(loss) >= float(start):  # the start, exactly
        return RefineResult(
            problem.support.double().clone(),
            log_scale,
            problem.weight.double() * objective.mask,
            problem.bias.double().clone(),
            float(start),
            float(start),
            evaluations,
        )
    support, theta_l, weight, bias = (t.clone() for t in objective.unpack(param.detach()))
    return RefineResult(
        support,
        theta_l.clamp_max(0.0),
        weight * objective.mask,
        bias,
        float(start),
        float(loss),
        evaluations,
    )
