"""Sequence graphs (cpmp.graph): nodes, edges, initial nodes, activations, text/dot output,
dict round trip and unknown names."""

from dataclasses import replace

import numpy as np
import pytest

from cpmp.data.demonstration import Demonstration
from cpmp.errors import CpmpError, DataError, UnknownMPError
from cpmp.graph import SequenceGraph, build_graph, build_graphs


def _demo(labels_a, labels_b=None, name=None):
    n = len(labels_a)
    labels = {"a": np.array(labels_a)}
    if labels_b is not None:
        labels["b"] = np.array(labels_b)
    x = np.arange(n, dtype=float)[:, None] * np.array([[1.0, 0.5]])
    return Demonstration(time=np.arange(n) * 0.1, features=x, labels=labels, name=name)


@pytest.fixture
def demos():
    # demo 0: A A B B A C  (A repeated -> cycle A->B->A), demo 1: B B C C (second initial node)
    return [
        _demo(["A", "A", "B", "B", "A", "C"], ["x"] * 6, name="demo_0"),
        _demo(["B", "B", "C", "C"], ["x", "y", "y", "x"], name="demo_1"),
    ]


def test_nodes_edges_initial(demos):
    g = build_graph(demos, "a")
    assert g.nodes == {"A", "B", "C"}
    assert g.initial_nodes == {"A", "B"}
    assert g.edges == {("A", "B"), ("B", "A"), ("A", "C"), ("B", "C")}
    assert g.successors("A") == ["B", "C"]
    assert g.successors("C") == []
    assert g.predecessors("C") == ["A", "B"]


def test_edge_added_when_target_node_exists(demos):
    # B -> C in demo 1 goes to a node that demo 0 created already; the paper's text (not the
    # indentation of Algorithm 1) says the edge is still added.
    assert ("B", "C") in build_graph(demos, "a").edges


def test_activations_split_by_labels(demos):
    g = build_graph(demos, "a")
    acts = g.activations["A"]
    assert [(a.demo, a.start, a.stop) for a in acts] == [(0, 0, 2), (0, 4, 5)]
    assert [(a.demo, a.start, a.stop) for a in g.activations["B"]] == [(0, 2, 4), (1, 0, 2)]
    np.testing.assert_array_equal(acts[1].features, demos[0].features[4:5])
    np.testing.assert_array_equal(acts[0].time, demos[0].time[0:2])
    assert sum(len(v) for v in g.activations.values()) == 6


def test_activations_are_the_demonstrations_segments(demos):
    """The graph keeps the demonstrations' own activations, marked with the demo's index."""
    g = build_graph(demos, "a")
    for m, demo in enumerate(demos):
        for segment in demo.segments("a"):
            (same,) = [a for a in g.activations[segment.mp] if a == replace(segment, demo=m)]
            assert same.features.base is demo.features  # a view, not a copy


def test_build_graphs_all_variables(demos):
    graphs = build_graphs(demos)
    assert sorted(graphs) == ["a", "b"]
    assert graphs["b"].edges == {("x", "y"), ("y", "x")}
    assert graphs["b"].initial_nodes == {"x"}


def test_text_and_dot(demos):
    g = build_graph(demos, "a")
    text = g.to_text()
    assert "* A [2 activations] -> B, C" in text
    assert "C [2 activations] -> (terminal)" in text
    dot = g.to_dot()
    assert dot.startswith('digraph "a" {')
    assert '"A" -> "B";' in dot and '"B" -> "A";' in dot
    assert "penwidth=3" in dot


def test_dict_round_trip(demos):
    g = build_graph(demos, "a")
    h = SequenceGraph.from_dict(g.to_dict())
    assert (h.nodes, h.initial_nodes, h.edges) == (g.nodes, g.initial_nodes, g.edges)


def test_unknown_variable_and_mp(demos):
    with pytest.raises(UnknownMPError, match="no labels for control variable 'zz'"):
        build_graph(demos, "zz")
    g = build_graph(demos, "a")
    with pytest.raises(UnknownMPError, match="known MPs: A, B, C"):
        g.successors("Q")
    with pytest.raises(DataError, match="zero demonstrations"):
        build_graphs([])
    assert issubclass(UnknownMPError, CpmpError)


def test_mp_names_differing_only_by_whitespace_are_refused_naming_both():
    demos = [_demo(["A", "A", "close"], name="demo_0"), _demo(["A", "close ", "close "], name="d1")]
    with pytest.raises(
        DataError, match=r"differ only by whitespace: 'close' \(in demo_0\) and 'close ' \(in d1\)"
    ):
        build_graph(demos, "a")
    with pytest.raises(DataError, match=r"'pick up' .* and 'pickup'"):
        build_graph([_demo(["pick up", "pickup"])], "a")
