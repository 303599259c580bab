"""What the transition rule reads of a fitted sequencer, as plain records built once.

:class:`NodeIndex` says where each node's φ sits among the predictor's heads and which successors
each node has; :class:`TransitionModel` gathers it with the graphs, the options, the coupling,
the features' ranges and the demonstrated starts. A
:class:`~cpmp.sequencer.ConcurrentSequencer` builds both once (``seq.nodes``,
``seq.transition_model``) and hands the model to every
:class:`~cpmp.sequencer.episode.SequencerEpisode`, which needs nothing else of it: the episode
and the batch depend on these records, not on the sequencer class.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from cpmp.config import SequencerConfig
from cpmp.errors import ConfigError
from cpmp.graph import SequenceGraph
from cpmp.sequencer.branches import BranchChoices
from cpmp.sequencer.switching import Coupling

Node = tuple[str, str]
"""(variable, MP): one node of a sequence graph."""


class Successors(NamedTuple):
    """The successors of one node and where their φ sit.

    Attributes:
        names: the successor MPs, sorted.
        columns: each successor's φ column.
    """

    names: list[str]
    columns: list[int]


@dataclass(frozen=True)
class NodeIndex:
    """Where each node's φ sits in the predictor's output, and the successor tables.

    The transition rule reads these every tick, and the start rules read the initial nodes'
    φ at the start; built once per sequencer (:meth:`build`).

    Attributes:
        keys: (variable, MP) of every graph node, in the order of the φ columns.
        index: (variable, MP) -> its φ column.
        successors: (variable, MP) -> its :class:`Successors`.
    """

    keys: list[Node]
    index: dict[Node, int]
    successors: dict[Node, Successors]

    @classmethod
    def build(
        cls, graphs: Mapping[str, SequenceGraph], predictor_keys: Sequence[Node]
    ) -> NodeIndex:
        """The index of ``graphs``' nodes in a predictor with heads ``predictor_keys``.

        The heads are the graph nodes, in order.

        Args:
            graphs: variable -> its sequence graph.
            predictor_keys: the predictor's heads, ``(variable, MP)`` each.

        Returns:
            The index.

        Raises:
            ConfigError: the predictor's heads are not the graphs' nodes.
        """
        keys = [(v, mp) for v in sorted(graphs) for mp in graphs[v].ordered_nodes()]
        if [tuple(k) for k in predictor_keys] != keys:
            raise ConfigError("the predictor's nodes do not match the sequence graphs' nodes")
        index = {key: i for i, key in enumerate(keys)}
        successors = {
            (v, mp): Successors(
                graphs[v].successors(mp),
                [index[(v, s)] for s in graphs[v].successors(mp)],
            )
            for v, mp in keys
        }
        return cls(keys, index, successors)

    def phi_dict(self, phi: np.ndarray | list[float]) -> dict[str, dict[str, float]]:
        """Per-node φ ``(K,)`` as variable -> MP -> φ."""
        out: dict[str, dict[str, float]] = {v: {} for v, _ in self.keys}
        values = phi.tolist() if isinstance(phi, np.ndarray) else phi
        for (v, mp), value in zip(self.keys, values, strict=True):
            out[v][mp] = value
        return out


@dataclass(frozen=True, eq=False)
class TransitionModel:
    """Everything one episode of the transition rule reads of a fitted sequencer.

    Attributes:
        graphs: variable -> its sequence graph.
        nodes: where each node's φ sits, and the successor tables.
        config: the transition rule's options.
        coupling: the learned contexts of the demonstrated switches (read with
            ``config.coupling == "context"``).
        feature_range: ``(d,)`` range of each feature in the training data (the stall
            detector's unit; 0 for features it ignores).
        initial_combinations: the demonstrated initial MP per variable (distinct; what
            ``config.start_rule == "joint"`` chooses among).
        branches: the learned choice at each node with several demonstrated successors.
        feature_names: the ``d`` feature names (what the notes call the features; empty:
            by index).
    """

    graphs: dict[str, SequenceGraph]
    nodes: NodeIndex
    config: SequencerConfig
    coupling: Coupling
    feature_range: np.ndarray
    initial_combinations: list[dict[str, str]]
    branches: BranchChoices = field(default_factory=lambda: BranchChoices({}))
    feature_names: list[str] = field(default_factory=list)

    def feature_name(self, j: int) -> str:
        """Feature ``j``'s name (``feature j`` without names)."""
        return self.feature_names[j] if j < len(self.feature_names) else f"feature {j}"
