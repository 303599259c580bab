"""Greedy forward selection of support points along a sparsity path (``klr_sparse``).

Each node's problem is the convex soft-label KLR loss of :mod:`cpmp.predictors.newton` (mean
BCE + ``½ l2 ||w||²``, bias unpenalised) over a set of *candidate* supports, of which a model
uses only the selected ones. The path starts with no support (bias only) and adds one support
at a time, to the node and candidate of the largest second-order estimate of the loss
decrease, ``g_j² / (2 h_j)`` with ``g_j`` and ``h_j`` the loss's gradient and curvature along
candidate ``j``'s weight at the node's current model (the import vector machine's rule, Zhu &
Hastie 2005). Supports are therefore spent where they lower the summed loss of all nodes most:
a node whose progress is easy to predict keeps few. Every node first gets one support. After
each addition the node's weights are updated by one damped Newton step from the previous
weights; at each checkpoint of the path (a total support count) every changed node is solved
to convergence and scored on its held-out samples. The models along the path are nested.

Per addition the cost is one Newton step on the selected supports ``(s+1)²`` and two products
of the candidate kernel with a vector ``(C, P)``; the candidate kernel itself is the one the
fixed rule's model needs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch.nn import functional as F

from cpmp.predictors.newton import bce_terms, newton_direction

CHECKPOINT_TOL = 1e-8
"""Gradient max-norm to which every node is solved on its scored samples at a checkpoint of the
path (the chosen model is then solved on every sample by the trainer's convex solver)."""
CHECKPOINT_MAX_ITER = 50
"""Newton steps per node and checkpoint at most."""
ROUND_SHARE = 0.25
"""Share of the nodes (those of the largest gains) that add a support in each round."""
SCORE_SAMPLES = 256
"""Training samples per node, at most, on which the candidates' gains are estimated (every
k-th; consecutive samples of an activation are nearly alike). The weights use every sample."""
_ARMIJO = 1e-4
_MAX_HALVINGS = 40


@dataclass(frozen=True)
class NodeProblem:
    """One node's selection problem (float64 tensors).

    Attributes:
        kernel: ``(C, P)`` kernel of each candidate support with each training sample.
        target: ``(P,)`` soft labels in [0, 1].
        val_kernel: ``(C, V)`` kernel of each candidate with each held-out sample (``V`` may
            be 0).
        val_target: ``(V,)`` held-out labels.
    """

    kernel: torch.Tensor
    target: torch.Tensor
    val_kernel: torch.Tensor
    val_target: torch.Tensor


@dataclass(frozen=True)
class NodeModel:
    """One node's model at a point of the path.

    Attributes:
        support: ``(s,)`` indices of the selected candidates, in the order they were added.
        weight: ``(s,)`` their weights (float64).
        bias: the intercept.
    """

    support: torch.Tensor
    weight: torch.Tensor
    bias: float


@dataclass(frozen=True)
class PathPoint:
    """One checkpoint of the path: every node's model and their scores.

    Attributes:
        n_support: supports of all nodes together.
        models: per node its :class:`NodeModel`.
        train_loss: Σ over nodes of the mean training BCE + ``½ l2 ||w||²``.
        val_loss: Σ over nodes with held-out samples of their mean BCE (the trainer's
            ``val/loss``); ``None`` without held-out samples.
        val_mae: mean |φ − label| over every node's held-out samples (the trainer's
            ``val/mae``); ``None`` without any.
    """

    n_support: int
    models: list[NodeModel]
    train_loss: float
    val_loss: float | None
    val_mae: float | None


class _Batch:
    """Every node's growing model on its scored samples, padded into batched tensors.

    Node ``i`` has ``P_i`` scored samples (every k-th training sample, :data:`SCORE_SAMPLES`
    at most) and ``C_i`` candidates; the tensors are padded to the largest of each, padded
    samples weigh 0 and padded candidates are never free. ``rows[i, :m_i]`` are the node's
    model rows (the bias's row of ones first, then the selected candidates' kernel rows); the
    rows past ``m_i`` are zero with a unit penalty, so their weights stay 0.
    """

    def __init__(self, problems: list[NodeProblem], l2: float, fit_bias: bool) -> None:
        n_nodes = len(problems)
        self.l2 = float(l2)
        self.fit_bias = fit_bias
        self.strides = [max(1, math.ceil(p.kernel.shape[1] / SCORE_SAMPLES)) for p in problems]
        sizes = [
            math.ceil(p.kernel.shape[1] / k) for p, k in zip(problems, self.strides, strict=True)
        ]
        n_cand = [int(p.kernel.shape[0]) for p in problems]
        n, c = max(sizes), max(n_cand)
        self.kernel = torch.zeros(n_nodes, c, n, dtype=torch.float32)
        self.target = torch.zeros(n_nodes, n, dtype=torch.float64)
        self.weight = torch.zeros(n_nodes, n, dtype=torch.float64)
        self.free = torch.zeros(n_nodes, c, dtype=torch.bool)
        for i, (p, k) in enumerate(zip(problems, self.strides, strict=True)):
            self.kernel[i, : n_cand[i], : sizes[i]] = p.kernel[:, ::k]
            self.target[i, : sizes[i]] = p.target[::k]
            self.weight[i, : sizes[i]] = 1.0 / max(sizes[i], 1)
            self.free[i, : n_cand[i]] = True
        self.kernel_sq = self.kernel * self.kernel
        self.m = torch.zeros(n_nodes, dtype=torch.long)
        self.selected: list[list[int]] = [[] for _ in problems]
        self.rows = torch.zeros(n_nodes, 0, n, dtype=torch.float64)
        self.theta = torch.zeros(n_nodes, 0, dtype=torch.float64)
        self.reg = torch.zeros(n_nodes, 0, dtype=torch.float64)
        self._grow(16)
        if fit_bias:
            self.rows[:, 0] = 1.0
            self.reg[:, 0] = 0.0
            mean = (self.target * self.weight).sum(1).clamp(1e-6, 1.0 - 1e-6)
            self.theta[:, 0] = torch.log(mean / (1.0 - mean))
            self.m[:] = 1
        self.best = torch.zeros(n_nodes, dtype=torch.long)
        self.gain = torch.zeros(n_nodes, dtype=torch.float64)
        self.score()

    def _grow(self, cap: int) -> None:
        """Room for ``cap`` model rows per node."""
        n_nodes, old, n = self.rows.shape
        rows = torch.zeros(n_nodes, cap, n, dtype=torch.float64)
        rows[:, :old] = self.rows
        theta = torch.zeros(n_nodes, cap, dtype=torch.float64)
        theta[:, :old] = self.theta
        reg = torch.ones(n_nodes, cap, dtype=torch.float64)
        reg[:, :old] = self.reg
        self.rows, self.theta, self.reg = rows, theta, reg

    def score(self, nodes: torch.Tensor | None = None) -> None:
        """The best free candidate of ``nodes`` (default all) and its estimated loss decrease.

        The estimate is ``g² / (2 h)``.
        """
        idx = torch.arange(self.m.numel()) if nodes is None else nodes
        used = max(int(self.m[idx].max()), 1)
        weight, target = self.weight[idx], self.target[idx]
        z = torch.bmm(self.theta[idx, None, :used], self.rows[idx, :used])[:, 0]
        p = torch.sigmoid(z)
        residual = (weight * (p - target)).to(torch.float32)
        curvature = (weight * p * (1.0 - p)).to(torch.float32)
        grad = torch.bmm(self.kernel[idx], residual[:, :, None])[:, :, 0].double()
        h = torch.bmm(self.kernel_sq[idx], curvature[:, :, None])[:, :, 0].double() + self.l2
        gain = grad * grad / (2.0 * h.clamp_min(1e-300))
        gain = torch.where(self.free[idx], gain, torch.full_like(gain, -math.inf))
        best_gain, best = gain.max(1)
        self.gain[idx], self.best[idx] = best_gain, best

    def add(self, nodes: list[int]) -> None:
        """Add each of ``nodes``' best free candidate, one Newton step for them, rescore them."""
        if int(self.m.max()) + 1 > self.theta.shape[1]:
            self._grow(min(2 * self.theta.shape[1], self.kernel.shape[1] + 1))
        for i in nodes:
            j, m = int(self.best[i]), int(self.m[i])
            self.selected[i].append(j)
            self.free[i, j] = False
            self.rows[i, m] = self.kernel[i, j].double()
            self.reg[i, m] = self.l2
            self.theta[i, m] = 0.0
            self.m[i] = m + 1
        idx = torch.tensor(nodes, dtype=torch.long)
        self.newton_step(idx)
        self.score(idx)

    def newton_step(self, idx: torch.Tensor) -> torch.Tensor:
        """One damped Newton step of the nodes ``idx`` on their scored samples (batched).

        Returns:
            ``(len(idx),)`` each node's gradient max-norm before the step.
        """
        used = max(int(self.m[idx].max()), 1)
        x, reg = self.rows[idx, :used], self.reg[idx, :used]
        theta = self.theta[idx, :used]
        weight, target = self.weight[idx], self.target[idx]

        def loss_at(t: torch.Tensor) -> torch.Tensor:
            z = torch.bmm(t[:, None, :], x)[:, 0]
            return (weight * bce_terms(z, target)).sum(1) + 0.5 * (reg * t * t).sum(1)

        z = torch.bmm(theta[:, None, :], x)[:, 0]
        p = torch.sigmoid(z)
        grad = torch.bmm(x, (weight * (p - target))[:, :, None])[:, :, 0] + reg * theta
        curvature = weight * p * torch.sigmoid(-z)
        hessian = torch.bmm(x * curvature[:, None, :], x.transpose(1, 2)) + torch.diag_embed(reg)
        chol, info = torch.linalg.cholesky_ex(hessian)
        direction = torch.zeros_like(theta)
        ok = info == 0
        if bool(ok.any()):
            direction[ok] = -torch.cholesky_solve(grad[ok][:, :, None], chol[ok])[:, :, 0]
        for k in torch.nonzero(~ok).flatten().tolist():
            direction[k] = newton_direction(hessian[k], grad[k])
        slope = (grad * direction).sum(1)
        loss = loss_at(theta)
        step = torch.where(slope < 0.0, 1.0, 0.0).to(theta.dtype)
        for _ in range(_MAX_HALVINGS):
            bad = (loss_at(theta + step[:, None] * direction) > loss + _ARMIJO * step * slope) & (
                step > 0
            )
            if not bool(bad.any()):
                break
            step = torch.where(bad, step * 0.5, step)
        else:
            step = torch.where(bad, 0.0, step)
        self.theta[idx, :used] = theta + step[:, None] * direction
        return grad.abs().amax(1)

    def settle(self) -> None:
        """Newton steps of every node on its scored samples to :data:`CHECKPOINT_TOL`."""
        idx = torch.arange(self.m.numel())
        for _ in range(CHECKPOINT_MAX_ITER):
            grad = self.newton_step(idx)
            idx = idx[grad > CHECKPOINT_TOL]
            if idx.numel() == 0:
                break
        self.score()

    def models(self) -> list[NodeModel]:
        """Every node's current model."""
        offset = 1 if self.fit_bias else 0
        out = []
        for i, selected in enumerate(self.selected):
            m = int(self.m[i])
            bias = float(self.theta[i, 0]) if self.fit_bias else 0.0
            weight = self.theta[i, offset:m].clone()
            out.append(NodeModel(torch.tensor(selected, dtype=torch.long), weight, bias))
        return out


def _scores(
    problems: list[NodeProblem], models: list[NodeModel], l2: float
) -> tuple[float, float | None, float | None]:
    """Training loss, held-out loss and held-out MAE of ``models`` (see :class:`PathPoint`)."""
    train, loss, abs_sum, count = 0.0, 0.0, 0.0, 0
    for problem, model in zip(problems, models, strict=True):
        z = model.weight @ problem.kernel[model.support] + model.bias
        train += float(bce_terms(z, problem.target).mean() + 0.5 * l2 * model.weight @ model.weight)
        n = int(problem.val_target.numel())
        if n == 0:
            continue
        phi = torch.sigmoid(model.weight @ problem.val_kernel[model.support] + model.bias)
        loss += float(F.binary_cross_entropy(phi, problem.val_target, reduction="mean"))
        abs_sum += float((phi - problem.val_target).abs().sum())
        count += n
    if not count:
        return train, None, None
    return train, loss, abs_sum / count


def forward_selection_path(
    problems: list[NodeProblem], totals: list[int], l2: float, fit_bias: bool = True
) -> list[PathPoint]:
    """Greedy forward selection over all nodes, checkpointed at the given support totals.

    Every node first gets one support; then each round the nodes of the largest gains (a
    quarter of the nodes, at least one) add their best candidate, until the next total.

    Args:
        problems: every node's candidates, samples and held-out samples (float64).
        totals: support totals (all nodes together) at which the path is recorded, in
            increasing order; each at least ``len(problems)`` (every node has a support).
        l2: weight of ``½ l2 ||w||²`` per node.
        fit_bias: learn each node's intercept (else it stays 0).

    Returns:
        One :class:`PathPoint` per total (fewer when the candidates run out first: the last
        point then holds every candidate).
    """
    batch = _Batch(problems, l2, fit_bias)
    per_round = max(1, math.ceil(ROUND_SHARE * len(problems)))
    batch.add([i for i in range(len(problems)) if math.isfinite(float(batch.gain[i]))])
    total = sum(len(s) for s in batch.selected)
    out: list[PathPoint] = []
    for target in totals:
        while total < target:
            finite = torch.isfinite(batch.gain)
            if not bool(finite.any()):
                break
            k = min(per_round, target - total, int(finite.sum()))
            nodes = torch.topk(batch.gain, k).indices.tolist()
            batch.add(nodes)
            total += k
        batch.settle()
        models = batch.models()
        train, val_loss, val_mae = _scores(problems, models, l2)
        out.append(PathPoint(total, models, train, val_loss, val_mae))
        if total < target:
            break
    return out
