"""What an import produced, as text.

Per demonstration its duration, rate and MP sequence per control variable, every note on what
the import changed or noticed (the clock window or resampling, repaired stamps, gaps, merged
glitches, moved switches, chattering signals), the demonstrations an ``on_error: skip`` import
left out and why, and the sequence graphs the demonstrations imply
(:func:`cpmp.graph.build_graphs`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cpmp.data import Demonstration, mp_sequences
from cpmp.graph import build_graphs
from cpmp.importers.convert import ImportResult


@dataclass(frozen=True)
class DemoSummary:
    """One demonstration at a glance.

    Attributes:
        name: the demonstration's name.
        split: ``train`` or ``test``.
        n_samples: time steps.
        duration: [s] last minus first sample time.
        rate: [Hz] mean sample rate.
        sequences: control variable -> its MPs in order (one entry per activation).
    """

    name: str
    split: str
    n_samples: int
    duration: float
    rate: float
    sequences: dict[str, list[str]]


def demo_summary(demo: Demonstration, split: str = "train") -> DemoSummary:
    """Summarise one demonstration."""
    return DemoSummary(
        name=str(demo.name),
        split=split,
        n_samples=demo.n_samples,
        duration=demo.duration,
        rate=(demo.n_samples - 1) / demo.duration,
        sequences=mp_sequences(demo),
    )


def summaries(result: ImportResult) -> list[DemoSummary]:
    """One :class:`DemoSummary` per imported demonstration, in file order."""
    split_of = {name: split for split, names in result.splits.items() for name in names}
    return [demo_summary(d, split_of.get(str(d.name), "train")) for d in result.demos]


def summary_text(result: ImportResult) -> str:
    """The import as readable text.

    A header, one block per demonstration, every note (each one changed the data shown or
    says what the recording lacked), the skipped demonstrations with their reasons, the
    features and the implied sequence graphs (``*`` marks initial MPs).
    """
    demos = result.demos
    first = demos[0]
    rows = summaries(result)
    skipped = f", skipped {len(result.skipped)}" if result.skipped else ""
    lines = [
        f"imported {len(demos)} demonstration(s){skipped} from {result.source} "
        f"({', '.join(result.inputs)}): {first.n_features} feature(s), control variable(s) "
        f"{', '.join(first.variables)}",
        "",
    ]
    width = max(len(v) for v in first.variables)
    for row in rows:
        lines.append(
            f"{row.name} [{row.split}]  {row.duration:.3f} s, {row.n_samples} samples at "
            f"{row.rate:.1f} Hz"
        )
        for variable, sequence in row.sequences.items():
            lines.append(f"    {variable:<{width}}  {' -> '.join(sequence)}")
    notes = result.notes
    if notes:
        lines += ["", f"notes ({len(notes)}):"]
        lines += [f"  {n.demo}: {n.text}" for n in notes]
    if result.skipped:
        lines += ["", f"skipped {len(result.skipped)} demonstration(s) (on_error: skip):"]
        lines += [f"  {s.demo} ({s.source}): {s.reason}" for s in result.skipped]
    durations = np.array([r.duration for r in rows])
    lines += [
        "",
        f"duration {durations.min():.3f} .. {durations.max():.3f} s "
        f"(mean {durations.mean():.3f} s)",
        f"features: {', '.join(first.feature_names)}",
        "",
        "sequence graphs (* = initial MP):",
    ]
    lines += [graph.to_text() for graph in build_graphs(demos).values()]
    if result.splits:
        counts = ", ".join(f"{split}: {len(names)}" for split, names in result.splits.items())
        lines += ["", f"splits: {counts}"]
    if result.skipped_path is not None:
        lines += [f"skipped demonstrations: {result.skipped_path}"]
    return "\n".join(lines)


__all__ = ["DemoSummary", "demo_summary", "summaries", "summary_text"]
