"""Read episode recordings back offline: summaries, views, text.

:func:`read_recording` (events, outcome, metadata), :func:`read_views` (the blueprint's
views) and :func:`format_summary`.
"""

from __future__ import annotations

import json
import math
import os
import uuid
import warnings
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, NamedTuple

from rerun.chunk import RrdReader
from rerun.error_utils import RerunWarning

from cpmp.errors import CpmpFileError
from cpmp.recordings.layout import (
    NOTE_ARCHETYPE,
    OUTCOME_ARCHETYPE,
    PROPERTY_NAME,
    START_ARCHETYPE,
    TRANSITION_ARCHETYPE,
    hold_text,
    outcome_text,
    start_table,
    start_text,
    transition_text,
)
from cpmp.records import (
    JsonValue,
    PendingSwitch,
    SequencerNote,
    StartDecision,
    StartOption,
    TransitionEvent,
)

if TYPE_CHECKING:
    import pyarrow as pa


class ViewInfo(NamedTuple):
    """One view of a recording's blueprint.

    ``kind`` (rerun's view class, e.g. ``TimeSeries``, ``TextLog``, ``StateTimeline``), display
    ``name``, ``origin`` entity path and the ``contents`` query lines (``+ features/box_x``).
    """

    kind: str
    name: str
    origin: str
    contents: list[str]


@dataclass
class RecordingSummary:
    """What :func:`read_recording` finds in an ``.rrd`` file.

    ``episodes``: episode names (recording name, else ``application_id/recording_id``), one per
    recording in the file. ``transitions``: in time order (a recording keeps no feature
    vector: their ``state`` is ``None``). ``notes``: in time order. ``outcome``/``reason``: of
    the last outcome logged, ``None`` if none. ``duration``: last time on the ``time`` timeline [s].
    ``n_ticks``: number of distinct ``tick`` values. ``entity_paths``: sorted, without the
    leading ``/`` and without recording properties. ``metadata``: the recorder's ``metadata``.
    ``feature_groups``: plot panel -> feature names (empty for files written before panels).
    ``start``: the start decision logged (``None`` if none), with its options and scores.
    ``note_texts``: each of ``notes`` as the events log shows it (a hold with how long it was
    held and what ended it: ``"...; held 0.63 s, until left_fingers switched to relax at
    9.91 s"``). ``cause``: an incomplete outcome's missing switch. ``start_correct``: the
    initial MPs the demonstrator uses for this episode (empty if unknown);
    ``start_references``: the training starts against this one, nearest first, each
    ``{"name", "combination", "values", "distance"}`` (distance in training ranges; empty for
    files written before they were kept).
    """

    episodes: list[str]
    transitions: list[TransitionEvent]
    outcome: str | None
    reason: str | None
    duration: float
    n_ticks: int
    entity_paths: list[str]
    metadata: dict[str, JsonValue] = field(default_factory=dict)
    notes: list[SequencerNote] = field(default_factory=list)
    feature_groups: dict[str, list[str]] = field(default_factory=dict)
    start: StartDecision | None = None
    note_texts: list[str] = field(default_factory=list)
    cause: PendingSwitch | None = None
    start_correct: dict[str, str] = field(default_factory=dict)
    start_references: list[dict[str, JsonValue]] = field(default_factory=list)

    def to_dict(self) -> dict[str, JsonValue]:
        """JSON-able dict of the fields, each transition and note as a dict with named fields.

        Transitions have no ``state``: a recording does not hold it. The start's options are
        ``{"combination", "score"}`` dicts.
        """
        data = asdict(self)
        data["transitions"] = [
            {k: v for k, v in asdict(event).items() if k != "state"} for event in self.transitions
        ]
        if self.start is not None:
            data["start"]["options"] = [o._asdict() for o in self.start.options]
        data["cause"] = self.cause.to_dict() if self.cause is not None else None
        return data


def _first(cell: object) -> object:
    """A component cell reads back as a list (one batch); return its first value or None."""
    if isinstance(cell, list):
        return cell[0] if cell else None
    return cell


