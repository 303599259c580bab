"""Kernel logistic regression progress predictors (paper eq. 4–5) with RBF kernels.

``klr``        support points equidistant by L1 arc length along each activation, their number
               ``max(min_support, ceil(support_scale * path length))`` (the paper's choice).
``klr_full``   every training sample is a support point (the standard, overfitting-prone KLR).
``klr_sparse`` learnable sparsity: a generous candidate set, L1-penalised weights, optionally
               learned positions and per-feature length-scales; near-zero supports are pruned.

All three share one batched kernel evaluation over padded support sets ``(K, S, d)``.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
import torch
from torch import nn

from cpmp.config.predictors import KLRConfig, SparseKLRConfig
from cpmp.config.trainer import SolverOptions
from cpmp.errors import ConfigError
from cpmp.predictors.base import (
    START_PREFIX,
    NodeData,
    NodeKey,
    ProgressPredictor,
    soft_bce,
)
from cpmp.predictors.newton import NewtonInfo, newton_fit
from cpmp.progress import feature_path_lengths, support_point_count, support_points


class KLRPredictor(ProgressPredictor):
    """``klr``: sparse support points along the activations, fixed during training."""

    kind: ClassVar[str] = "klr"
    config_class = KLRConfig
    convex: ClassVar[bool] = True
    config: KLRConfig

    def __init__(
        self, node_keys: list[NodeKey], n_features: int, config: KLRConfig, n_support: int = 1
    ) -> None:
        super().__init__(node_keys, n_features, config)
        k, d, dt = self.n_nodes, n_features, self.dtype_
        self.register_buffer("support", torch.zeros(k, n_support, d, dtype=dt))
        self.register_buffer("support_mask", torch.zeros(k, n_support, dtype=torch.bool))
        self.register_buffer("gamma", torch.tensor(float(config.gamma), dtype=dt))
        self.register_buffer("feature_scale", torch.ones(k, d, dtype=dt))
        self.weight = nn.Parameter(torch.zeros(k, n_support, dtype=dt))
        self.bias = nn.Parameter(torch.zeros(k, dtype=dt), requires_grad=config.bias)
        self._cache: list[torch.Tensor] | None = None
        self._packed_cache: tuple[tuple, tuple[Any, ...], dict[int, tuple]] | None = None

    def shape_spec(self) -> dict[str, Any]:
        """The padded support count ``S``."""
        return {"n_support": int(self.support.shape[1])}

    def feature_weights(self) -> torch.Tensor:
        """Per-node, per-feature kernel weights ``(K, d)``.

        γ times the feature scale (all ones for the isotropic kernel).
        """
        return self.gamma * self.feature_scale

    def kernel(self, z: torch.Tensor) -> torch.Tensor:
        """RBF kernel ``(B, K, S)`` of scaled features ``z (B, d)`` with every node's supports.

        Padded slots are 0.
        """
        a = self.feature_weights()
        s = self.support
        x_term = (z * z) @ a.T
        cross = torch.einsum("bd,ksd->bks", z, a[:, None, :] * s)
        s_term = (a[:, None, :] * s * s).sum(-1)
        sq = (x_term[:, :, None] - 2.0 * cross + s_term[None]).clamp_min(0.0)
        return torch.exp(-sq) * self.support_mask

    def logits(self, z: torch.Tensor) -> torch.Tensor:
        """Logits ``(B, K)`` of every node for scaled features ``z (B, d)``."""
        return self.head_logits(z, self.n_nodes)

    def head_logits(self, z: torch.Tensor, heads: int) -> torch.Tensor:
        """Logits ``(B, heads)`` of the first ``heads`` nodes over their packed supports.

        The packed supports are the real ones, without padding.

        With ``a_n`` the kernel weights of support ``n``'s node,
        ``Σ_j a_nj (z_j - s_nj)² = a_n · z² - 2 z · (a_n s_n) + a_n · s_n²``: one small product
        for the per-node first term, one matrix product of ``z`` with the weighted supports,
        one exp over ``(B, N)`` and a per-node sum. Without gradients the packed tensors are
        cached until a parameter or buffer changes, so a control tick costs a handful of small
        tensor calls.
        """
        a_t, node, weighted, s_term, w = self._packed(heads)
        x_term = torch.index_select((z * z) @ a_t, 1, node)
        sq = torch.addmm(s_term, z, weighted.T, alpha=-2.0) + x_term
        terms = torch.exp(-sq.clamp_min(0.0)) * w
        out = torch.zeros(z.shape[0], heads, dtype=terms.dtype, device=terms.device)
        return out.index_add(1, node, terms) + self.bias[:heads]

    def _packed(self, heads: int) -> tuple[torch.Tensor, ...]:
        """The real (unpadded) supports of the first ``heads`` nodes, grouped by node.

        Kernel weights ``a[:heads]ᵀ (d, heads)``, node index ``(N,)``, ``a_n s_n (N, d)``,
        ``a_n · s_n² (N,)`` and weights ``(N,)``. Cached per ``heads`` while no gradient is
        needed, keyed on the identity and version counter of every tensor they derive from.
        """
        tensors = (self.gamma, self.feature_scale, self.support, self.support_mask, self.weight)
        extra = getattr(self, "log_feature_scale", None)
        if extra is not None:
            tensors += (extra,)
        grad = torch.is_grad_enabled() and any(t.requires_grad for t in tensors)
        key = tuple((id(t), t._version) for t in tensors)
        if grad or self._packed_cache is None or self._packed_cache[0] != key:
            a = self.feature_weights()
            node, slot = torch.nonzero(self.support_mask, as_tuple=True)
            s = self.support[node, slot]
            weighted = a[node] * s
            ends = torch.cumsum(self.support_mask.sum(1), 0).tolist()
            full = (a, node, weighted, (weighted * s).sum(-1), self.weight[node, slot], ends)
            if grad:
                return self._first_heads(full, heads)
            self._packed_cache = (key, full, {})
        _, full, per_heads = self._packed_cache
        if heads not in per_heads:
            per_heads[heads] = self._first_heads(full, heads)
        return per_heads[heads]

    @staticmethod
    def _first_heads(full: tuple[Any, ...], heads: int) -> tuple[torch.Tensor, ...]:
        a, node, weighted, s_term, w, ends = full
        n = ends[heads - 1]
        return a[:heads].T.contiguous(), node[:n], weighted[:n], s_term[:n], w[:n]

    def _supports_for(self, node: NodeData) -> np.ndarray:
        rule = (*self._support_rule(), "none")  # node.paths: denoised already where asked
        return np.concatenate([support_points(p, *rule) for p in node.paths], axis=0)

    def _support_rule(self) -> tuple[float, int, int | None]:
        """``(per unit path length, minimum, maximum)`` support points per activation."""
        c = self.config
        return c.support_scale, c.min_support, c.max_support

    def _support_total(self, data: list[NodeData]) -> int:
        """Support points :meth:`_supports_for` would place, counted without placing them."""
        rule = (*self._support_rule(), "none")
        return sum(support_point_count(p, *rule) for node in data for p in node.paths)

    def _check_support_budget(self, data: list[NodeData]) -> None:
        total = self._support_total(data)
        if total > self.config.max_total_support:
            raise ConfigError(
                f"the fit needs {total} support points, more than max_total_support="
                f"{self.config.max_total_support}: lower support_scale or set max_support "
                "(or raise max_total_support if the memory is there); with "
                f"feature_scaling={self.config.feature_scaling!r} the count follows the "
                "features' units"
            )

    def initialize(self, data: list[NodeData], generator: torch.Generator) -> None:
        """Place every node's supports along its activations (and its path feature weights)."""
        self._check_support_budget(data)
        per_node = [self._supports_for(node) for node in data]
        self._set_supports(per_node)
        if self.config.feature_weighting == "path":
            ones = torch.ones(self.n_features, dtype=self.dtype_)
            self.feature_scale = torch.stack(
                [
                    ones if node.key[1].startswith(START_PREFIX) else self._path_weights(node)
                    for node in data
                ]
            )

    def _path_weights(self, node: NodeData) -> torch.Tensor:
        """``(d,)`` kernel weights from each feature's share of the node's L1 path length."""
        per_feature = sum(feature_path_lengths(p) for p in node.paths)
        total = float(np.sum(per_feature))
        d = self.n_features
        share = per_feature / total if total > 0 else np.full(d, 1.0 / d)
        weights = np.maximum(d * share, self.config.weight_floor)
        return torch.as_tensor(weights, dtype=self.dtype_)

    def _set_supports(self, per_node: list[np.ndarray]) -> None:
        s_max = max(len(p) for p in per_node)
        support = torch.zeros(self.n_nodes, s_max, self.n_features, dtype=self.dtype_)
        mask = torch.zeros(self.n_nodes, s_max, dtype=torch.bool)
        for i, pts in enumerate(per_node):
            support[i, : len(pts)] = torch.as_tensor(pts, dtype=self.dtype_)
            mask[i, : len(pts)] = True
        self._assign_support(support)
        self.support_mask = mask
        self.weight = nn.Parameter(torch.zeros(self.n_nodes, s_max, dtype=self.dtype_))
        self._cache = None

    def _assign_support(self, support: torch.Tensor) -> None:
        self.support = support

    def node_kernels(self, data: list[NodeData]) -> list[torch.Tensor]:
        """Kernel matrix ``(P_i, S)`` of each node's samples against its own supports.

        Computed once per fit (and again after the bank moves to another device); the
        supports and kernel weights must not change in between.
        """
        if self._cache is None or self._cache[0].device != self.support.device:
            with torch.no_grad():
                self._cache = [self.node_kernel(i, node.x) for i, node in enumerate(data)]
        return self._cache

    def node_kernel(self, i: int, x: torch.Tensor) -> torch.Tensor:
        """Kernel ``(P, S)`` of samples ``x (P, d)`` against node ``i``'s supports.

        Padded slots are 0. ``Σ_j a_j (x_j - s_j)² = a · x² - 2 x · (a s) + a · s²``: one matrix
        product instead of a ``(P, S, d)`` difference tensor.
        """
        a = self.feature_weights()[i]
        weighted = a * self.support[i]
        sq = torch.addmm(((weighted * self.support[i]).sum(-1)), x, weighted.T, alpha=-2.0)
        sq = sq + ((x * x) @ a)[:, None]
        return torch.exp(-sq.clamp_min(0.0)) * self.support_mask[i]

    def node_logits(self, z: torch.Tensor, i: int) -> torch.Tensor:
        """Logits ``(B,)`` of node ``i`` for scaled features ``z (B, d)``."""
        return self.node_kernel(i, z) @ self.weight[i] + self.bias[i]

    def training_loss(
        self, data: list[NodeData], rows: list[torch.Tensor] | None = None
    ) -> torch.Tensor:
        """Mean soft BCE (eq. 5) plus ``½ l2 ||w||²`` per node, summed (see the base class)."""
        return self._penalised_loss(data, _rows_of(self.node_kernels(data), rows), rows=rows)

    def _penalised_loss(
        self,
        data: list[NodeData],
        kernels: list[torch.Tensor],
        l1: float = 0.0,
        rows: list[torch.Tensor] | None = None,
    ) -> torch.Tensor:
        """Sum over nodes of the penalised soft-label loss given each node's kernel matrix.

        Args:
            data: every node's training data.
            kernels: per node the kernel ``(P_i, S)`` of its samples (``(b_i, S)``: of the
                mini-batch's rows when ``rows`` is given).
            l1: weight of the ``l1 · mean |w|`` term per node (0: none).
            rows: per node the mini-batch's rows ``(b_i,)`` (``None``: every sample).

        Returns:
            Σ over nodes of the mean soft BCE (eq. 5) + ``½ l2 ||w||²`` (+ the L1 term).
        """
        total = torch.zeros((), dtype=self.dtype_, device=self.weight.device)
        for i, (node, kern) in enumerate(zip(data, kernels, strict=True)):
            w = self.weight[i] * self.support_mask[i]
            target = node.target if rows is None else node.target[rows[i]]
            total = total + soft_bce(kern @ w + self.bias[i], target)
            total = total + 0.5 * self.config.l2 * (w * w).sum()
            if l1 > 0.0:
                total = total + l1 * w.abs().sum() / self.support_mask[i].sum().clamp_min(1)
        return total

    def solve_convex(
        self, data: list[NodeData], solver: SolverOptions, kernels: list[torch.Tensor] | None = None
    ) -> list[NewtonInfo]:
        """Newton solve of :meth:`_penalised_loss` (no L1) for weight and bias, kernel fixed.

        Args:
            data: every node's training data.
            solver: the solver's tolerances.
            kernels: each node's ``(P_i, S)`` kernel (default: the cached ones).

        Returns:
            Each node's solver outcome.
        """
        kernels = self.node_kernels(data) if kernels is None else kernels
        masks = list(self.support_mask)
        with torch.no_grad():
            solutions, infos = newton_fit(
                [kern[:, mask] for kern, mask in zip(kernels, masks, strict=True)],
                [node.target for node in data],
                self.config.l2,
                init=[(self.weight[i, m], float(self.bias[i])) for i, m in enumerate(masks)],
                fit_bias=self.config.bias,
                tol=solver.tol,
                max_iter=solver.max_iter,
            )
            weight = torch.zeros_like(self.weight)
            bias = self.bias.detach().clone()
            for i, (mask, (w, b)) in enumerate(zip(masks, solutions, strict=True)):
                weight[i, mask] = w.to(weight.dtype)
                bias[i] = b
            self.weight.copy_(weight)
            self.bias.copy_(bias)
        return infos

    def support_counts(self) -> dict[str, int]:
        """Real supports per node, keyed ``"variable/mp"``."""
        return {
            f"{v}/{mp}": int(n)
            for (v, mp), n in zip(self.node_keys, self.support_mask.sum(1).tolist(), strict=True)
        }

    def summary(self) -> dict[str, Any]:
        """The base facts and the support counts (per node and in total)."""
        out = super().summary()
        counts = self.support_counts()
        out["support_counts"] = counts
        out["n_support_total"] = sum(counts.values())
        return out


