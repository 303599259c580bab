"""Baselines on the kernel features of ``klr``: what a user would compare cpmp's predictor with.

All three use ``klr``'s support rule, γ and feature weighting (they subclass
:class:`~cpmp.predictors.klr.KLRPredictor`), so only the fit or the labels differ:

``sklearn_klr``     the same soft-label KLR problem solved by scikit-learn's
                    ``LogisticRegression`` on the RBF features, each sample entering as two
                    weighted copies (target 1 with weight φ, target 0 with weight 1 − φ); an
                    independent cross-check of the soft-label loss.
``regression_clip`` kernel ridge regression of the progress labels on the same features, its
                    output clipped to [0, 1] (the alternative the paper argues against).
``time_phase``      the same KLR trained on normalised elapsed time instead of the L1 line
                    integral (the label ablation of eq. 1).

The fitted coefficients live in the module's parameters: prediction is a torch call and a
checkpoint holds tensors only.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import ClassVar

import numpy as np
import torch

from cpmp.config.predictors import (
    RegressionClipConfig,
    SklearnKLRConfig,
    TimePhaseConfig,
)
from cpmp.config.trainer import SolverOptions
from cpmp.errors import require
from cpmp.predictors.base import NodeData
from cpmp.predictors.klr import KLRPredictor
from cpmp.predictors.newton import NewtonInfo, penalised_loss
from cpmp.records import JsonValue


class SklearnKLRPredictor(KLRPredictor):
    """``sklearn_klr``: ``klr``'s model, its weights fitted by scikit-learn.

    scikit-learn replaces the trainer's Newton solve (``solver: newton``, the default); with
    ``solver: lbfgs`` torch's LBFGS minimises the same loss, as for ``klr``.
    """

    kind: ClassVar[str] = "sklearn_klr"
    config_class = SklearnKLRConfig
    config: SklearnKLRConfig

    def solve_convex(
        self, data: list[NodeData], solver: SolverOptions, kernels: list[torch.Tensor] | None = None
    ) -> list[NewtonInfo]:
        """Fit each node's weights and bias with scikit-learn's ``LogisticRegression``.

        On its kernel features ``(P, S)``, two weighted copies per sample.

        Args:
            data: every node's training data.
            solver: unused (scikit-learn's own solver and tolerance apply).
            kernels: each node's ``(P_i, S)`` kernel (default: the cached ones).

        Returns:
            Per node scikit-learn's iterations and the max-norm of the gradient of ``klr``'s
            loss at the result.
        """
        require("sklearn", "baselines", "the sklearn_klr predictor")
        from sklearn.linear_model import LogisticRegression  # lazy: the [baselines] extra

        c = self.config

        def solve(i: int, k: torch.Tensor, phi: torch.Tensor) -> tuple:
            n = k.shape[0]
            features = torch.cat([k, k]).numpy(force=True)
            classes = np.concatenate([np.ones(n), np.zeros(n)])
            sample_weight = torch.cat([phi, 1.0 - phi]).numpy(force=True)
            model = LogisticRegression(
                C=1.0 / (n * c.l2) if c.l2 > 0 else np.inf,
                fit_intercept=c.bias,
                solver=c.sklearn_solver,
                tol=c.sklearn_tol,
                max_iter=c.sklearn_max_iter,
            )
            model.fit(features, classes, sample_weight=sample_weight)
            w = torch.as_tensor(model.coef_[0], dtype=torch.float64, device=k.device)
            b = float(model.intercept_[0]) if c.bias else float(self.bias[i])
            return w, b, self._report(k, phi, w, b, int(np.max(model.n_iter_)))

        return _solve_nodes(self, data, kernels, solve)

    def _report(
        self, k: torch.Tensor, phi: torch.Tensor, w: torch.Tensor, b: float, iterations: int
    ) -> NewtonInfo:
        """The solver outcome in the terms of :class:`NewtonInfo` (no Newton decrement)."""
        l2 = self.config.l2
        c = torch.full_like(phi, 1.0 / phi.shape[0])
        residual = c * (torch.sigmoid(k @ w + b) - phi)
        grad = k.T @ residual + l2 * w
        if self.config.bias:
            grad = torch.cat([grad, residual.sum()[None]])
        loss = float(penalised_loss(k, phi, c, w, b, l2))
        converged = iterations < self.config.sklearn_max_iter
        return NewtonInfo(iterations, float(grad.abs().max()), float("nan"), loss, converged)

    def summary(self) -> dict[str, JsonValue]:
        """The kernel bank's facts and scikit-learn's solver."""
        out = super().summary()
        out["sklearn_solver"] = self.config.sklearn_solver
        return out


class RegressionClipPredictor(KLRPredictor):
    """``regression_clip``: kernel ridge regression of progress, clipped to [0, 1].

    The bank's logits are ``logit(clip(K w + b, 0, 1))``, ``±inf`` at the clip bounds, so the
    sigmoid of :meth:`forward` returns exactly 0 and 1 there and the clipped value in between
    (to rounding); far from every support point the output tends to the node's intercept. The
    fit is closed-form (trainer ``solver: newton``, the default) or LBFGS on the same ridge loss
    (``solver: lbfgs``).
    """

    kind: ClassVar[str] = "regression_clip"
    config_class = RegressionClipConfig
    config: RegressionClipConfig

    def logits(self, z: torch.Tensor) -> torch.Tensor:
        """``logit(clip(K w + b, 0, 1))`` ``(B, K)`` of every node."""
        return _clipped_logit(super().logits(z))

    def node_logits(self, z: torch.Tensor, i: int) -> torch.Tensor:
        """``logit(clip(K w + b, 0, 1))`` ``(B,)`` of node ``i``."""
        return _clipped_logit(super().node_logits(z, i))

    def training_loss(
        self, data: list[NodeData], rows: list[torch.Tensor] | None = None
    ) -> torch.Tensor:
        """Sum over nodes of ``½ mean (K w + b − φ)² + ½ l2 ||w||²`` (unclipped output)."""
        total = torch.zeros((), dtype=self.dtype_, device=self.weight.device)
        for i, (node, kern) in enumerate(zip(data, self.node_kernels(data), strict=True)):
            w = self.weight[i] * self.support_mask[i]
            target = node.target
            if rows is not None:
                kern, target = kern[rows[i]], target[rows[i]]
            residual = kern @ w + self.bias[i] - target
            total = total + 0.5 * (residual * residual).mean()
            total = total + 0.5 * self.config.l2 * (w * w).sum()
        return total

    def solve_convex(
        self, data: list[NodeData], solver: SolverOptions, kernels: list[torch.Tensor] | None = None
    ) -> list[NewtonInfo]:
        """Closed-form ridge solution per node: ``(XᵀX / n + R) θ = Xᵀ φ / n``.

        With ``X = [K, 1]`` and ``R = diag(l2, ..., l2, 0)``; one Cholesky solve (least squares
        if the system is singular, e.g. for ``l2 = 0`` with repeated supports).

        Args:
            data: every node's training data.
            solver: unused (the solution is exact).
            kernels: each node's ``(P_i, S)`` kernel (default: the cached ones).

        Returns:
            Per node one "iteration" and the max-norm of the gradient at the solution.
        """

        def solve(i: int, k: torch.Tensor, y: torch.Tensor) -> tuple:
            n = k.shape[0]
            f64 = {"dtype": torch.float64, "device": k.device}
            offset = 0.0 if self.config.bias else float(self.bias[i])
            x = torch.cat([k, torch.ones(n, 1, **f64)], 1) if self.config.bias else k
            reg = torch.full((x.shape[1],), float(self.config.l2), **f64)
            if self.config.bias:
                reg[-1] = 0.0
            gram = x.T @ x / n + torch.diag(reg)
            rhs = x.T @ (y - offset) / n
            chol, info = torch.linalg.cholesky_ex(gram)
            if int(info) == 0:
                theta = torch.cholesky_solve(rhs[:, None], chol)[:, 0]
            else:
                theta = torch.linalg.lstsq(gram, rhs[:, None], driver="gelsd").solution[:, 0]
            s = k.shape[1]
            b = float(theta[-1]) if self.config.bias else offset
            residual = x @ theta + offset - y
            grad = x.T @ residual / n + reg * theta
            loss = 0.5 * float((residual * residual).mean()) + 0.5 * self.config.l2 * float(
                theta[:s] @ theta[:s]
            )
            return theta[:s], b, NewtonInfo(1, float(grad.abs().max()), float("nan"), loss, True)

        return _solve_nodes(self, data, kernels, solve)


def _solve_nodes(
    bank: KLRPredictor,
    data: list[NodeData],
    kernels: list[torch.Tensor] | None,
    solve: Callable[[int, torch.Tensor, torch.Tensor], tuple[torch.Tensor, float, NewtonInfo]],
) -> list[NewtonInfo]:
    """Fit every node of a kernel bank by ``solve`` and write the weights into the bank.

    Args:
        bank: the kernel bank.
        data: every node's training data.
        kernels: each node's ``(P_i, S)`` kernel (default: the cached ones).
        solve: ``solve(i, K_i (P, S_i), target (P,))`` -> (weights ``(S_i,)``, bias,
            outcome) of node ``i`` on its real supports.

    Returns:
        Each node's outcome.
    """
    kernels = bank.node_kernels(data) if kernels is None else kernels
    weight = torch.zeros_like(bank.weight, requires_grad=False)
    bias = bank.bias.detach().clone()
    infos = []
    for i, (node, kern) in enumerate(zip(data, kernels, strict=True)):
        mask = bank.support_mask[i]
        k = kern[:, mask].detach().to(torch.float64)
        w, b, info = solve(i, k, node.target.detach().to(torch.float64))
        weight[i, mask] = w.to(weight.dtype)
        bias[i] = b
        infos.append(info)
    with torch.no_grad():
        bank.weight.copy_(weight)
        bank.bias.copy_(bias)
    return infos


def _clipped_logit(raw: torch.Tensor) -> torch.Tensor:
    """``logit(clip(raw, 0, 1))``: ``-inf`` at or below 0, ``+inf`` at or above 1."""
    return torch.logit(raw.clamp(0.0, 1.0))


class TimePhasePredictor(KLRPredictor):
    """``time_phase``: ``klr`` trained on normalised elapsed time instead of eq. 1.

    The labels are :func:`cpmp.progress.time_labels`, not the L1 line integral.
    """

    kind: ClassVar[str] = "time_phase"
    config_class = TimePhaseConfig
    config: TimePhaseConfig
    labels: ClassVar[str] = "time"