def _times_seconds(batch: pa.RecordBatch) -> list[float] | None:
    if "time" not in batch.schema.names:
        return None
    column = batch.column("time")
    raw = column.cast("int64").to_pylist()
    scale = 1e-9 if str(column.type).startswith(("duration", "timestamp")) else 1.0
    return [math.nan if value is None else value * scale for value in raw]


def _timed_rows(entity: str, batch: pa.RecordBatch, times: list[float]) -> list[float]:
    """The times of ``batch``'s rows that count for the episode's duration [s].

    An event's continuation rows in the events log sit a few microseconds after it (the
    writer's ``ROW_STEP``, so that they sort as written); only the event's own row, the one
    with its record (a ``cpmp.*`` column), counts, at the time its record holds
    (:func:`_event_times`).
    """
    if not entity.startswith("events/"):
        return times
    records = [name for name in batch.schema.names if name.startswith("cpmp.")]
    if not records:
        return []
    archetype = records[0].partition(":")[0]
    valid = batch.column(records[0]).is_valid().to_pylist()
    own = _event_times(batch, archetype, times)
    return [t for t, ok in zip(own, valid, strict=True) if ok]


def _event_times(batch: pa.RecordBatch, archetype: str, times: list[float]) -> list[float]:
    """The time [s] of each row's ``archetype`` record: its ``t`` field, else the row's time.

    The writer logs an event after the rows of one logged before it at the same time, a few
    microseconds later (its ``ROW_STEP``), and keeps the event's time in its record (files
    written before have no ``t``: there the row's time is the event's).
    """
    column = f"{archetype}:t"
    if column not in batch.schema.names:
        return times
    own = [_first(value) for value in batch.column(column).to_pylist()]
    return [t if value is None else float(value) for t, value in zip(times, own, strict=True)]


def _open(path: str | os.PathLike[str]) -> tuple[Path, RrdReader]:
    """``(path, RrdReader)``; :class:`~cpmp.errors.CpmpFileError` for a missing path."""
    file = Path(path)
    if not file.exists():
        raise CpmpFileError(f"recording {file} does not exist")
    if not file.is_file():
        raise CpmpFileError(f"recording {file} is not a file")
    try:
        return file, RrdReader(file)
    except (RuntimeError, ValueError, OSError) as err:
        raise CpmpFileError(f"cannot read {file} as a rerun recording (.rrd): {err}") from err


