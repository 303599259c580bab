"""Kernel logistic regression progress predictors (paper eq. 4–5) with RBF kernels.

``klr``        support points equidistant by L1 arc length along each activation, their number
               ``max(min_support, ceil(support_scale * path length))`` (the paper's choice).
``klr_full``   every training sample is a support point (the standard, overfitting-prone KLR).
``klr_sparse`` learned sparsity on the default model: the supports a sparsity path keeps
               (greedy forward selection, level chosen on validation data).

All three share one batched kernel evaluation over padded support sets ``(K, S, d)``.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import ClassVar, TypeAlias, TypeVar

import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

from cpmp.config.predictors import (
    CHUNK_SIZE,
    MERGE_SIMILARITY,
    POOL_SIZE,
    SUPPORT_CAP,
    KLRConfig,
    PredictorConfig,
    SparseKLRConfig,
)
from cpmp.config.trainer import SolverOptions
from cpmp.errors import ConfigError, DataError
from cpmp.predictors.base import NodeData, NodeKey, ProgressPredictor, soft_bce
from cpmp.predictors.inducing import RefineProblem, padded_samples, refine
from cpmp.predictors.newton import NewtonInfo, block_bounds, newton_fit, newton_solve_blocks
from cpmp.predictors.selection import (
    NodeModel,
    NodeProblem,
    PathPoint,
    forward_selection_path,
)
from cpmp.progress import feature_path_lengths, support_point_count, support_points
from cpmp.records import JsonValue

log = logging.getLogger(__name__)

_Number = TypeVar("_Number", int, float)
_CacheKey: TypeAlias = tuple[tuple[int, int], ...]
"""The identity and version counter of every tensor a cached value derives from."""
_PackedSupports: TypeAlias = tuple[
    torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor
]
"""Every node's real supports (:meth:`KLRPredictor._packed`): kernel weights ``aᵀ (d, K)``,
node index ``(N,)``, ``a_n s_n (N, d)``, ``a_n · s_n² (N,)`` and weights ``(N,)``."""

POOL_CANDIDATES = 20
"""Pooling places every point of the rule first: a fit whose rule places more than this many
times ``max_total_support`` points stops with a :class:`~cpmp.errors.ConfigError` (1,000,000
candidates by default: 8 MB per feature)."""

WARM_SHARE = 8
"""A node of several kernel blocks first solves every k-th of its samples, a ``1/WARM_SHARE``
block's worth, to start its solve on every sample near the optimum (two_point, 768
demonstrations: 2-4 Newton steps on every sample instead of 6)."""


@dataclass(frozen=True)
class BlockedKernel:
    """One node's kernel as it is evaluated in blocks of samples.

    Made by :meth:`KLRPredictor.blocked`.

    Attributes:
        kernel: ``kernel(x (b, d)) -> (b, S_i)`` of samples against the node's real supports.
        rows: samples per block (``None``: every sample in one block).
        mask: ``(S,)`` the node's real slots among the padded ones.
    """

    kernel: Callable[[torch.Tensor], torch.Tensor]
    rows: int | None
    mask: torch.Tensor


class KLRPredictor(ProgressPredictor):
    """``klr``: sparse support points along the activations, fixed during training."""

    kind: ClassVar[str] = "klr"
    config_class = KLRConfig
    convex: ClassVar[bool] = True
    config: KLRConfig
    pools_supports: ClassVar[bool] = True
    """Whether a node over ``support_cap`` support points has them pooled (``klr``; not
    ``klr_full``, whose supports are its samples, nor ``klr_sparse``, which selects its own)."""

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
        self._packed_cache: tuple[_CacheKey, _PackedSupports] | None = None
        self.chunk_size = _option(config, "chunk_size", CHUNK_SIZE, int)
        """Kernel entries (samples x supports) per block (:data:`CHUNK_SIZE`)."""
        self.support_cap = _option(config, "support_cap", SUPPORT_CAP, int)
        """Support points per node above which they are pooled (:data:`SUPPORT_CAP`)."""
        self.pool_size = _option(config, "pool_size", POOL_SIZE, int)
        """Supports a pooled node keeps at most (:data:`POOL_SIZE`)."""
        self.merge_similarity = _option(config, "merge_similarity", MERGE_SIMILARITY, float)
        """Kernel value from which a pooled support duplicates a kept one
        (:data:`MERGE_SIMILARITY`)."""
        if not 0.0 < self.merge_similarity < 1.0:
            raise ConfigError(
                "predictor option merge_similarity must be in (0, 1) (a kernel value), got "
                f"{self.merge_similarity!r}"
            )

    def block_rows(self, columns: int) -> int:
        """Samples per kernel block against ``columns`` supports: ``chunk_size // columns``."""
        return max(1, self.chunk_size // max(int(columns), 1))

    def shape_spec(self) -> dict[str, int]:
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
        """Logits ``(B, K)`` of every node for scaled features ``z (B, d)``.

        Over the packed supports: the real ones, without padding. With ``a_n`` the kernel
        weights of support ``n``'s node,
        ``Σ_j a_nj (z_j - s_nj)² = a_n · z² - 2 z · (a_n s_n) + a_n · s_n²``: one small product
        for the per-node first term, one matrix product of ``z`` with the weighted supports,
        one exp over ``(B, N)`` and a per-node sum. Without gradients the packed tensors are
        cached until a parameter or buffer changes, so a control tick costs a handful of small
        tensor calls.
        """
        packed = self._packed()
        rows = self.block_rows(int(packed[1].numel()))
        if z.shape[0] <= rows:
            return self._logits_block(z, packed)
        return torch.cat(
            [self._logits_block(z[a:b], packed) for a, b in block_bounds(z.shape[0], rows)]
        )

    def _logits_block(self, z: torch.Tensor, packed: _PackedSupports) -> torch.Tensor:
        """:meth:`logits` of one block of rows ``z (B, d)`` -> ``(B, K)``."""
        a_t, node, weighted, s_term, w = packed
        x_term = torch.index_select((z * z) @ a_t, 1, node)
        sq = torch.addmm(s_term, z, weighted.T, alpha=-2.0) + x_term
        terms = torch.exp(-sq.clamp_min(0.0)) * w
        out = torch.zeros(z.shape[0], self.n_nodes, dtype=terms.dtype, device=terms.device)
        return out.index_add(1, node, terms) + self.bias

    def _packed(self) -> _PackedSupports:
        """The real (unpadded) supports, grouped by node (:data:`_PackedSupports`).

        Cached while no gradient is needed, keyed on the identity and version counter of
        every tensor they derive from.
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
            packed = (
                a.T.contiguous(),
                node,
                weighted,
                (weighted * s).sum(-1),
                self.weight[node, slot],
            )
            if grad:
                return packed
            self._packed_cache = (key, packed)
        return self._packed_cache[1]

    def clear_cache(self) -> None:
        """Drop the cached training kernels and packed supports; the next call rebuilds them.

        Changes made with torch operations are seen without it (the cache is keyed on the
        tensors' version counters); changes through ``.data`` (``p.data[i] = 0``,
        ``p.data = t``) bypass the version counters: call this after them.
        """
        self._cache = None
        self._packed_cache = None

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
        """Place every node's supports along its activations (and its path feature weights).

        A node whose rule places more than ``support_cap`` points has them pooled
        (:func:`pool_supports`, ``klr`` only): the count then follows the region its
        activations cover, not their number.
        """
        scale = None
        if self.config.feature_weighting == "path":
            scale = torch.stack([self._path_weights(node) for node in data])
        if self.pools_supports:
            per_node = self._pooled_supports(data, scale)
        else:
            self._check_support_budget(data)
            per_node = [self._supports_for(node) for node in data]
        self._set_supports(per_node)
        if scale is not None:
            self.feature_scale = scale

    def _pooled_supports(
        self, data: list[NodeData], scale: torch.Tensor | None
    ) -> list[np.ndarray]:
        """Every node's supports ``(S_i, d)``: the rule's, pooled where over ``support_cap``.

        Raises:
            ConfigError: more than ``max_total_support`` supports after pooling.
        """
        rule = (*self._support_rule(), "none")
        counts = [sum(support_point_count(p, *rule) for p in node.paths) for node in data]
        if max(counts) <= self.support_cap:
            self._check_support_budget(data)
            return [self._supports_for(node) for node in data]
        limit = POOL_CANDIDATES * self.config.max_total_support
        if sum(counts) > limit:  # every rule point is placed before pooling: bound them
            raise ConfigError(
                f"the fit's support rule places {sum(counts)} points, more than "
                f"{POOL_CANDIDATES} x max_total_support={self.config.max_total_support} "
                "that pooling takes as candidates: lower support_scale or set max_support; with "
                f"feature_scaling={self.config.feature_scaling!r} the count follows the "
                "features' units"
            )
        gamma = float(self.config.gamma)
        out = []
        for i, (node, count) in enumerate(zip(data, counts, strict=True)):
            if count <= self.support_cap:
                out.append(self._supports_for(node))
                continue
            weights = np.ones(self.n_features) if scale is None else scale[i].numpy(force=True)
            per_activation = [support_points(p, *rule) for p in node.paths]
            out.append(
                pool_supports(
                    per_activation, gamma * weights, self.merge_similarity, self.pool_size
                )
            )
        total = sum(len(p) for p in out)
        if total > self.config.max_total_support:
            raise ConfigError(
                f"the fit needs {total} support points after pooling, more than "
                f"max_total_support={self.config.max_total_support}: lower support_scale or "
                "merge_similarity, or raise max_total_support if the memory is there"
            )
        pooled = sum(c > self.support_cap for c in counts)
        log.info(
            "pooled the supports of %d of %d nodes (over support_cap=%d): %d of the rule's %d "
            "kept (pool_size %d, merge_similarity %g)",
            pooled, len(data), self.support_cap, total, sum(counts), self.pool_size,
            self.merge_similarity,
        )  # fmt: skip
        return out

    def _path_weights(self, node: NodeData) -> torch.Tensor:
        """``(d,)`` kernel weights from each feature's share of the node's L1 path length.

        The node's ignored features (:attr:`NodeData.ignored`) weigh 0: the floor is for the
        task's features that do not move in the node (a context that decides a branch).
        """
        per_feature = sum(feature_path_lengths(p) for p in node.paths)
        total = float(np.sum(per_feature))
        d = self.n_features
        share = per_feature / total if total > 0 else np.full(d, 1.0 / d)
        weights = np.maximum(d * share, self.config.weight_floor)
        if node.ignored is not None:
            weights = np.where(node.ignored, 0.0, weights)
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
        self.clear_cache()

    def _assign_support(self, support: torch.Tensor) -> None:
        self.support = support

    def keep_supports(self, keep: torch.Tensor) -> None:
        """Keep only the supports ``keep (K, S)`` (bool, real slots), with their weights.

        The bank is repacked to the most kept supports per node; the biases, the kernel
        weights and the kept supports' order are unchanged, so each node's logit loses exactly
        the terms of the supports dropped. A benchmark strips a bank to one support per node
        with it to time a tick's fixed cost.

        Raises:
            DataError: ``keep`` is not ``(K, S)``, keeps a padded slot or no slot of a node.
        """
        if tuple(keep.shape) != tuple(self.support_mask.shape):
            raise DataError(
                f"keep must have the support mask's shape {tuple(self.support_mask.shape)}, "
                f"got {tuple(keep.shape)}"
            )
        keep = keep.to(torch.bool)
        if bool((keep & ~self.support_mask.to(keep.device)).any()):
            raise DataError("keep marks padded support slots; keep only real supports")
        if bool((keep.sum(1) == 0).any()):
            raise DataError("keep leaves a node without supports; keep one per node at least")
        with torch.no_grad():
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
        self.clear_cache()  # new tensors: an old id may be reused

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

    def blocked(self, i: int, n: int) -> BlockedKernel:
        """Node ``i``'s kernel on ``n`` samples as :class:`BlockedKernel` evaluates it.

        When the whole ``(n, S)`` kernel (``S`` the padded support count) is at most
        ``chunk_size`` entries it is one block, computed as :meth:`node_kernel` computes it
        (padded, then cut to the real supports), so every number is the one of a kernel held
        whole. Otherwise blocks of ``chunk_size // S_i`` samples against the node's ``S_i``
        real supports only.
        """
        mask = self.support_mask[i]
        if n * self.support.shape[1] <= self.chunk_size:
            return BlockedKernel(lambda x: self.node_kernel(i, x)[:, mask], None, mask)
        real = self.support[i, mask]
        a = self.feature_weights()[i]
        weighted = a * real
        s_term = (weighted * real).sum(-1)

        def kernel(x: torch.Tensor) -> torch.Tensor:
            sq = torch.addmm(s_term, x, weighted.T, alpha=-2.0) + ((x * x) @ a)[:, None]
            return torch.exp(-sq.clamp_min(0.0))

        return BlockedKernel(kernel, self.block_rows(real.shape[0]), mask)

    def node_logits(self, z: torch.Tensor, i: int) -> torch.Tensor:
        """Logits ``(B,)`` of node ``i`` for scaled features ``z (B, d)``.

        In blocks (:meth:`blocked`), so the ``(B, S)`` kernel is never held whole.
        """
        blocked = self.blocked(i, z.shape[0])
        w, b = self.weight[i, blocked.mask], self.bias[i]
        if blocked.rows is None:
            return self.node_kernel(i, z) @ self.weight[i] + b
        return torch.cat(
            [blocked.kernel(z[a:c]) @ w + b for a, c in block_bounds(z.shape[0], blocked.rows)]
        )

    def training_loss(
        self, data: list[NodeData], rows: list[torch.Tensor] | None = None
    ) -> torch.Tensor:
        """Mean soft BCE (eq. 5) plus ``½ l2 ||w||²`` per node, summed (see the base class).

        Without gradients and on every sample (the Newton fit's loss, the final loss), each
        node's kernel is evaluated in blocks (:meth:`streamed_loss`); with gradients (LBFGS,
        Adam) on the kernels cached for the fit.
        """
        if rows is None and not torch.is_grad_enabled():
            return self.streamed_loss(data)
        return self._penalised_loss(data, _rows_of(self.node_kernels(data), rows), rows=rows)

    def streamed_loss(self, data: list[NodeData]) -> torch.Tensor:
        """:meth:`_penalised_loss` (no L1) on every sample, the kernels evaluated in blocks.

        A node whose kernel fits one block gives the number a whole kernel gives, to the bit;
        the others sum their blocks' BCE.

        Args:
            data: every node's training data (on the bank's device).

        Returns:
            The scalar loss (no gradient).
        """
        total = torch.zeros((), dtype=self.dtype_, device=self.weight.device)
        with torch.no_grad():
            for i, node in enumerate(data):
                w = self.weight[i] * self.support_mask[i]
                blocked = self.blocked(i, node.n_samples)
                if blocked.rows is None:
                    logits = self.node_kernel(i, node.x) @ w + self.bias[i]
                    total = total + soft_bce(logits, node.target)
                else:
                    w_real = w[blocked.mask]
                    summed = sum(
                        F.binary_cross_entropy_with_logits(
                            blocked.kernel(node.x[a:b]) @ w_real + self.bias[i],
                            node.target[a:b],
                            reduction="sum",
                        )
                        for a, b in block_bounds(node.n_samples, blocked.rows)
                    )
                    total = total + summed / node.n_samples
                total = total + 0.5 * self.config.l2 * (w * w).sum()
        return total

    def _penalised_loss(
        self,
        data: list[NodeData],
        kernels: list[torch.Tensor],
        rows: list[torch.Tensor] | None = None,
    ) -> torch.Tensor:
        """Sum over nodes of the penalised soft-label loss given each node's kernel matrix.

        Args:
            data: every node's training data.
            kernels: per node the kernel ``(P_i, S)`` of its samples (``(b_i, S)``: of the
                mini-batch's rows when ``rows`` is given).
            rows: per node the mini-batch's rows ``(b_i,)`` (``None``: every sample).

        Returns:
            Σ over nodes of the mean soft BCE (eq. 5) + ``½ l2 ||w||²``.
        """
        total = torch.zeros((), dtype=self.dtype_, device=self.weight.device)
        for i, (node, kern) in enumerate(zip(data, kernels, strict=True)):
            w = self.weight[i] * self.support_mask[i]
            target = node.target if rows is None else node.target[rows[i]]
            total = total + soft_bce(kern @ w + self.bias[i], target)
            total = total + 0.5 * self.config.l2 * (w * w).sum()
        return total

    def solve_convex(
        self, data: list[NodeData], solver: SolverOptions, kernels: list[torch.Tensor] | None = None
    ) -> list[NewtonInfo]:
        """Newton solve of :meth:`_penalised_loss` for weight and bias, kernel fixed.

        Each node's kernel is evaluated in blocks (:meth:`blocked`,
        :func:`~cpmp.predictors.newton.newton_solve_blocks`); a node held in one block is
        solved as before blocks existed, to the bit. A node of several blocks first solves
        every k-th of its samples (:data:`WARM_SHARE`), and starts its solve on every sample
        from there: the same optimum (to the solver's tolerance) in about half the passes.

        Args:
            data: every node's training data.
            solver: the solver's tolerances.
            kernels: each node's ``(P_i, S)`` kernel, held whole (default: in blocks).

        Returns:
            Each node's solver outcome (of the solve on every sample).
        """
        if kernels is not None:
            return self._solve_cached(data, solver, kernels)
        infos = []
        with torch.no_grad():
            weight = torch.zeros_like(self.weight)
            bias = self.bias.detach().clone()
            for i, node in enumerate(data):
                blocked = self.blocked(i, node.n_samples)
                mask = blocked.mask
                options = {
                    "fit_bias": self.config.bias,
                    "tol": solver.tol,
                    "max_iter": solver.max_iter,
                    "device": self.weight.device,
                }
                w0, b0 = self.weight[i, mask], float(self.bias[i])
                if blocked.rows is not None and node.n_samples > blocked.rows:  # warm start
                    stride = math.ceil(WARM_SHARE * node.n_samples / blocked.rows)
                    x, target = node.x[::stride], node.target[::stride]
                    w0, b0, _ = newton_solve_blocks(
                        lambda a, b, x=x, kernel=blocked.kernel: kernel(x[a:b]),
                        int(x.shape[0]), int(mask.sum()), target, self.config.l2,
                        w0=w0, b0=b0, **options,
                    )  # fmt: skip
                w, b, info = newton_solve_blocks(
                    lambda a, b, x=node.x, kernel=blocked.kernel: kernel(x[a:b]),
                    node.n_samples,
                    int(mask.sum()),
                    node.target,
                    self.config.l2,
                    w0=w0,
                    b0=b0,
                    block_rows=blocked.rows,
                    **options,
                )
                weight[i, mask] = w.to(weight.dtype)
                bias[i] = b
                infos.append(info)
            self.weight.copy_(weight)
            self.bias.copy_(bias)
        return infos

    def _solve_cached(
        self, data: list[NodeData], solver: SolverOptions, kernels: list[torch.Tensor]
    ) -> list[NewtonInfo]:
        """:meth:`solve_convex` on kernels ``(P_i, S)`` held whole."""
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

    def summary(self) -> dict[str, JsonValue]:
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
    pools_supports: ClassVar[bool] = False

    def _supports_for(self, node: NodeData) -> np.ndarray:
        return node.x.detach().numpy(force=True)

    def _support_total(self, data: list[NodeData]) -> int:
        return sum(int(node.x.shape[0]) for node in data)


@dataclass(frozen=True)
class SparsityLevel:
    """One point of ``klr_sparse``'s sparsity path (a row of ``summary()["sparsity_path"]``).

    Attributes:
        level: the share of the fixed rule's support count the point was recorded at.
        gamma_scale: the kernel width, as the factor of ``gamma`` of its path.
        n_support: supports of all nodes together.
        train_loss: Σ over nodes of the mean training BCE + ``½ l2 ||w||²``.
        val_loss: Σ over nodes of the mean held-out BCE (the trainer's ``val/loss``), or
            ``None`` without held-out data.
        val_mae: mean |φ − eq. 1| over every node's held-out samples (``val/mae``), or
            ``None``.
        chosen: the fitted model is this point's.
    """

    level: float
    gamma_scale: float
    n_support: int
    train_loss: float
    val_loss: float | None
    val_mae: float | None
    chosen: bool = False


@dataclass(frozen=True)
class _Split:
    """The problems a path is run on and where its held-out data came from."""

    problems: list[NodeProblem]
    candidates: list[torch.Tensor]
    source: str


class SparseKLRPredictor(KLRPredictor):
    """``klr_sparse``: the default model with the supports a sparsity path keeps.

    The fixed rule's supports are the candidates; greedy forward selection
    (:func:`cpmp.predictors.selection.forward_selection_path`) records a path per kernel
    width, the validation data choose its level and width, and the trainer's convex solver
    solves the kept supports. See :class:`~cpmp.config.SparseKLRConfig`.
    """

    config: SparseKLRConfig
    kind: ClassVar[str] = "klr_sparse"
    config_class = SparseKLRConfig
    pools_supports: ClassVar[bool] = False

    def __init__(
        self,
        node_keys: list[NodeKey],
        n_features: int,
        config: SparseKLRConfig,
        n_support: int = 1,
    ) -> None:
        super().__init__(node_keys, n_features, config, n_support)
        # per-node, per-feature kernel factors, set by the refinement (widening only since
        # session 32; an older checkpoint's may narrow), not by the trainer
        self.log_feature_scale = nn.Parameter(
            torch.zeros(self.n_nodes, n_features, dtype=self.dtype_), requires_grad=False
        )
        self.support = nn.Parameter(self.support.clone(), requires_grad=False)
        self.sparsity_path: list[SparsityLevel] = []
        """The path of the last fit (empty before one)."""
        self.sparsity_validation = "none"
        """Where the path's held-out data came from: ``validation``, ``held-out activations``
        or ``none``."""
        self.n_support_rule = 0
        """Supports the fixed rule places on the fit's data (the levels' reference)."""
        self.refine_summary: dict[str, float | int] = {}
        """The last refinement's loss before and after and its evaluations (empty: none)."""
        self._validation: list[NodeData] | None = None

    def feature_weights(self) -> torch.Tensor:
        """Per-node, per-feature kernel weights ``(K, d)``.

        γ (times the chosen width factor) times the path weights, times the refinement's
        per-node, per-feature factors (at most 1 since session 32).
        """
        return self.gamma * self.feature_scale * torch.exp(self.log_feature_scale)

    def _assign_support(self, support: torch.Tensor) -> None:
        del self.support
        self.support = nn.Parameter(support, requires_grad=False)

    # ------------------------------------------------------------------ the sparsity path
    def set_validation(self, validation: list[NodeData] | None) -> None:
        """Keep the fit's held-out data for choosing the level."""
        self._validation = validation

    def initialize(self, data: list[NodeData], generator: torch.Generator) -> None:
        """Place the candidates, run the path and keep the chosen supports."""
        super().initialize(data, generator)
        validation, self._validation = self._validation, None
        with torch.no_grad():
            self._select(data, validation, generator)

    def _levels(self) -> list[float]:
        """The levels the path is recorded at (up to ``level`` when it is set)."""
        levels = sorted(set(self.config.path_levels))
        if self.config.level is None:
            return levels
        return [lv for lv in levels if lv < self.config.level] + [self.config.level]

    def _select(
        self, data: list[NodeData], validation: list[NodeData] | None, generator: torch.Generator
    ) -> None:
        """Run the path per width, choose the level and width, keep their supports."""
        masks = self.support_mask
        candidates = [self.support[i, masks[i]].detach().clone() for i in range(self.n_nodes)]
        self.n_support_rule = sum(len(c) for c in candidates)
        kernels = [
            self.node_kernel(i, node.x)[:, : len(candidates[i])].T.contiguous()
            for i, node in enumerate(data)
        ]
        split = self._split(data, validation, candidates, kernels, generator)
        levels = self._levels()
        points: list[tuple[SparsityLevel, list[NodeModel]]] = []
        for scale in self.config.gamma_scales:
            for level, point in self._path(split.problems, levels, scale):
                record = SparsityLevel(
                    level, scale, point.n_support, point.train_loss, point.val_loss, point.val_mae
                )
                points.append((record, point.models))
        best = self._choose([p for p, _ in points], levels[-1])
        chosen, models = points[best]
        kept_from = split.candidates
        if split.source == "held-out activations":
            # choose on the split, then select again on every activation
            problems = [_problem(k, node.target) for k, node in zip(kernels, data, strict=True)]
            fitted = self._path(problems, [chosen.level], chosen.gamma_scale)
            models, kept_from = fitted[-1][1].models, candidates
        self.sparsity_path = [
            dataclasses.replace(p, chosen=i == best) for i, (p, _) in enumerate(points)
        ]
        self.sparsity_validation = split.source
        self._keep(kept_from, models, chosen.gamma_scale)
        if self.config.refine_iter > 0:  # the moved supports learn from every activation
            self._refine(data)
        log.info("%s", self.describe_path())

    def _refine(self, data: list[NodeData]) -> None:
        """Move the kept supports and widen every node's kernel on every sample.

        See :mod:`cpmp.predictors.inducing`; the trainer's convex solver then re-solves the
        weights on every sample.
        """
        cfg = self.config
        x, target, sample_weight = padded_samples(
            [node.x for node in data], [node.target for node in data], cfg.refine_samples
        )
        mask = self.support_mask
        s = max(int(mask.sum(1).max()), 1)
        problem = RefineProblem(
            x,
            target,
            sample_weight,
            self.support.detach()[:, :s].double(),
            mask[:, :s],
            self.feature_weights().double(),
            self.weight.detach()[:, :s].double(),
            self.bias.detach().double(),
        )
        result = refine(problem, cfg.l2, cfg.refine_iter, cfg.bias, cfg.refine_anchor)
        if not math.isfinite(result.loss_start):
            log.warning(
                "klr_sparse: the refinement's starting loss is not finite; the selected "
                "supports are kept unrefined (check the features for non-finite values)"
            )
        with torch.no_grad():
            self.support[:, :s] = result.support.to(self.dtype_)
            self.log_feature_scale += result.log_scale.to(self.dtype_)
            self.weight[:, :s] = result.weight.to(self.dtype_)
            self.bias.copy_(result.bias.to(self.dtype_))
        self._cache = None
        self.refine_summary = {
            "loss_start": result.loss_start,
            "loss": result.loss,
            "evaluations": result.evaluations,
        }

    def _split(
        self,
        data: list[NodeData],
        validation: list[NodeData] | None,
        candidates: list[torch.Tensor],
        kernels: list[torch.Tensor],
        generator: torch.Generator,
    ) -> _Split:
        """The path's problems: the training data against the validation data.

        Without validation data, ``holdout_fraction`` of each node's activations (nodes with
        two or more) are held out, and the candidates are those placed along the remaining
        ones.
        """
        if validation is not None and any(v.n_samples for v in validation):
            problems = [
                _problem(k, node.target, self.node_kernel(i, v.x)[:, : len(c)].T, v.target)
                for i, (k, node, v, c) in enumerate(
                    zip(kernels, data, validation, candidates, strict=True)
                )
            ]
            return _Split(problems, candidates, "validation")
        seed = int(torch.randint(0, 2**31 - 1, (1,), generator=generator))
        rng = np.random.default_rng(seed)
        held = False
        problems, kept = [], []
        rule = (*self._support_rule(), "none")
        for i, node in enumerate(data):
            n_act = len(node.activations)
            n_out = round(self.config.holdout_fraction * n_act) if n_act >= 2 else 0
            n_out = min(max(n_out, 1 if n_act >= 2 else 0), n_act - 1)
            out = set(rng.choice(n_act, size=n_out, replace=False).tolist())
            held = held or bool(out)
            counts = [support_point_count(p, *rule) for p in node.paths]
            ends = np.cumsum([0, *counts])
            keep = [j for j in range(n_act) if j not in out]
            cand = torch.cat([candidates[i][ends[j] : ends[j + 1]] for j in keep])
            kept.append(cand)
            x_tr = torch.as_tensor(np.concatenate([node.activations[j] for j in keep]))
            y_tr = torch.as_tensor(np.concatenate([node.labels[j] for j in keep]))
            x_va = [node.activations[j] for j in sorted(out)]
            y_va = [node.labels[j] for j in sorted(out)]
            k_tr = self._kernel_with(i, cand, x_tr)
            k_va = (
                self._kernel_with(i, cand, torch.as_tensor(np.concatenate(x_va))) if x_va else None
            )
            y_va_t = torch.as_tensor(np.concatenate(y_va)) if y_va else None
            problems.append(_problem(k_tr, y_tr, k_va, y_va_t))
        source = "held-out activations" if held else "none"
        return _Split(problems, kept, source)

    def _kernel_with(self, i: int, support: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
        """Kernel ``(C, P)`` of node ``i``'s kernel weights between ``support`` and ``x``."""
        a = self.feature_weights()[i].double()
        s, z = support.double(), x.double()
        sq = (a * s * s).sum(-1)[:, None] - 2.0 * (a * s) @ z.T + ((z * z) @ a)[None, :]
        return torch.exp(-sq.clamp_min(0.0))

    def _path(
        self, problems: list[NodeProblem], levels: list[float], scale: float
    ) -> list[tuple[float, PathPoint]]:
        """The path at kernel width factor ``scale``, recorded at ``levels``.

        A level's support total is ``floor(level * n_support_rule)`` (at least one per node),
        whichever candidates the problems hold. The kernel at ``scale`` is the base kernel to
        the power ``scale``.
        """
        if scale != 1.0:
            problems = [
                dataclasses.replace(
                    p, kernel=p.kernel.pow(scale), val_kernel=p.val_kernel.pow(scale)
                )
                for p in problems
            ]
        n_rule = self.n_support_rule
        totals = [max(len(problems), math.floor(level * n_rule + 1e-9)) for level in levels]
        points = forward_selection_path(problems, totals, self.config.l2, self.config.bias)
        return list(zip(levels, points, strict=False))

    def _choose(self, points: list[SparsityLevel], last: float) -> int:
        """Index of the point of least held-out progress MAE (then loss, then fewest supports).

        The MAE, not the loss: on a few held-out activations (three demonstrations of the
        simulator) the summed loss can favour the smallest level by 3 % while its MAE is the
        worst of the path and the refined model's held-out MAE then 2.4x the default's.
        With ``level`` set, among that level's points; without held-out data, the first
        width's point at the last level.
        """
        allowed = [i for i, p in enumerate(points) if self.config.level is None or p.level == last]
        scored = [i for i in allowed if points[i].val_mae is not None]
        if not scored:
            return next(i for i in allowed if points[i].level == last)
        return min(
            scored, key=lambda i: (points[i].val_mae, points[i].val_loss, points[i].n_support, i)
        )

    def _keep(self, candidates: list[torch.Tensor], models: list[NodeModel], scale: float) -> None:
        """Make the chosen supports, weights and width factor ``scale`` the bank's."""
        self.gamma = self.gamma * scale
        self._set_supports(
            [c[m.support].numpy(force=True) for c, m in zip(candidates, models, strict=True)]
        )
        with torch.no_grad():
            self.log_feature_scale.zero_()
            for i, m in enumerate(models):
                self.weight[i, : m.support.numel()] = m.weight.to(self.dtype_)
                self.bias[i] = m.bias

    def describe_path(self) -> str:
        """The sparsity path as text: one line per point, the chosen one marked."""
        chosen = next((p for p in self.sparsity_path if p.chosen), None)
        if chosen is None:
            return "klr_sparse: no sparsity path (not fitted)"
        lines = [
            f"klr_sparse kept {chosen.n_support} of the fixed rule's {self.n_support_rule} "
            f"supports (level {chosen.level:g}, gamma x {chosen.gamma_scale:g}), chosen on "
            f"{self.sparsity_validation}; the path (level, gamma x, supports, val loss, val MAE):"
        ]
        for p in self.sparsity_path:
            loss = "-" if p.val_loss is None else f"{p.val_loss:.5f}"
            mae = "-" if p.val_mae is None else f"{p.val_mae:.4f}"
            mark = "  <- chosen" if p.chosen else ""
            lines.append(f"  {p.level:g}  {p.gamma_scale:g}  {p.n_support}  {loss}  {mae}{mark}")
        if self.refine_summary:
            r = self.refine_summary
            lines.append(
                f"then refined (supports moved, kernels widened) on every training activation: "
                f"training loss {r['loss_start']:.5f} -> {r['loss']:.5f} in "
                f"{r['evaluations']} evaluations"
            )
        return "\n".join(lines)

    def summary(self) -> dict[str, JsonValue]:
        """The kernel bank's facts and the sparsity path.

        ``sparsity_path`` (one dict per :class:`SparsityLevel`),
        ``sparsity_level``, ``sparsity_gamma_scale``, ``sparsity_validation``,
        ``n_support_rule`` (the fixed rule's count) and, after a refinement, ``refine``
        (``loss_start``, ``loss``, ``evaluations``).
        """
        out = super().summary()
        if self.sparsity_path:
            chosen = next(p for p in self.sparsity_path if p.chosen)
            out["sparsity_path"] = [dataclasses.asdict(p) for p in self.sparsity_path]
            out["sparsity_level"] = chosen.level
            out["sparsity_gamma_scale"] = chosen.gamma_scale
            out["sparsity_validation"] = self.sparsity_validation
            out["n_support_rule"] = self.n_support_rule
        if self.refine_summary:
            out["refine"] = dict(self.refine_summary)
        return out


def _option(config: PredictorConfig, name: str, default: _Number, kind: type[_Number]) -> _Number:
    """Option ``name`` of ``config`` as ``kind`` (``default`` when the options lack it).

    Raises:
        ConfigError: a value that is not a positive number of that kind.
    """
    value = getattr(config, name, default)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not value > 0:
        raise ConfigError(f"predictor option {name} must be a positive number, got {value!r}")
    if kind is int and value != int(value):
        raise ConfigError(f"predictor option {name} must be a whole number, got {value!r}")
    return kind(value)


def pool_supports(
    per_activation: list[np.ndarray], weights: np.ndarray, similarity: float, size: int
) -> np.ndarray:
    """One node's support points pooled over its activations: at most ``size``, spread evenly.

    Farthest-point selection (greedy k-center) in the kernel's metric
    ``Σ_j a_j (s_j - t_j)²`` over the rule's points of every activation: it starts from the
    first activation's first point and adds the point farthest from every chosen one, until
    ``size`` points are chosen or every point has a chosen one of kernel value at least
    ``similarity`` (then the rest are near-duplicates). The count therefore follows the
    extent of the region the task visits, at the resolution ``similarity`` sets, and never
    exceeds ``size``, however many activations there are.

    Args:
        per_activation: per activation its support points ``(S_j, d)`` (the fixed rule's).
        weights: ``(d,)`` the node's kernel weights ``a`` (γ times the feature weights).
        similarity: the kernel value in (0, 1) from which a point duplicates a chosen one.
        size: the most points kept (>= 1).

    Returns:
        The chosen points ``(S, d)``, in the activations' order.
    """
    points = np.concatenate([np.asarray(p, dtype=np.float64) for p in per_activation])
    scaled = points * np.sqrt(np.asarray(weights, dtype=np.float64))
    tau = -math.log(similarity)
    chosen = [0]
    dist = ((scaled - scaled[0]) ** 2).sum(1)
    while len(chosen) < size:
        j = int(np.argmax(dist))
        if dist[j] <= tau:
            break
        chosen.append(j)
        dist = np.minimum(dist, ((scaled - scaled[j]) ** 2).sum(1))
    return points[np.sort(chosen)]


def _problem(
    kernel: torch.Tensor,
    target: torch.Tensor,
    val_kernel: torch.Tensor | None = None,
    val_target: torch.Tensor | None = None,
) -> NodeProblem:
    """A node's selection problem in float64 (no held-out data: zero held-out samples)."""
    f64 = torch.float64
    c = kernel.shape[0]
    return NodeProblem(
        kernel.to(f64).contiguous(),
        target.to(f64),
        torch.zeros(c, 0, dtype=f64) if val_kernel is None else val_kernel.to(f64).contiguous(),
        torch.zeros(0, dtype=f64) if val_target is None else val_target.to(f64),
    )
