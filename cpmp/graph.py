"""Sequence graphs (paper Algorithm 1): one graph per control variable.

A graph has a node per movement primitive (MP) observed for its variable, a directed edge per
observed switch ``a -> b`` and a set of initial nodes (MPs that start some demonstration).
Every node keeps the feature segment of each of its activations; an MP may be activated several
times, so graphs can have cycles.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace

from cpmp.data import Activation, Demonstration
from cpmp.errors import DataError, UnknownMPError


@dataclass
class SequenceGraph:
    """The sequence graph of one control variable.

    Attributes:
        variable: control-variable name.
        nodes: MP names (one node each).
        initial_nodes: MPs that start at least one demonstration.
        edges: observed switches ``(source, target)``.
        activations: MP name -> list of its activations (empty for a graph loaded without data).
    """

    variable: str
    nodes: set[str] = field(default_factory=set)
    initial_nodes: set[str] = field(default_factory=set)
    edges: set[tuple[str, str]] = field(default_factory=set)
    activations: dict[str, list[Activation]] = field(default_factory=dict)

    def add_node(self, mp: str) -> None:
        """Add ``mp`` as a node (with no activations yet) unless it is one already."""
        if mp not in self.nodes:
            self.nodes.add(mp)
            self.activations.setdefault(mp, [])

    def successors(self, mp: str) -> list[str]:
        """Sorted successors of ``mp``; raises :class:`UnknownMPError` for an unknown MP."""
        self._check(mp)
        return sorted(t for s, t in self.edges if s == mp)

    def predecessors(self, mp: str) -> list[str]:
        """Sorted predecessors of ``mp``; raises :class:`UnknownMPError` for an unknown MP."""
        self._check(mp)
        return sorted(s for s, t in self.edges if t == mp)

    def ordered_nodes(self) -> list[str]:
        """Nodes in a stable (sorted) order; the order used for batched predictors."""
        return sorted(self.nodes)

    def _check(self, mp: str) -> None:
        """:class:`UnknownMPError` unless ``mp`` is a node."""
        if mp not in self.nodes:
            raise UnknownMPError(
                f"MP {mp!r} is not a node of the graph of {self.variable!r}; "
                f"known MPs: {', '.join(self.ordered_nodes())}"
            )

    def to_text(self) -> str:
        """A readable multi-line description: nodes (``*`` = initial), activations, edges."""
        lines = [f"graph {self.variable}:"]
        for mp in self.ordered_nodes():
            mark = "*" if mp in self.initial_nodes else " "
            n_act = len(self.activations.get(mp, []))
            succ = ", ".join(self.successors(mp)) or "(terminal)"
            lines.append(f"  {mark} {mp} [{n_act} activations] -> {succ}")
        return "\n".join(lines)

    def to_dot(self) -> str:
        """Graphviz DOT source; initial nodes are drawn with thick borders as in the paper."""
        name = _dot_id(self.variable)
        lines = [f"digraph {name} {{", "  rankdir=LR;"]
        for mp in self.ordered_nodes():
            width = 3 if mp in self.initial_nodes else 1
            n_act = len(self.activations.get(mp, []))
            lines.append(f'  {_dot_id(mp)} [label="{mp}\\n({n_act})", penwidth={width}];')
        for s, t in sorted(self.edges):
            lines.append(f"  {_dot_id(s)} -> {_dot_id(t)};")
        lines.append("}")
        return "\n".join(lines)

    def to_dict(self) -> dict:
        """Structure only (no data), for checkpoints."""
        return {
            "variable": self.variable,
            "nodes": self.ordered_nodes(),
            "initial_nodes": sorted(self.initial_nodes),
            "edges": [list(e) for e in sorted(self.edges)],
            "n_activations": {mp: len(self.activations.get(mp, [])) for mp in self.ordered_nodes()},
        }

    @classmethod
    def from_dict(cls, d: dict) -> SequenceGraph:
        """Inverse of :meth:`to_dict`: the structure, without the activations."""
        g = cls(variable=str(d["variable"]))
        for mp in d["nodes"]:
            g.add_node(str(mp))
        g.initial_nodes = {str(mp) for mp in d["initial_nodes"]}
        g.edges = {(str(s), str(t)) for s, t in d["edges"]}
        return g


def _dot_id(name: str) -> str:
    escaped = name.replace('"', '\\"')
    return f'"{escaped}"'


def build_graph(demos: Sequence[Demonstration], variable: str) -> SequenceGraph:
    """Build the sequence graph of ``variable`` from labelled demonstrations (Algorithm 1).

    Every switch ``y[i-1] != y[i]`` adds the edge ``(y[i-1], y[i])`` if it is new, and starts a
    new activation of ``y[i]`` (so repeated MPs keep one activation per visit). Edges are added
    for every observed switch, also when the target node already exists.

    Args:
        demos: the labelled demonstrations.
        variable: the control variable.

    Returns:
        The graph, its activations indexing ``demos``.

    Raises:
        DataError: no demonstrations, or two MP names of ``variable`` that differ only by
            whitespace (naming both).
        UnknownMPError: a demonstration without labels for ``variable``.
    """
    if len(demos) == 0:
        raise DataError("cannot build a sequence graph from zero demonstrations; give at least one")
    graph = SequenceGraph(variable=variable)
    for m, demo in enumerate(demos):
        if variable not in demo.labels:
            raise UnknownMPError(
                f"{demo.name or f'demonstration {m}'} has no labels for control variable "
                f"{variable!r}; it labels: {', '.join(sorted(demo.labels))}"
            )
        segments = demo.segments(variable)
        graph.initial_nodes.add(segments[0].mp)
        previous: str | None = None
        for segment in segments:
            graph.add_node(segment.mp)
            if previous is not None:
                graph.edges.add((previous, segment.mp))
            graph.activations[segment.mp].append(replace(segment, demo=m))
            previous = segment.mp
    _check_distinct_names(demos, graph)
    return graph


def _check_distinct_names(demos: Sequence[Demonstration], graph: SequenceGraph) -> None:
    """Refuse MP names of one variable that differ only by whitespace (``"close"``, ``"close "``).

    Args:
        demos: the demonstrations ``graph`` was built from (to name where each name occurs).
        graph: the built graph.

    Raises:
        DataError: naming both spellings and a demonstration of each.
    """
    seen: dict[str, str] = {}
    for mp in sorted(graph.nodes):
        other = seen.setdefault("".join(mp.split()), mp)
        if other == mp:
            continue
        first = {name: graph.activations[name][0].demo for name in (other, mp)}
        where = {name: demos[m].name or f"demonstration {m}" for name, m in first.items()}
        raise DataError(
            f"control variable {graph.variable!r} has MP names that differ only by whitespace: "
            f"{other!r} (in {where[other]}) and {mp!r} (in {where[mp]}); label one MP with one "
            "name"
        )


def build_graphs(
    demos: Sequence[Demonstration], variables: Sequence[str] | None = None
) -> dict[str, SequenceGraph]:
    """One sequence graph per control variable (all variables of the first demo by default)."""
    if len(demos) == 0:
        raise DataError("cannot build sequence graphs from zero demonstrations; give at least one")
    names = sorted(demos[0].labels) if variables is None else list(variables)
    return {v: build_graph(demos, v) for v in names}