def read_recording(path: str | os.PathLike[str]) -> RecordingSummary:
    """Read an ``.rrd`` file back offline and summarise it (see :class:`RecordingSummary`).

    Raises:
        CpmpFileError: ``path`` is missing or not a rerun recording.
    """
    try:
        with warnings.catch_warnings():
            # A truncated file warns about its missing footer before failing: the error says it.
            warnings.simplefilter("ignore", RerunWarning)
            file, reader = _open(path)
            stores = reader.recordings()
            batches = [
                (index, store, chunk.entity_path, chunk.to_record_batch())
                for index, store in enumerate(stores)
                for chunk in reader.stream(store=store)
            ]
    except CpmpFileError:
        raise
    except (RuntimeError, ValueError, OSError) as err:
        raise CpmpFileError(f"cannot read {path} as a rerun recording (.rrd): {err}") from err
    if not stores:
        raise CpmpFileError(f"{file} contains no rerun recording")

    names: dict[int, str] = {}
    metadata: dict[str, JsonValue] = {}
    feature_groups: dict[str, list[str]] = {}
    ticks: dict[int, set[int]] = {index: set() for index in range(len(stores))}
    entity_paths: set[str] = set()
    transitions: list[TransitionEvent] = []
    notes: list[tuple[SequencerNote, str]] = []
    outcomes: list[tuple[float, int, str, str, PendingSwitch | None]] = []
    start: StartDecision | None = None
    start_correct: dict[str, str] = {}
    start_references: list[dict[str, JsonValue]] = []
    duration = 0.0
    for index, _store, entity_path, batch in batches:
        columns = batch.schema.names
        entity = entity_path.lstrip("/")
        if entity.startswith("__properties"):
            if "RecordingInfo:name" in columns:
                names[index] = str(_first(batch.column("RecordingInfo:name")[0].as_py()))
            if entity == f"__properties/{PROPERTY_NAME}":
                if "metadata" in columns:
                    metadata = json.loads(_first(batch.column("metadata")[0].as_py()) or "{}")
                if "feature_groups" in columns:
                    cell = _first(batch.column("feature_groups")[0].as_py())
                    feature_groups = json.loads(cell or "{}")
            continue
        entity_paths.add(entity)
        times = _times_seconds(batch)
        if times:
            finite = [t for t in _timed_rows(entity, batch, times) if math.isfinite(t)]
            duration = max([duration, *finite])
        if "tick" in columns:
            ticks[index].update(v for v in batch.column("tick").to_pylist() if v is not None)
        if times is None:
            continue
        if f"{TRANSITION_ARCHETYPE}:variable" in columns:
            fields = {
                name: batch.column(f"{TRANSITION_ARCHETYPE}:{name}").to_pylist()
                for name in ("variable", "source", "target", "probability")
            }
            kind_column = f"{TRANSITION_ARCHETYPE}:kind"
            kinds = (
                batch.column(kind_column).to_pylist()
                if kind_column in columns
                else [None] * len(times)
            )
            for row, t in enumerate(_event_times(batch, TRANSITION_ARCHETYPE, times)):
                if _first(fields["variable"][row]) is None:
                    continue
                transitions.append(
                    TransitionEvent(
                        t=t,
                        variable=str(_first(fields["variable"][row])),
                        source=str(_first(fields["source"][row])),
                        target=str(_first(fields["target"][row])),
                        probability=float(_first(fields["probability"][row])),
                        kind=str(_first(kinds[row]) or "switch"),
                    )
                )
        if f"{NOTE_ARCHETYPE}:kind" in columns:
            cells = {
                name: batch.column(f"{NOTE_ARCHETYPE}:{name}").to_pylist()
                if f"{NOTE_ARCHETYPE}:{name}" in columns
                else [None] * len(times)
                for name in ("kind", "variable", "text", "until", "count", "ended_by", "then")
            }
            for row, t in enumerate(_event_times(batch, NOTE_ARCHETYPE, times)):
                if _first(cells["kind"][row]) is not None:
                    note = SequencerNote(
                        t,
                        str(_first(cells["kind"][row])),
                        str(_first(cells["variable"][row]) or ""),
                        str(_first(cells["text"][row]) or ""),
                    )
                    notes.append(
                        (note, _note_text(note, {k: _first(v[row]) for k, v in cells.items()}))
                    )
        if f"{START_ARCHETYPE}:rule" in columns:
            cells = {
                name: batch.column(f"{START_ARCHETYPE}:{name}").to_pylist()
                for name in ("rule", "chosen", "options")
            }
            for name in ("correct", "references"):
                cells[name] = (
                    batch.column(f"{START_ARCHETYPE}:{name}").to_pylist()
                    if f"{START_ARCHETYPE}:{name}" in columns
                    else [None] * len(times)
                )
            for row, t in enumerate(_event_times(batch, START_ARCHETYPE, times)):
                if _first(cells["rule"][row]) is not None:
                    start_correct = json.loads(_first(cells["correct"][row]) or "{}")
                    start_references = json.loads(_first(cells["references"][row]) or "[]")
                    options = json.loads(_first(cells["options"][row]) or "[]")
                    start = StartDecision(
                        t,
                        str(_first(cells["rule"][row])),
                        [StartOption(dict(o["combination"]), float(o["score"])) for o in options],
                        json.loads(_first(cells["chosen"][row]) or "{}"),
                    )
        if f"{OUTCOME_ARCHETYPE}:outcome" in columns:
            outcome_column = batch.column(f"{OUTCOME_ARCHETYPE}:outcome").to_pylist()
            reason_column, cause_column = (
                batch.column(f"{OUTCOME_ARCHETYPE}:{name}").to_pylist()
                if f"{OUTCOME_ARCHETYPE}:{name}" in columns
                else [None] * len(times)
                for name in ("reason", "cause")
            )
            for row, t in enumerate(_event_times(batch, OUTCOME_ARCHETYPE, times)):
                outcome = _first(outcome_column[row])
                if outcome is not None:
                    reason = _first(reason_column[row])
                    cause = _first(cause_column[row])
                    found = PendingSwitch.from_dict(json.loads(cause)) if cause else None
                    outcomes.append((t, len(outcomes), str(outcome), str(reason or ""), found))

    transitions.sort(key=lambda event: event.t)
    notes.sort(key=lambda pair: pair[0].t)
    last_outcome = max(outcomes, default=None)
    episodes = [
        names.get(index, f"{store.application_id}/{store.recording_id}")
        for index, store in enumerate(stores)
    ]
    return RecordingSummary(
        episodes=episodes,
        transitions=transitions,
        outcome=last_outcome[2] if last_outcome else None,
        reason=last_outcome[3] if last_outcome else None,
        cause=last_outcome[4] if last_outcome else None,
        duration=duration,
        n_ticks=sum(len(values) for values in ticks.values()),
        entity_paths=sorted(entity_paths),
        metadata=metadata,
        notes=[note for note, _ in notes],
        feature_groups=feature_groups,
        start=start,
        start_correct=start_correct,
        start_references=start_references,
        note_texts=[text for _, text in notes],
    )


