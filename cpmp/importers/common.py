"""What the three importers share.

The imported record with its notes, feature-column selection and naming, label decoding and
the notes on cleaned streams.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from cpmp.data import Demonstration
from cpmp.errors import DataError
from cpmp.importers.resample import Relabelled, StreamReport, merge_short_activations
from cpmp.importers.spec import LabelNames, Selection


@dataclass(frozen=True)
class ImportNote:
    """Something an import changed or noticed, for the summary.

    Attributes:
        demo: the demonstration's name.
        kind: ``gap``, ``duplicates``, ``out_of_order``, ``glitch`` or ``window``.
        where: the topic, column, key or control variable concerned.
        text: one readable sentence (times in seconds from the demonstration's start).
    """

    demo: str
    kind: str
    where: str
    text: str


@dataclass(frozen=True)
class ImportedDemo:
    """One imported demonstration and what its import noted.

    Attributes:
        demo: the validated demonstration.
        notes: gaps, repaired stamps, merged glitches, the clock window.
        source: the recording it came from (bag directory, dataset, file#group).
    """

    demo: Demonstration
    notes: tuple[ImportNote, ...]
    source: str


@dataclass(frozen=True)
class FeatureBlock:
    """Columns that one feature entry contributes.

    Attributes:
        values: (n, k) float64 samples.
        names: k feature names.
    """

    values: np.ndarray
    names: list[str]


def pick_columns(selection: Selection, width: int, where: str) -> np.ndarray:
    """The element indices ``selection`` keeps out of ``width`` elements.

    Raises:
        DataError: an index or the slice lies outside ``0 .. width - 1``.
    """
    if selection.index is not None:
        bad = [i for i in selection.index if not 0 <= i < width]
        if bad:
            raise DataError(
                f"{where} has {width} element(s) but the mapping's index asks for {bad}; "
                f"use indices 0..{width - 1}"
            )
        return np.array(selection.index, dtype=np.int64)
    if selection.slice is not None:
        start, stop = selection.slice
        if stop > width:
            raise DataError(
                f"{where} has {width} element(s) but the mapping's slice is [{start}, {stop}]; "
                f"use a stop of at most {width}"
            )
        return np.arange(start, stop)
    return np.arange(width)


def column_names(
    selection: Selection, prefix: str, elements: Sequence[str], picked: np.ndarray, where: str
) -> list[str]:
    """Feature names of the picked elements.

    The mapping's ``names``, else ``<name or prefix>.<element>``, or just the prefix for a
    scalar (``elements == [""]``).

    Raises:
        DataError: ``names`` has another length than the picked elements (``where`` names the
            source).
    """
    if selection.names is not None:
        if len(selection.names) != len(picked):
            raise DataError(
                f"{where}: the mapping gives {len(selection.names)} names but {len(picked)} "
                "element(s) are selected; give one name per element (or pick with index/slice)"
            )
        return list(selection.names)
    base = selection.name or prefix
    if len(elements) == 1 and elements[0] == "":
        return [base]
    return [f"{base}.{elements[i]}" for i in picked]


def decode_labels(
    spec: LabelNames,
    raw: np.ndarray,
    where: str,
    table: Sequence[str] | Mapping[int, str] | None = None,
) -> np.ndarray:
    """Recorded label values as MP names.

    Integers go through ``spec.names`` (else ``table``, e.g. ``meta/subtasks.parquet``),
    strings (or bytes) are taken as they are; then ``spec.rename`` applies and, when
    ``spec.mps`` is set, every name must be one of them.

    Args:
        spec: the label's mapping entry.
        raw: (n,) recorded values.
        where: names the source in messages (``column subtask_index``).
        table: id -> name used where ``spec.names`` is not given.

    Returns:
        (n,) str MP names.

    Raises:
        DataError: integer ids with no names, an id outside the names, a non-integer number,
            an empty name or one outside ``spec.mps``.
    """
    values = np.asarray(raw)
    if values.dtype.kind == "S" or values.dtype.kind == "O":
        values = np.array(
            [v.decode("utf-8") if isinstance(v, bytes) else v for v in values.tolist()],
            dtype=object,
        )
        if not all(isinstance(v, str) for v in values):
            odd = next(v for v in values if not isinstance(v, str))
            raise DataError(f"{where} holds {odd!r}; labels must be MP names or integer ids")
        values = values.astype(str)
    if values.dtype.kind == "f":
        if not np.all(np.isfinite(values)) or np.any(values != np.round(values)):
            raise DataError(
                f"{where} holds non-integer numbers; labels must be MP names or integer ids"
            )
        values = values.astype(np.int64)
    if values.dtype.kind == "b":
        values = values.astype(np.int64)
    if values.dtype.kind in "iu":
        names = spec.names if spec.names is not None else table
        if names is None:
            raise DataError(
                f"{where} holds integer ids; give the control variable {spec.variable!r} "
                "names: [MP of id 0, MP of id 1, ...] in the mapping"
            )
        lookup = dict(enumerate(names)) if not isinstance(names, Mapping) else dict(names)
        unknown = sorted({int(i) for i in np.unique(values)} - set(lookup))
        if unknown:
            raise DataError(
                f"{where} holds id(s) {unknown} that have no name (known ids: "
                f"{sorted(lookup)}); extend the names of {spec.variable!r}"
            )
        values = np.array([lookup[int(i)] for i in values], dtype=str)
    if values.dtype.kind != "U":
        raise DataError(f"{where} has dtype {values.dtype}; labels must be MP names or integer ids")
    if spec.rename:
        values = np.array([spec.rename.get(v, v) for v in values.tolist()], dtype=str)
    empty = np.flatnonzero(np.char.str_len(np.char.strip(values)) == 0)
    if empty.size:
        raise DataError(
            f"{where} has an empty MP name at sample {empty[0]} ({empty.size} in all); label "
            "every sample with the active MP (e.g. 'hold' while idle)"
        )
    if spec.mps is not None:
        unknown_mps = sorted(set(np.unique(values).tolist()) - set(spec.mps))
        if unknown_mps:
            raise DataError(
                f"{where} names MP(s) {unknown_mps} that are not in the mapping's mps for "
                f"{spec.variable!r} ({', '.join(spec.mps)}); fix the recording or add them"
            )
    return values


def stream_notes(
    demo: str, report: StreamReport, on_gap: str, offset: float = 0.0
) -> list[ImportNote]:
    """Notes on one cleaned stream.

    Times are the report's minus ``offset`` [s] (the demonstration's first tick).

    Raises:
        DataError: ``on_gap == "error"`` and the stream has a gap.
    """
    notes = []
    where = report.stream
    if report.gaps and on_gap == "error":
        gap = report.gaps[0]
        raise DataError(
            f"{demo}: {where} is silent for {gap.duration:.3f} s ({gap.start - offset:.3f} s "
            f"to {gap.stop - offset:.3f} s; {len(report.gaps)} gap(s) in all); re-record it, "
            "raise max_gap or set on_gap: report"
        )
    for gap in report.gaps:
        notes.append(
            ImportNote(
                demo,
                "gap",
                where,
                f"{where} silent for {gap.duration:.3f} s "
                f"({gap.start - offset:.3f} s to {gap.stop - offset:.3f} s)",
            )
        )
    if report.n_duplicates:
        notes.append(
            ImportNote(
                demo,
                "duplicates",
                where,
                f"{where}: {report.n_duplicates} sample(s) with a repeated stamp dropped "
                "(the last received kept)",
            )
        )
    if report.n_out_of_order:
        notes.append(
            ImportNote(
                demo,
                "out_of_order",
                where,
                f"{where}: {report.n_out_of_order} sample(s) arrived out of order "
                "(sorted by stamp)",
            )
        )
    return notes


def debounce(
    demo: str, variable: str, time: np.ndarray, labels: np.ndarray, min_activation: float
) -> tuple[np.ndarray, list[ImportNote]]:
    """Merge activations shorter than ``min_activation`` [s]; one note per merged glitch."""
    result: Relabelled = merge_short_activations(time, labels, min_activation)
    notes = [
        ImportNote(
            demo,
            "glitch",
            variable,
            f"{variable}: {g.mp!r} at {g.start:.3f} s lasted {g.duration:.3f} s "
            f"(< min_activation {min_activation} s), merged into {g.merged_into!r}",
        )
        for g in result.glitches
    ]
    return result.labels, notes


def check_unique_names(blocks: Sequence[FeatureBlock], where: str) -> list[str]:
    """All feature names of ``blocks`` in order.

    Raises:
        DataError: two entries produce the same name.
    """
    names = [n for block in blocks for n in block.names]
    repeated = sorted({n for n in names if names.count(n) > 1})
    if repeated:
        raise DataError(
            f"{where}: feature name(s) {', '.join(repeated)} come from two mapping entries; "
            "give one of them name: or names:"
        )
    return names


def demo_name(stem: str) -> str:
    """A valid cpmp group name ``demo_<stem>`` (other characters become ``_``)."""
    clean = "".join(c if (c.isascii() and c.isalnum()) or c in "_.-" else "_" for c in stem)
    return clean if clean.startswith("demo_") else f"demo_{clean}"


__all__ = [
    "FeatureBlock",
    "ImportNote",
    "ImportedDemo",
    "check_unique_names",
    "column_names",
    "debounce",
    "decode_labels",
    "demo_name",
    "pick_columns",
    "stream_notes",
]
