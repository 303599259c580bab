"""Nearest-neighbour progress: the goal-nearest baseline's stand-in for a progress predictor.

The baseline (:mod:`cpmp.baselines.goal_nearest`) never uses progress to switch; offline evaluation
(Fig. 6, :mod:`cpmp.evaluation.offline`) still asks every sequencer for φ, and
:class:`NearestProgress` answers with the expected progress (eq. 1) of the nearest training
sample of each node.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, NamedTuple

import numpy as np
import torch
from scipy.spatial import cKDTree
from torch import nn

from cpmp.errors import DataError
from cpmp.predictors import FeatureScaler

if TYPE_CHECKING:
    from torch.nn.modules.module import _IncompatibleKeys


class _NodeTree(NamedTuple):
    """One node's training samples, searchable, and their expected progress."""

    tree: cKDTree
    targets: np.ndarray


class NearestProgress(nn.Module):
    """Nearest-neighbour progress of every node.

    φ of node ``k`` at ``x`` is the expected progress (eq. 1) of the training sample of ``k``
    nearest to ``x`` in the scaled space.

    Buffers: ``samples (P, d)`` scaled training samples of all nodes, ``targets (P,)`` their
    expected progress, ``node (P,)`` the node index of each. Offers what offline evaluation
    needs of a predictor (``scaler``, ``node_keys``, ``stateful``, ``reset_state``).
    """

    stateful = False

    def __init__(
        self,
        node_keys: Sequence[tuple[str, str]],
        n_features: int,
        n_samples: int,
        dtype: torch.dtype = torch.float64,
    ) -> None:
        super().__init__()
        self.node_keys = [tuple(k) for k in node_keys]
        self.n_features = n_features
        self.scaler = FeatureScaler(n_features, dtype)
        self.register_buffer("samples", torch.zeros(n_samples, n_features, dtype=dtype))
        self.register_buffer("targets", torch.zeros(n_samples, dtype=dtype))
        self.register_buffer("node", torch.zeros(n_samples, dtype=torch.long))
        self._trees: list[_NodeTree] | None = None

    def reset_state(self, n_streams: int) -> None:
        """Stateless: nothing to reset."""

    def n_parameters(self) -> int:
        """No trained parameters: 0."""
        return 0

    def _lookup(self) -> list[_NodeTree]:
        """Each node's search tree, built on first use."""
        if self._trees is None:
            samples, node = self.samples.numpy(), self.node.numpy()
            self._trees = []
            for k in range(len(self.node_keys)):
                rows = np.flatnonzero(node == k)
                if rows.size == 0:
                    raise DataError(f"node {self.node_keys[k]} has no training samples")
                self._trees.append(_NodeTree(cKDTree(samples[rows]), self.targets.numpy()[rows]))
        return self._trees

    def forward(self, x: torch.Tensor, heads: int | None = None) -> torch.Tensor:
        """Raw features ``x (..., d)`` -> nearest-neighbour progress ``(..., K)`` in [0, 1].

        Args:
            x: raw features ``(..., d)``.
            heads: only the first ``heads`` nodes (``None``: all).

        Returns:
            φ ``(..., K)``, float64.
        """
        lead = x.shape[:-1]
        z = self.scaler.transform(x.detach().cpu().numpy().reshape(-1, self.n_features))
        trees = self._lookup()[: len(self.node_keys) if heads is None else heads]
        out = np.empty((z.shape[0], len(trees)))
        for k, (tree, targets) in enumerate(trees):
            out[:, k] = targets[tree.query(z)[1]]
        return torch.from_numpy(out).reshape(*lead, len(trees))

    def load_state_dict(
        self, state_dict: Mapping[str, torch.Tensor], strict: bool = True, assign: bool = False
    ) -> _IncompatibleKeys:
        """:meth:`torch.nn.Module.load_state_dict`; the search trees are rebuilt on next use."""
        self._trees = None
        return super().load_state_dict(state_dict, strict, assign)