def _note_text(note: SequencerNote, cells: dict[str, JsonValue]) -> str:
    """A note's text as the events log shows it: a hold's with how long it was held.

    ``cells``: the note record's ``until`` [s], ``count``, ``ended_by`` and ``then`` (a hold
    logged when it ended; ``None`` for other notes). A file written before ``ended_by`` was
    recorded gets the duration and the end time.
    """
    until, count = cells.get("until"), cells.get("count")
    if note.kind != "hold" or until is None:
        return note.text
    ended_by = cells.get("ended_by")
    if ended_by in ("switch", "hold", "end"):
        then = str(cells.get("then") or "")
        return hold_text(
            note.text, note.t, float(until), ended_by, int(count or 1), note.variable, then
        )
    noted = f" (noted {count} times)" if count and count > 1 else ""
    held = max(float(until) - note.t, 0.0)
    return f"{note.text}; held {held:.2f} s, until {float(until):.2f} s{noted}"


def read_views(path: str | os.PathLike[str]) -> list[ViewInfo]:
    """The views of the default blueprint stored in an ``.rrd`` file, in layout order.

    Depth first from the root container; ``[]`` if the file has no blueprint.

    Raises:
        CpmpFileError: ``path`` is missing or not a rerun recording.
    """
    views: dict[str, dict[str, str | list[str]]] = {}
    containers: dict[str, list[str]] = {}
    root = None
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RerunWarning)
            _, reader = _open(path)
            blueprints = reader.blueprints()
            chunks = [chunk for store in blueprints[:1] for chunk in reader.stream(store=store)]
    except CpmpFileError:
        raise
    except (RuntimeError, ValueError, OSError) as err:
        raise CpmpFileError(f"cannot read {path} as a rerun recording (.rrd): {err}") from err
    for chunk in chunks:
        batch = chunk.to_record_batch()
        columns = batch.schema.names
        entity = chunk.entity_path.strip("/")

        # The last row of a column holds the blueprint's current value.
        cells = {
            name: batch.column(name)[batch.num_rows - 1].as_py()
            for name in columns
            if name.startswith(
                ("Viewport", "ContainerBlueprint:", "ViewBlueprint:", "ViewContents:")
            )
        }
        if "ViewportBlueprint:root_container" in cells:
            root = _first(cells["ViewportBlueprint:root_container"])
        if "ContainerBlueprint:contents" in cells:
            containers[entity] = [str(c) for c in cells["ContainerBlueprint:contents"] or []]
        if "ViewBlueprint:class_identifier" in cells:
            view = views.setdefault(entity, {})
            view["kind"] = str(_first(cells["ViewBlueprint:class_identifier"]))
            view["name"] = str(_first(cells.get("ViewBlueprint:display_name")) or "")
            view["origin"] = str(_first(cells.get("ViewBlueprint:space_origin")) or "")
        if "ViewContents:query" in cells and entity.endswith("/ViewContents"):
            query = cells["ViewContents:query"] or []
            views.setdefault(entity.removesuffix("/ViewContents"), {})["contents"] = query

    order: list[str] = []

    def visit(container: str) -> None:
        for child in (c.strip("/") for c in containers.get(container, [])):
            if child in views:
                order.append(child)
            else:
                visit(child)

    if root is not None:
        visit(f"container/{uuid.UUID(bytes=bytes(root))}")
    order += [key for key in views if key not in order]
    return [
        ViewInfo(
            views[key].get("kind", ""),
            views[key].get("name", ""),
            views[key].get("origin", ""),
            [str(line) for line in views[key].get("contents") or []],
        )
        for key in dict.fromkeys(order)
        if "kind" in views[key]
    ]


