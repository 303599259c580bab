"""A small neural progress predictor trained on the same soft-label loss (eq. 5).

One MLP per node, all stored as stacked weight tensors so every node is evaluated in one
batched ``einsum`` per layer.
"""

from __future__ import annotations

import itertools
import math
from typing import ClassVar

import torch
from torch import nn

from cpmp.config.predictors import MLPConfig
from cpmp.predictors.base import NodeData, NodeKey, ProgressPredictor, soft_bce
from cpmp.records import JsonValue

_ACTIVATIONS = {"tanh": torch.tanh, "relu": torch.relu, "silu": nn.functional.silu}
"""The functions of :data:`cpmp.config.ACTIVATIONS` (tested to match)."""


class MLPPredictor(ProgressPredictor):
    """``mlp``: per-node multilayer perceptrons ``d -> hidden... -> 1`` with a sigmoid output."""

    kind: ClassVar[str] = "mlp"
    config_class = MLPConfig
    config: MLPConfig

    def __init__(self, node_keys: list[NodeKey], n_features: int, config: MLPConfig) -> None:
        super().__init__(node_keys, n_features, config)
        sizes = [n_features, *config.hidden, 1]
        k = self.n_nodes
        self.weights = nn.ParameterList(
            nn.Parameter(torch.zeros(k, a, b, dtype=self.dtype_))
            for a, b in itertools.pairwise(sizes)
        )
        self.biases = nn.ParameterList(
            nn.Parameter(torch.zeros(k, b, dtype=self.dtype_)) for b in sizes[1:]
        )
        self._act = _ACTIVATIONS[config.activation]

    def initialize(self, data: list[NodeData], generator: torch.Generator) -> None:
        """Glorot-uniform weights drawn from ``generator`` (so a seed fixes the result)."""
        with torch.no_grad():
            for w, b in zip(self.weights, self.biases, strict=True):
                fan_in, fan_out = w.shape[1], w.shape[2]
                bound = math.sqrt(6.0 / (fan_in + fan_out))
                u = torch.rand(w.shape, generator=generator, dtype=self.dtype_)
                w.copy_((2.0 * u - 1.0) * bound)
                b.zero_()

    def logits(self, z: torch.Tensor) -> torch.Tensor:
        """Logits ``(B, K)`` of every node's MLP for scaled features ``z (B, d)``.

        One batched einsum per layer.
        """
        h = z[:, None, :].expand(-1, self.n_nodes, -1)
        last = len(self.weights) - 1
        for layer, (w, b) in enumerate(zip(self.weights, self.biases, strict=True)):
            h = torch.einsum("bki,kio->bko", h, w) + b
            if layer < last:
                h = self._act(h)
        return h[..., 0]

    def node_logits(self, z: torch.Tensor, i: int) -> torch.Tensor:
        """Logits ``(B,)`` of node ``i``'s MLP for scaled features ``z (B, d)``."""
        h = z
        last = len(self.weights) - 1
        for layer, (w, b) in enumerate(zip(self.weights, self.biases, strict=True)):
            h = h @ w[i] + b[i]
            if layer < last:
                h = self._act(h)
        return h[:, 0]

    def training_loss(
        self, data: list[NodeData], rows: list[torch.Tensor] | None = None
    ) -> torch.Tensor:
        """Mean soft BCE (eq. 5) plus ``½ weight_decay ||W||²`` per node, summed."""
        total = torch.zeros((), dtype=self.dtype_, device=self.biases[0].device)
        for i, node in enumerate(data):
            x, target = (
                (node.x, node.target) if rows is None else (node.x[rows[i]], node.target[rows[i]])
            )
            total = total + soft_bce(self.node_logits(x, i), target)
            penalty = sum((w[i] * w[i]).sum() for w in self.weights)
            total = total + 0.5 * self.config.weight_decay * penalty
        return total

    def summary(self) -> dict[str, JsonValue]:
        """The base facts and the hidden layer sizes."""
        out = super().summary()
        out["hidden"] = list(self.config.hidden)
        return out
