"""What the three importers share.

The imported record with its notes, the record of a skipped demonstration and the loop that
skips (``on_error: skip``), feature-column selection, naming and derived velocities, label
decoding, and the notes on cleaned streams and moved switches.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from cpmp.data import Demonstration
from cpmp.errors import CpmpError, DataError
from cpmp.importers.resample import Relabelled, StreamReport, merge_short_activations
from cpmp.importers.spec import LabelNames, Selection


@dataclass(frozen=True)
class ImportNote:
    """Something an import changed or noticed, for the summary.

    Attributes:
        demo: the demonstration's name.
        kind: ``gap``, ``duplicates``, ``out_of_order``, ``glitch``, ``switch_moved``,
            ``chatter``, ``flip`` (quaternion signs aligned) or ``window`` (the clock: a trimmed
            span, a resampling).
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
class SkippedDemo:
    """A demonstration left out of an ``on_error: skip`` import, and why.

    Attributes:
        demo: the name it would have had.
        source: the recording (bag, ``dataset#episode_<i>``, ``file#demo_<i>``).
        error: the error's class (``DataError``, ``CpmpFileError``, ...).
        reason: the error's message (what is wrong and what to do).
    """

    demo: str
    source: str
    error: str
    reason: str

    def to_dict(self) -> dict[str, str]:
        """The record as a JSON-ready dict."""
        return {
            "demo": self.demo,
            "source": self.source,
            "error": self.error,
            "reason": self.reason,
        }


@dataclass(frozen=True)
class DemoReader:
    """How to read one demonstration, for the per-demonstration loop of :func:`read_each`.

    Attributes:
        demo: the demonstration's name.
        source: the recording it comes from.
        read: reads and checks it; raises a :class:`~cpmp.errors.CpmpError` when it cannot.
    """

    demo: str
    source: str
    read: Callable[[], ImportedDemo]


def read_each(
    readers: Iterable[DemoReader], skipped: list[SkippedDemo] | None = None
) -> list[ImportedDemo]:
    """Read every demonstration of ``readers`` in order.

    Args:
        readers: one reader per demonstration.
        skipped: ``None``: the first error is raised (all or nothing); a list: a demonstration
            that raises a :class:`~cpmp.errors.CpmpError` is left out and recorded there.

    Returns:
        The demonstrations that were read.
    """
    out = []
    for reader in readers:
        if skipped is None:
            out.append(reader.read())
            continue
        try:
            out.append(reader.read())
        except CpmpError as err:
            reason = " ".join(str(err).split())
            skipped.append(SkippedDemo(reader.demo, reader.source, type(err).__name__, reason))
    return out


def velocity(time: np.ndarray, values: np.ndarray, where: str) -> np.ndarray:
    """Time derivatives of ``values`` (n, k) sampled at ``time`` (n,) [s].

    Central differences inside, one-sided at the ends (:func:`numpy.gradient`).

    Raises:
        DataError: fewer than two samples, or times that do not increase.
    """
    if len(time) < 2:
        raise DataError(f"{where}: a velocity needs at least two samples, got {len(time)}")
    if np.any(np.diff(time) <= 0):
        raise DataError(f"{where}: the sample times do not increase; cannot derive a velocity")
    return np.gradient(values, time, axis=0)


def derived_names(names: Sequence[str], derive: str | None, explicit: bool) -> list[str]:
    """Feature names of a derived entry: ``<name>.vel`` unless the mapping named them."""
    if derive is None or explicit:
        return list(names)
    return [f"{n}.vel" for n in names]


def velocity_hint(name: str, derive_from: str, what: str) -> str:
    """The fix for a missing velocity ``name``: map it if recorded, or derive it.

    Empty when ``name`` does not look like a velocity (``vel`` in it).
    """
    if "vel" not in name.lower():
        return ""
    return (
        f"; if the recording has no velocity, derive one from the positions: "
        f"{{{what}: {derive_from}, derive: velocity}}"
    )


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
    """Merge activations shorter than ``min_activation`` [s].

    One note per merged glitch, and one per switch the merging moved (saying from when to
    when and by how much).
    """
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
    if result.glitches:
        notes += moved_switches(demo, variable, time, labels, result.labels, "min_activation")
    return result.labels, notes


def moved_switches(
    demo: str,
    variable: str,
    time: np.ndarray,
    recorded: np.ndarray,
    cleaned: np.ndarray,
    why: str,
) -> list[ImportNote]:
    """Notes on switches that cleaning moved later than recorded.

    A switch into MP ``m`` of the cleaned labels is compared with the first recorded switch
    into ``m`` since the cleaned labels' previous switch.
    """
    recorded, cleaned = np.asarray(recorded), np.asarray(cleaned)
    notes = []
    switches = np.flatnonzero(cleaned[1:] != cleaned[:-1]) + 1
    previous = 0
    for b in switches.tolist():
        into = recorded[previous + 1 : b + 1] == cleaned[b]
        before = recorded[previous:b] != cleaned[b]
        firsts = np.flatnonzero(into & before) + previous + 1
        if firsts.size and firsts[0] < b:
            a = int(firsts[0])
            notes.append(
                ImportNote(
                    demo,
                    "switch_moved",
                    variable,
                    f"{variable}: the switch {cleaned[b - 1]} -> {cleaned[b]} moved from "
                    f"{time[a]:.3f} s (first recorded) to {time[b]:.3f} s "
                    f"(+{time[b] - time[a]:.3f} s, {why})",
                )
            )
        previous = b
    return notes


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
    """A valid cpmp group name ``demo_<stem>``.

    Demonstration names are stored as ASCII (``/data/demo_*``, ``mask/<split>``): a stem with
    non-ASCII letters or digits (``試行_2``) is written in Punycode first, as internationalised
    domain names are (``xn--_2-1e9fv5e``), so every letter is kept and distinct stems stay
    distinct (``name.removeprefix("demo_xn--").encode().decode("punycode")`` gives the stem
    back). Other characters become ``_``.
    """
    if any(not c.isascii() and c.isalnum() for c in stem):
        stem = "xn--" + stem.encode("punycode").decode("ascii")
    clean = "".join(c if (c.isascii() and c.isalnum()) or c in "_.-" else "_" for c in stem)
    return clean if clean.startswith("demo_") else f"demo_{clean}"


__all__ = [
    "DemoReader",
    "FeatureBlock",
    "ImportNote",
    "ImportedDemo",
    "SkippedDemo",
    "check_unique_names",
    "column_names",
    "debounce",
    "decode_labels",
    "demo_name",
    "derived_names",
    "moved_switches",
    "pick_columns",
    "read_each",
    "stream_notes",
    "velocity",
    "velocity_hint",
]
