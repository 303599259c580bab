"""Test doubles of progress predictors (and the small graphs they drive) shared by the sequencer
tests."""

from __future__ import annotations

from typing import ClassVar

import torch

from cpmp.graph import SequenceGraph
from cpmp.predictors import ProgressPredictor


class FirstColumnsAreProgress(ProgressPredictor):
    """Test double: node k's progress is feature k; the features after the nodes' are state."""

    kind: ClassVar[str] = "first_columns_are_progress"

    def logits(self, z: torch.Tensor) -> torch.Tensor:
        return torch.logit(z[:, : self.n_nodes].clamp(1e-9, 1 - 1e-9))


def chain_graphs(chains: dict[str, tuple[str, str]]) -> dict[str, SequenceGraph]:
    """One graph per variable: ``variable -> (a, b)`` is the chain ``a -> b``, starting at ``a``."""
    graphs = {}
    for v, (a, b) in chains.items():
        g = SequenceGraph(v)
        g.add_node(a)
        g.add_node(b)
        g.initial_nodes = {a}
        g.edges = {(a, b)}
        graphs[v] = g
    return graphs