def _rows_of(kernels: list[torch.Tensor], rows: list[torch.Tensor] | None) -> list[torch.Tensor]:
    """Each node's kernel ``(P_i, S)`` cut to its mini-batch rows ``(b_i,)`` (``None``: all)."""
    if rows is None:
        return kernels
    return [kern[r] for kern, r in zip(kernels, rows, strict=True)]


class FullKLRPredictor(KLRPredictor):
    """``klr_full``: every training sample is a support point (the paper's overfitting baseline)."""

    kind: ClassVar[str] = "klr_full"

    def _supports_for(self, node: NodeData) -> np.ndarray:
        return node.x.detach().numpy(force=True)

    def _support_total(self, data: list[NodeData]) -> int:
        return sum(int(node.x.shape[0]) for node in data)


class SparseKLRPredictor(KLRPredictor):
    """``klr_sparse``: learn which of many candidate supports to keep (L1 + pruning)."""

    config: SparseKLRConfig
    kind: ClassVar[str] = "klr_sparse"
    config_class = SparseKLRConfig
    convex: ClassVar[bool] = False

    def __init__(
        self,
        node_keys: list[NodeKey],
        n_features: int,
        config: SparseKLRConfig,
        n_support: int = 1,
    ) -> None:
        super().__init__(node_keys, n_features, config, n_support)
        self.log_feature_scale = nn.Parameter(
            torch.zeros(self.n_nodes, n_features, dtype=self.dtype_),
            requires_grad=config.learn_lengthscales,
        )
        self.support = nn.Parameter(self.support.clone(), requires_grad=config.learn_positions)
        self.refit_info: list[NewtonInfo] = []
        """Per-node outcome of the last Newton re-fit (empty before one)."""

    def feature_weights(self) -> torch.Tensor:
        """Per-node, per-feature kernel weights ``(K, d)``: γ times the learned scales."""
        return self.gamma * torch.exp(self.log_feature_scale)

    def _support_rule(self) -> tuple[float, int, int | None]:
        return self.config.candidate_scale, self.config.min_candidates, None

    def _assign_support(self, support: torch.Tensor) -> None:
        del self.support
        self.support = nn.Parameter(support, requires_grad=self.config.learn_positions)

    def _learned_kernel(self) -> bool:
        return self.config.learn_positions or self.config.learn_lengthscales

    def training_loss(
        self, data: list[NodeData], rows: list[torch.Tensor] | None = None
    ) -> torch.Tensor:
        """Penalised loss with the L1 term; a learned kernel is recomputed on every call."""
        if self._learned_kernel():
            self._cache = None
            kernels = [
                self.node_kernel(i, node.x if rows is None else node.x[rows[i]])
                for i, node in enumerate(data)
            ]
        else:
            kernels = _rows_of(self.node_kernels(data), rows)
        return self._penalised_loss(data, kernels, self.config.l1, rows)

    def finalize(self, data: list[NodeData], solver: SolverOptions | None = None) -> None:
        """Prune near-zero supports, compact the padded arrays, optionally re-fit the weights.

        Args:
            data: every node's training data.
            solver: how the convex re-fit is solved (default: Newton).
        """
        with torch.no_grad():
            w = (self.weight * self.support_mask).abs()
            keep = (w >= self.config.prune_tol * w.max(dim=1, keepdim=True).values) & (w > 0)
            keep &= self.support_mask
            empty = keep.sum(1) == 0
            if empty.any():
                keep[empty] = self.support_mask[empty] & (w[empty] == w[empty].max(1, True).values)
            s_max = int(keep.sum(1).max())
            on = {"device": self.weight.device}
            support = torch.zeros(self.n_nodes, s_max, self.n_features, dtype=self.dtype_, **on)
            weight = torch.zeros(self.n_nodes, s_max, dtype=self.dtype_, **on)
            mask = torch.zeros(self.n_nodes, s_max, dtype=torch.bool, **on)
            for i in range(self.n_nodes):
                idx = torch.nonzero(keep[i]).squeeze(1)
                support[i, : len(idx)] = self.support[i, idx]
                weight[i, : len(idx)] = self.weight[i, idx]
                mask[i, : len(idx)] = True
        self._assign_support(support)
        self.support.requires_grad_(False)
        self.support_mask = mask
        self.weight = nn.Parameter(weight)
        self.log_feature_scale.requires_grad_(False)
        self._cache = None
        if self.config.refit:
            self._refit(data, solver or SolverOptions())

    def _refit(self, data: list[NodeData], solver: SolverOptions) -> None:
        """Convex re-fit of weights and bias on the surviving (fixed) supports.

        Without the L1 shrinkage: Newton, or LBFGS with ``solver.method == "lbfgs"``.
        """
        kernels = self.node_kernels(data)
        if solver.method == "newton":
            self.refit_info = self.solve_convex(data, solver, kernels)
            return
        params = [self.weight] + ([self.bias] if self.config.bias else [])
        opt = torch.optim.LBFGS(
            params,
            max_iter=self.config.max_iter,
            line_search_fn="strong_wolfe",
            tolerance_grad=1e-9,
            tolerance_change=1e-12,
        )

        def closure() -> torch.Tensor:
            opt.zero_grad()
            total = self._penalised_loss(data, kernels)
            total.backward()
            return total

        opt.step(closure)

    def summary(self) -> dict[str, Any]:
        """The kernel bank's facts and which kernel parts were learned."""
        out = super().summary()
        out["learn_positions"] = self.config.learn_positions
        out["learn_lengthscales"] = self.config.learn_lengthscales
        return out