def format_summary(summary: RecordingSummary) -> str:
    """Human-readable multi-line text of a :class:`RecordingSummary`."""
    lines = [
        f"episode: {', '.join(summary.episodes)}",
        f"ticks: {summary.n_ticks}, duration: {summary.duration:.3f} s",
    ]
    if summary.feature_groups:
        panels = ", ".join(f"{g} ({len(m)})" for g, m in summary.feature_groups.items())
        lines.append(f"feature panels: {panels}")
    if summary.start is not None:
        lines.append(f"t={summary.start.t:8.3f} s  {start_text(summary.start)}")
        lines.append(f"  start options ({len(summary.start.options)}, by score, best first):")
        lines += [f"  {line}" for line in start_table(summary.start)]
        if summary.start_correct:
            right = ", ".join(f"{v}={mp}" for v, mp in sorted(summary.start_correct.items()))
            lines.append(f"  the demonstrator starts this episode with {right}")
        if summary.start_references:
            lines.append("  training starts, nearest first (distance in training ranges):")
            for ref in summary.start_references:
                values = ", ".join(f"{a} {v:.3f}" for a, v in ref["values"].items())
                combo = ", ".join(f"{v}={mp}" for v, mp in sorted(ref["combination"].items()))
                lines.append(f"    {ref['distance']:6.2f}  {ref['name']}: {values}; {combo}")
    lines.append(f"transitions ({len(summary.transitions)}):")
    lines += [
        f"  t={e.t:8.3f} s  "
        + transition_text(e.variable, e.source, e.target, e.probability, e.kind)
        for e in summary.transitions
    ]
    if summary.notes:
        lines.append(f"notes ({len(summary.notes)}):")
        texts = summary.note_texts or [n.text for n in summary.notes]
        lines += [
            f"  t={n.t:8.3f} s  {n.kind}: {text}"
            for n, text in zip(summary.notes, texts, strict=True)
        ]
    if summary.outcome is None:
        lines.append("outcome: none recorded")
    else:
        lines.append(outcome_text(summary.outcome, summary.reason or ""))
    if summary.cause is not None:
        lines += cause_lines(summary.cause)
    return "\n".join(lines)


def cause_lines(cause: PendingSwitch) -> list[str]:
    """An incomplete episode's cause as :func:`format_summary` prints it: words, then fields."""
    fields = ", ".join(
        f"{k}={'–' if v is None else (f'{v:.3f}' if isinstance(v, float) else v)}"
        for k, v in cause.to_dict().items()
        if v not in ("", None) or k in ("variable", "expected", "best_p")
    )
    return [f"cause: {cause.describe()}", f"  {fields}"]


__all__ = [
    "RecordingSummary",
    "SequencerNote",
    "TransitionEvent",
    "ViewInfo",
    "format_summary",
    "read_recording",
    "read_views",
]
