"""Label glitches: one or two samples of another MP between two samples of the same MP.

A demonstration labelled ``A A A X A A`` (``X`` for at most :data:`GLITCH_SAMPLES` samples,
the same MP ``A`` on both sides) did not run ``X``: a labelling tool, a debounced button or a
resampled label stream flickered. Kept, the glitch adds the node ``X`` and the edges
``A -> X -> A`` to the variable's sequence graph, and closed loop may follow them (restart a
finished MP, enter a node it can hardly ever leave). :func:`repair_glitches` relabels such
samples with the MP around them before the graphs are built
(:meth:`~cpmp.sequencer.ConcurrentSequencer.fit_config`, ``repair_glitches=True`` by default)
and says what each repair would have added. Short activations between two *different* MPs
(``A A X B B``) are not repaired: :func:`cpmp.sequencer.fit_data.glitch_warnings` reports them.
"""

from __future__ import annotations

import dataclasses
import itertools
from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from cpmp.data import Demonstration
from cpmp.graph import build_graphs
from cpmp.records import JsonValue
from cpmp.sequencer.fit_data import GLITCH_SAMPLES


@dataclass(frozen=True)
class LabelGlitch:
    """One label glitch of one demonstration.

    Attributes:
        demo: the demonstration's name (``demonstration <i>`` without one).
        variable: the control variable.
        start: its first sample.
        stop: one past its last sample.
        glitch: the MP of the glitch's samples.
        around: the MP on both sides (what they are relabelled with).
        would_add: what keeping it would have added to the variable's graph: ``"X"`` for a
            node, ``"A -> X"`` for an edge, none of them demonstrated elsewhere.
    """

    demo: str
    variable: str
    start: int
    stop: int
    glitch: str
    around: str
    would_add: tuple[str, ...] = ()

    def describe(self) -> str:
        """One line for the fit summary's log."""
        added = ", ".join(self.would_add) if self.would_add else "nothing new"
        n = self.stop - self.start
        return (
            f"label glitch repaired: {self.demo}, {self.variable}: {n} sample(s) of "
            f"{self.glitch} between {self.around} and {self.around} (samples {self.start}-"
            f"{self.stop - 1}) relabelled {self.around}; kept, it would have added {added}"
        )

    def to_dict(self) -> dict[str, JsonValue]:
        """JSON-ready form (``fit_summary.label_glitches``)."""
        return {**dataclasses.asdict(self), "would_add": list(self.would_add)}


class Repair(NamedTuple):
    """Demonstrations with their label glitches repaired.

    Attributes:
        demos: the demonstrations, each repaired one a copy (the others as given).
        glitches: every repaired glitch, by demonstration, variable and sample.
    """

    demos: list[Demonstration]
    glitches: list[LabelGlitch]


def find_glitches(labels: np.ndarray, max_samples: int = GLITCH_SAMPLES) -> list[tuple[int, int]]:
    """The glitches of one variable's labels ``(n,)``.

    Args:
        labels: the MP at each sample.
        max_samples: the longest glitch, in samples.

    Returns:
        ``(start, stop)`` of every run of at most ``max_samples`` samples with the same MP
        on both sides, in order.
    """
    bounds = [0, *(np.flatnonzero(labels[1:] != labels[:-1]) + 1).tolist(), len(labels)]
    runs = list(itertools.pairwise(bounds))
    return [
        (a, b)
        for k, (a, b) in enumerate(runs[1:-1], start=1)
        if b - a <= max_samples and labels[runs[k - 1][0]] == labels[runs[k + 1][0]]
    ]


def repair_glitches(
    demos: Sequence[Demonstration],
    variables: Sequence[str] | None = None,
    max_samples: int = GLITCH_SAMPLES,
) -> Repair:
    """Relabel every label glitch with the MP around it.

    Args:
        demos: the demonstrations.
        variables: the control variables to repair (``None``: every labelled one).
        max_samples: the longest glitch, in samples.

    Returns:
        The repaired demonstrations and the glitches, each with what it would have added to
        the graphs built from the repaired demonstrations.
    """
    out: list[Demonstration] = []
    found: list[LabelGlitch] = []
    for i, demo in enumerate(demos):
        labels = dict(demo.labels)
        name = demo.name or f"demonstration {i}"
        changed = False
        for v in demo.variables if variables is None else [v for v in variables if v in labels]:
            fixed = labels[v]
            # one at a time, first to last: a flicker (A A X A X X) is one glitch, not two
            while runs := find_glitches(fixed, max_samples):
                a, b = runs[0]
                found.append(LabelGlitch(name, v, a, b, str(fixed[a]), str(fixed[a - 1])))
                fixed = fixed.copy()
                fixed[a:b] = fixed[a - 1]
            if fixed is not labels[v]:
                labels[v] = fixed
                changed = True
        out.append(dataclasses.replace(demo, labels=labels) if changed else demo)
    if not found:
        return Repair(out, [])
    graphs = build_graphs(out, sorted({g.variable for g in found}))
    glitches = []
    for g in found:
        graph = graphs[g.variable]
        added = [] if g.glitch in graph.nodes else [g.glitch]
        added += [
            f"{a} -> {b}"
            for a, b in ((g.around, g.glitch), (g.glitch, g.around))
            if (a, b) not in graph.edges
        ]
        glitches.append(dataclasses.replace(g, would_add=tuple(added)))
    return Repair(out, glitches)


__all__ = ["LabelGlitch", "Repair", "find_glitches", "repair_glitches"]
