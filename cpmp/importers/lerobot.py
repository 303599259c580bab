"""LeRobot datasets on local disk (the v3 layout) as demonstrations, read with pyarrow.

The v3 layout (``codebase_version`` ``v3.x``, written by lerobot 0.4 to 0.6): ``meta/info.json``
(``fps``, ``features`` with each column's dtype, shape and element ``names``), frames in
``data/chunk-*/file-*.parquet`` (many episodes per file; columns ``timestamp``,
``frame_index``, ``episode_index``, ``observation.state``, ...) and per-episode metadata in
``meta/episodes/chunk-*/file-*.parquet``. Videos are not read: cpmp's features are
low-dimensional columns.

One episode is one demonstration (``demo_<episode_index>``). A control variable's labels come
from one of:

- a per-frame column (strings, or integer ids with ``names``), or ``subtask_index`` with its
  texts in ``meta/subtasks.parquet`` (lerobot 0.4.4 - 0.5.x; stored as pandas' index column
  ``subtask``);
- ``language_persistent`` (lerobot >= 0.6, ``lerobot-annotate``): every frame of an episode
  holds the episode's persistent rows (``role``, ``content``, ``style``, ``timestamp``, ...);
  a row of style ``subtask`` (or ``motion``) names what is active from its ``timestamp``
  until the next row of that style (lerobot's ``active_at``);
- SARM annotations in ``meta/episodes`` (``sparse_subtask_names``,
  ``sparse_subtask_start_frames``, ..., or ``dense_*``): subtask ``k`` is active from its start
  frame until the next one starts.
"""

from __future__ import annotations

import functools
import json
import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from cpmp.data import Demonstration
from cpmp.errors import CpmpFileError, DataError
from cpmp.importers.common import (
    DemoReader,
    FeatureBlock,
    ImportedDemo,
    ImportNote,
    SkippedDemo,
    check_unique_names,
    column_names,
    debounce,
    decode_labels,
    derived_names,
    pick_columns,
    read_each,
    stream_notes,
    velocity,
    velocity_hint,
)
from cpmp.importers.resample import clean_stream, interpolate_linear, uniform_clock, zero_order_hold
from cpmp.importers.spec import ColumnFeature, ColumnLabel, LeRobotSpec
from cpmp.records import JsonValue

INFO_PATH = "meta/info.json"
SUBTASKS_PATH = "meta/subtasks.parquet"
DATA_GLOB = "data/*/*.parquet"
EPISODES_GLOB = "meta/episodes/*/*.parquet"
LANGUAGE_COLUMN = "language_persistent"
SUPPORTED_VERSION = 3
"""The major ``codebase_version`` cpmp reads (``v3.0``: lerobot 0.4 - 0.6.1)."""
TESTED_RELEASES = "lerobot 0.4.4 - 0.6.1"
"""The releases whose layout the tests write (docs/importing.md)."""
_INDEX_COLUMNS = ("episode_index", "frame_index", "timestamp")
_TIME_TOLERANCE = 1e-4
"""[s] a language row stamped this close before a frame is active at that frame."""


@dataclass(frozen=True)
class LeRobotInfo:
    """What cpmp reads from ``meta/info.json``.

    Attributes:
        version: ``codebase_version`` (``v3.0``).
        fps: [Hz] the recording's frame rate.
        features: column -> its entry (``dtype``, ``shape``, ``names``).
    """

    version: str
    fps: float
    features: dict[str, JsonValue]


def read_info(root: str | os.PathLike[str]) -> LeRobotInfo:
    """Read and check ``meta/info.json`` of the dataset at ``root``.

    Raises:
        CpmpFileError: no dataset there, unreadable JSON, a version other than v3, no fps.
    """
    root = Path(root)
    path = root / INFO_PATH
    if not path.is_file():
        raise CpmpFileError(
            f"{root} is not a LeRobot dataset: {INFO_PATH} is missing; give the dataset's root "
            "folder (the one holding meta/ and data/)"
        )
    try:
        info = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise CpmpFileError(f"cannot read {path}: {err}") from None
    if not isinstance(info, dict):
        raise CpmpFileError(f"{path} must hold a JSON object")
    version = str(info.get("codebase_version", ""))
    _check_version(version, path)
    fps = info.get("fps")
    if isinstance(fps, bool) or not isinstance(fps, (int, float)) or not fps > 0:
        raise CpmpFileError(f"{path}: fps must be a positive number, got {fps!r}")
    features = info.get("features")
    return LeRobotInfo(version, float(fps), features if isinstance(features, dict) else {})


def _check_version(version: str, path: Path) -> None:
    """Accept ``v3.x``; say what to do with an older, newer or unreadable version."""
    match = re.fullmatch(r"v(\d+)(?:\.\d+)*", version)
    supported = f"cpmp reads the LeRobot v3 layout (codebase_version v3.x, {TESTED_RELEASES})"
    if match is None:
        raise CpmpFileError(
            f"{path}: codebase_version is {version or 'missing'!r}, not a version like v3.0; "
            f"{supported}"
        )
    major = int(match.group(1))
    if major < SUPPORTED_VERSION:
        raise CpmpFileError(
            f"{path}: codebase_version is {version}, older than the v3 layout; {supported} "
            "(many episodes per data/chunk-*/file-*.parquet); convert the dataset with "
            "lerobot's convert_dataset_v21_to_v30 first"
        )
    if major > SUPPORTED_VERSION:
        raise CpmpFileError(
            f"{path}: codebase_version is {version}, newer than the layouts cpmp knows; "
            f"{supported}; export the dataset with a lerobot release that writes v3.0 or use a "
            "cpmp that reads this version"
        )


def read_lerobot(
    root: str | os.PathLike[str],
    spec: LeRobotSpec,
    *,
    skipped: list[SkippedDemo] | None = None,
) -> list[ImportedDemo]:
    """Import the episodes of the LeRobot dataset at ``root`` with ``spec``.

    Args:
        root: the dataset's root folder (holding ``meta/`` and ``data/``).
        spec: the mapping.
        skipped: ``None``: a bad episode raises; a list: a bad episode is left out and
            recorded there (``on_error: skip``).

    Returns:
        One demonstration per episode (``demo_<episode_index>``, in episode order), on the
        recorded frames or, with ``spec.rate``, resampled onto a clock of that rate.

    Raises:
        CpmpFileError: not a v3 dataset, no or unreadable parquet files.
        DataError: a mapped column is missing, not numeric (features), a data file has no
            rows, an episode asked for is not there; per episode (unless skipped): NaN
            features, empty labels, integer labels without names, frames before the first
            subtask.
    """
    root = Path(root)
    info = read_info(root)
    files = sorted(root.glob(DATA_GLOB))
    if not files:
        raise CpmpFileError(f"{root}: no frames in {DATA_GLOB}; is the dataset complete?")
    for feature in spec.features:
        dtype = info.features.get(feature.column, {}).get("dtype")
        if dtype in ("video", "image"):
            raise DataError(
                f"{root}: column {feature.column} is a{'n' if dtype == 'image' else ''} {dtype}; "
                "cpmp's features are low-dimensional columns (observation.state, ...); map one of "
                "those instead"
            )
    frames = _read_frames(root, files, spec)
    subtasks = _subtask_names(root, spec)
    sarm = _sarm_annotations(root, spec)
    episodes = frames.table.column("episode_index").to_numpy()
    available = np.unique(episodes)
    wanted = list(spec.episodes) if spec.episodes is not None else available.tolist()
    missing = sorted(set(wanted) - set(available.tolist()))
    if missing:
        raise DataError(
            f"{root}: episode(s) {missing} are not in the data; episodes present: "
            f"{_ranges(available.tolist())}"
        )
    columns = _columns(frames, info, spec)
    context = _Context(root, spec, info, frames, columns, subtasks, sarm)
    readers = [
        DemoReader(
            f"demo_{k}",
            f"{root}#episode_{k}",
            functools.partial(_episode, context, int(k), np.flatnonzero(episodes == k)),
        )
        for k in wanted
    ]
    return read_each(readers, skipped)


@dataclass(frozen=True)
class _Frames:
    """The frame table and where each row comes from.

    Attributes:
        table: the needed columns of every data file with rows, concatenated.
        files: the data files, relative to the dataset root.
        file: (N,) the index into ``files`` of every row.
        row: (N,) the row within its file.
        language: episode -> its ``language_persistent`` rows (when a label reads them).
    """

    table: pa.Table
    files: list[str]
    file: np.ndarray
    row: np.ndarray
    language: dict[int, list[dict[str, JsonValue]]]

    def where(self, index: int) -> str:
        """``row <r> of <file>`` for table row ``index``."""
        return f"row {int(self.row[index])} of {self.files[int(self.file[index])]}"


@dataclass(frozen=True)
class _Columns:
    """The frame table as numpy arrays, converted once (rows of every episode).

    Attributes:
        time: (N,) [s] ``timestamp``.
        frame: (N,) ``frame_index``.
        features: one block per mapped feature, (N, k) each (NaN checked per episode).
        labels: per mapped label, its (N,) recorded values and (N,) null mask, or ``None``
            for labels not read from a column.
    """

    time: np.ndarray
    frame: np.ndarray
    features: list[FeatureBlock]
    labels: list[tuple[np.ndarray, np.ndarray] | None]


@dataclass(frozen=True)
class _Context:
    """Everything one episode's import reads (shared by the episodes)."""

    root: Path
    spec: LeRobotSpec
    info: LeRobotInfo
    frames: _Frames
    columns: _Columns
    subtasks: dict[int, str] | None
    sarm: dict[str, dict[int, tuple[list[str], list[int]]]]


def _columns(frames: _Frames, info: LeRobotInfo, spec: LeRobotSpec) -> _Columns:
    table = frames.table
    return _Columns(
        time=table.column("timestamp").to_numpy().astype(np.float64),
        frame=table.column("frame_index").to_numpy(),
        features=[_feature_block(table, f, info) for f in spec.features],
        labels=[
            _label_column(table, lab) if lab.column is not None else None for lab in spec.labels
        ],
    )


def _read_frames(root: Path, files: list[Path], spec: LeRobotSpec) -> _Frames:
    """The needed columns of every data file, concatenated, with each row's origin."""
    columns = [lab.column for lab in spec.labels if lab.column is not None]
    needed = list(dict.fromkeys([*_INDEX_COLUMNS, *(f.column for f in spec.features), *columns]))
    wants_language = any(lab.language is not None for lab in spec.labels)
    tables, names, file_of, row_of = [], [], [], []
    language: dict[int, list[dict[str, JsonValue]]] = {}
    empty = []
    for path in files:
        relative = str(path.relative_to(root))
        try:
            schema = pq.read_schema(path)
        except (OSError, pa.ArrowException) as err:
            raise CpmpFileError(f"cannot read {path} as parquet: {err}") from None
        missing = [c for c in needed if c not in schema.names]
        if missing:
            raise DataError(
                f"{root}: column {missing[0]} is not in {relative} (its columns: "
                f"{', '.join(schema.names)}); {_missing_column_fix(missing[0], schema.names, spec)}"
            )
        if wants_language and LANGUAGE_COLUMN not in schema.names:
            raise DataError(
                f"{root}: the mapping reads subtasks from {LANGUAGE_COLUMN} but {relative} has no "
                f"such column (its columns: {', '.join(schema.names)}); annotate the dataset "
                "with lerobot-annotate (lerobot >= 0.6), or map a label column, subtask_index "
                "or sarm:"
            )
        try:
            table = pq.read_table(
                path, columns=needed + ([LANGUAGE_COLUMN] if wants_language else [])
            )
        except (OSError, pa.ArrowException) as err:
            raise CpmpFileError(f"cannot read {path}: {err}") from None
        if table.num_rows == 0:
            empty.append(relative)
            continue
        if wants_language:
            language.update(_language_rows(table, relative))
            table = table.drop_columns([LANGUAGE_COLUMN])
        file_of.append(np.full(table.num_rows, len(names)))
        row_of.append(np.arange(table.num_rows))
        names.append(relative)
        tables.append(table)
    if not tables:
        raise DataError(
            f"{root}: {', '.join(empty)} {'has' if len(empty) == 1 else 'have'} no rows (no "
            "frames); the dataset holds no episodes: re-export it (a recording that was not "
            "finalised leaves empty files) or give the dataset that holds the frames"
        )
    try:
        table = pa.concat_tables(tables)
    except pa.ArrowException as err:
        raise DataError(f"{root}: the data files disagree on column types ({err})") from None
    return _Frames(table, names, np.concatenate(file_of), np.concatenate(row_of), language)


def _missing_column_fix(column: str, present: list[str], spec: LeRobotSpec) -> str:
    """What to do about a mapped column that a data file lacks."""
    if column == "subtask_index" and LANGUAGE_COLUMN in present:
        return (
            "this dataset keeps its subtasks in language_persistent (lerobot >= 0.6 no longer "
            "writes subtask_index): label the variable with language: subtask"
        )
    feature = next((f for f in spec.features if f.column == column), None)
    if feature is not None:
        state = "observation.state" if "observation.state" in present else "<position column>"
        hint = velocity_hint(column, state, "column")
        if hint:
            return f"fix the column name in the mapping{hint}"
    return "fix the column name in the mapping"


def _language_rows(table: pa.Table, where: str) -> dict[int, list[dict[str, JsonValue]]]:
    """Episode -> its persistent language rows (the first frame's; every frame holds them)."""
    episodes = table.column("episode_index").to_numpy()
    starts = np.flatnonzero(np.r_[True, episodes[1:] != episodes[:-1]])
    column = table.column(LANGUAGE_COLUMN)
    if not pa.types.is_list(column.type) and not pa.types.is_large_list(column.type):
        raise DataError(
            f"{where}: {LANGUAGE_COLUMN} has type {column.type}; lerobot writes a list of rows "
            "(role, content, style, timestamp, ...) per frame"
        )
    out: dict[int, list[dict[str, JsonValue]]] = {}
    for start, rows in zip(starts.tolist(), column.take(pa.array(starts)).to_pylist(), strict=True):
        out.setdefault(int(episodes[start]), rows or [])
    return out


def _feature_block(table: pa.Table, feature: ColumnFeature, info: LeRobotInfo) -> FeatureBlock:
    """A feature column as (n_frames, k) float64 (NaN checked per episode) and its names."""
    where = f"column {feature.column}"
    column = table.column(feature.column).combine_chunks()
    if column.null_count:
        raise DataError(
            f"{where} has {column.null_count} empty (null) frame(s); fill them or drop the episodes"
        )
    kind = column.type
    if pa.types.is_integer(kind) or pa.types.is_floating(kind) or pa.types.is_boolean(kind):
        values = column.to_numpy(zero_copy_only=False).astype(np.float64)[:, None]
    elif (
        pa.types.is_fixed_size_list(kind) or pa.types.is_list(kind) or pa.types.is_large_list(kind)
    ):
        lengths = np.unique(pc.list_value_length(column).to_numpy(zero_copy_only=False))
        if len(lengths) != 1:  # zero-row files were dropped, so there are lengths
            raise DataError(
                f"{where} holds lists of lengths {lengths.tolist()}; features need one length"
            )
        inner = column.flatten()
        if not (pa.types.is_integer(inner.type) or pa.types.is_floating(inner.type)):
            raise DataError(f"{where} holds lists of {inner.type}; features need numbers")
        if inner.null_count:
            raise DataError(f"{where} has empty (null) elements; fill them")
        values = (
            inner.to_numpy(zero_copy_only=False)
            .astype(np.float64)
            .reshape(len(column), int(lengths[0]))
        )
    else:
        raise DataError(
            f"{where} has type {kind}; features need numbers or fixed-length lists of numbers"
        )
    width = values.shape[1]
    picked = pick_columns(feature, width, where)
    elements = _element_names(info.features.get(feature.column, {}), width)
    names = column_names(feature, feature.default_prefix, elements, picked, where)
    names = derived_names(names, feature.derive, feature.names is not None)
    return FeatureBlock(values[:, picked], names)


def _element_names(entry: JsonValue, width: int) -> list[str]:
    """A column's element names.

    From info.json (a list, or a dict holding one list), else indices; ``[""]`` for a scalar
    column.
    """
    names = entry.get("names") if isinstance(entry, dict) else None
    if isinstance(names, dict) and len(names) == 1:
        names = next(iter(names.values()))
    if isinstance(names, list) and len(names) == width and all(isinstance(n, str) for n in names):
        if width == 1 and entry.get("shape") in ([1], (1,)):
            return [""]
        return list(names)
    return [""] if width == 1 else [str(i) for i in range(width)]


def _label_column(table: pa.Table, label: ColumnLabel) -> tuple[np.ndarray, np.ndarray]:
    """A label column's (N,) values and (N,) null mask (nulls are checked per episode)."""
    column = table.column(label.column).combine_chunks()
    nulls = column.is_null().to_numpy(zero_copy_only=False)
    kind = column.type
    if pa.types.is_string(kind) or pa.types.is_large_string(kind):
        return np.asarray(pc.fill_null(column, "").to_pylist(), dtype=str), nulls
    if pa.types.is_integer(kind):
        return pc.fill_null(column, 0).to_numpy(zero_copy_only=False), nulls
    fix = (
        "; label the variable with language: subtask (or motion) instead"
        if label.column == LANGUAGE_COLUMN
        else ""
    )
    raise DataError(
        f"column {label.column} has type {kind}; label columns hold MP names (strings) or "
        f"integer ids{fix}"
    )


def _subtask_names(root: Path, spec: LeRobotSpec) -> dict[int, str] | None:
    """``meta/subtasks.parquet`` as id -> text.

    Only read when a label reads ``subtask_index`` without ``names`` (else ``None``).
    """
    if not any(lab.column == "subtask_index" and lab.names is None for lab in spec.labels):
        return None
    path = root / SUBTASKS_PATH
    if not path.is_file():
        raise DataError(
            f"{root}: the mapping reads subtask_index but {SUBTASKS_PATH} (the subtask names) is "
            "missing; annotate the dataset with subtasks or give names: in the mapping"
        )
    try:
        table = pq.read_table(path)
    except (OSError, pa.ArrowException) as err:
        raise CpmpFileError(f"cannot read {path}: {err}") from None
    text = _text_column(table)
    if text is None:
        raise DataError(
            f"{path} has no subtask text column (columns: {', '.join(table.column_names)}); "
            "expected subtask_index and subtask"
        )
    texts = [str(v) for v in table.column(text).to_pylist()]
    if "subtask_index" in table.column_names:
        ids = [int(v) for v in table.column("subtask_index").to_pylist()]
    else:  # lerobot looks subtasks up by row position
        ids = list(range(len(texts)))
    return dict(zip(ids, texts, strict=True))


def _text_column(table: pa.Table) -> str | None:
    """The subtask text column.

    ``subtask``, else pandas' stored index, else the only string column.
    """
    if "subtask" in table.column_names:
        return "subtask"
    meta = table.schema.metadata or {}
    if b"pandas" in meta:
        try:
            index = json.loads(meta[b"pandas"]).get("index_columns", [])
        except (ValueError, AttributeError):
            index = []
        for name in index:
            if isinstance(name, str) and name in table.column_names:
                return name
    strings = [
        f.name
        for f in table.schema
        if pa.types.is_string(f.type) or pa.types.is_large_string(f.type)
    ]
    return strings[0] if len(strings) == 1 else None


def _sarm_annotations(
    root: Path, spec: LeRobotSpec
) -> dict[str, dict[int, tuple[list[str], list[int]]]]:
    """SARM annotations per kind the mapping reads: episode -> (subtask names, start frames).

    Read from ``meta/episodes/*/*.parquet`` (``<kind>_subtask_names`` and
    ``<kind>_subtask_start_frames``; for ``sparse``, SARM's legacy ``subtask_names`` /
    ``subtask_start_frames`` when the prefixed columns are absent). An episode SARM did not
    annotate is absent.

    Raises:
        DataError: no episode metadata, or no such annotation columns.
    """
    kinds = sorted({lab.sarm for lab in spec.labels if lab.sarm is not None})
    if not kinds:
        return {}
    files = sorted(root.glob(EPISODES_GLOB))
    if not files:
        raise DataError(
            f"{root}: the mapping reads SARM annotations but {EPISODES_GLOB} (the episode "
            "metadata) is missing; give the complete dataset"
        )
    out: dict[str, dict[int, tuple[list[str], list[int]]]] = {kind: {} for kind in kinds}
    for path in files:
        try:
            schema = pq.read_schema(path)
        except (OSError, pa.ArrowException) as err:
            raise CpmpFileError(f"cannot read {path} as parquet: {err}") from None
        for kind in kinds:
            names, starts = f"{kind}_subtask_names", f"{kind}_subtask_start_frames"
            if names not in schema.names and kind == "sparse":
                names, starts = "subtask_names", "subtask_start_frames"
            if names not in schema.names or starts not in schema.names:
                raise DataError(
                    f"{root}: {path.relative_to(root)} has no {kind}_subtask_names and "
                    f"{kind}_subtask_start_frames columns (its columns: "
                    f"{', '.join(schema.names)}); annotate the dataset with SARM's "
                    f"subtask_annotation.py (--{kind}-subtasks) or map another label source"
                )
            try:
                table = pq.read_table(path, columns=["episode_index", names, starts])
            except (OSError, pa.ArrowException) as err:
                raise CpmpFileError(f"cannot read {path}: {err}") from None
            for episode, subtasks, frames in zip(
                table.column("episode_index").to_pylist(),
                table.column(names).to_pylist(),
                table.column(starts).to_pylist(),
                strict=True,
            ):
                if subtasks is not None:
                    out[kind][int(episode)] = (list(subtasks), list(frames or []))
    return out


def _language_labels(
    context: _Context, label: ColumnLabel, index: int, time: np.ndarray
) -> np.ndarray:
    """(n,) texts of the active ``label.language`` rows at the frames' ``time`` [s]."""
    style = label.language
    rows = context.frames.language.get(index, [])
    mine = [r for r in rows if isinstance(r, dict) and r.get("style") == style]
    if not mine:
        styles = sorted({str(r.get("style")) for r in rows if isinstance(r, dict)})
        raise DataError(
            f"{context.root}: episode {index} has no {LANGUAGE_COLUMN} row of style {style} "
            f"(styles there: {', '.join(styles) or 'none, the episode is not annotated'}); "
            f"annotate it with lerobot-annotate, or leave it out (episodes: or on_error: skip)"
        )
    stamps = np.array([float(r.get("timestamp") or 0.0) for r in mine])
    texts = [r.get("content") for r in mine]
    empty = [i for i, text in enumerate(texts) if not isinstance(text, str) or not text.strip()]
    if empty:
        raise DataError(
            f"{context.root}: episode {index}: the {style} row at {stamps[empty[0]]:.3f} s in "
            f"{LANGUAGE_COLUMN} has no content; every {style} row must name what is active"
        )
    order = np.argsort(stamps, kind="stable")
    stamps, texts = stamps[order], [texts[i] for i in order]
    active = np.searchsorted(stamps, time + _TIME_TOLERANCE, side="right") - 1
    if active[0] < 0:
        raise DataError(
            f"{context.root}: episode {index}: no {style} row is active at its first frame "
            f"({time[0]:.3f} s; the first {style} row starts at {stamps[0]:.3f} s); annotate "
            f"the episode from its start or leave it out (episodes: or on_error: skip)"
        )
    return np.asarray(texts, dtype=object)[active].astype(str)


def _sarm_labels(
    context: _Context, label: ColumnLabel, index: int, frame: np.ndarray
) -> np.ndarray:
    """(n,) SARM subtask names at the frames' ``frame_index``."""
    kind = label.sarm
    assert kind is not None
    entry = context.sarm[kind].get(index)
    if entry is None:
        raise DataError(
            f"{context.root}: episode {index} has no SARM {kind} annotation in meta/episodes "
            f"({kind}_subtask_names is empty); annotate it or leave it out (episodes: or "
            "on_error: skip)"
        )
    names, starts = entry
    if not names or len(names) != len(starts):
        raise DataError(
            f"{context.root}: episode {index}: SARM {kind} annotation has {len(names)} "
            f"subtask name(s) but {len(starts)} start frame(s); re-annotate the episode"
        )
    starts_array = np.asarray(starts, dtype=np.int64)
    if np.any(np.diff(starts_array) < 0):
        raise DataError(
            f"{context.root}: episode {index}: SARM {kind} start frames {starts} are not in "
            "order; re-annotate the episode"
        )
    active = np.clip(np.searchsorted(starts_array, frame, side="right") - 1, 0, None)
    return np.asarray(names, dtype=object)[active].astype(str)


def _episode(context: _Context, index: int, rows: np.ndarray) -> ImportedDemo:
    root, spec, info, columns = context.root, context.spec, context.info, context.columns
    name = f"demo_{index}"
    rows = rows[np.argsort(columns.frame[rows], kind="stable")]
    max_gap = spec.max_gap if spec.max_gap is not None else 1.5 / info.fps
    stream = clean_stream("frames (timestamp)", columns.time[rows], rows, max_gap)
    notes = stream_notes(name, stream.report, spec.on_gap, offset=float(stream.time[0]))
    kept = stream.values.astype(np.int64)
    time = stream.time - stream.time[0]
    if len(time) < 2:
        raise DataError(f"{root}: episode {index} has {len(time)} frame(s); cpmp needs at least 2")
    blocks = []
    for feature, block in zip(spec.features, columns.features, strict=True):
        values = block.values[kept]
        bad = np.argwhere(~np.isfinite(values))
        if bad.size:
            row = int(kept[bad[0][0]])
            raise DataError(
                f"{root}: column {feature.column} is NaN/inf in episode {index} at frame "
                f"{int(columns.frame[row])} ({context.frames.where(row)}); repair those frames "
                "or leave the episode out (episodes: or on_error: skip)"
            )
        if feature.derive == "velocity":
            values = velocity(time, values, f"{name}: column {feature.column}")
        blocks.append(FeatureBlock(values, block.names))
    features = np.hstack([block.values for block in blocks])
    labels = {}
    for lab, column in zip(spec.labels, columns.labels, strict=True):
        where = f"episode {index}: {lab.source}"
        if column is not None:
            raw, nulls = column
            empty = np.flatnonzero(nulls[kept])
            if empty.size:
                row = int(kept[empty[0]])
                raise DataError(
                    f"{root}: column {lab.column} is empty (null) in {empty.size} frame(s) of "
                    f"episode {index}, first at frame {int(columns.frame[row])} "
                    f"({context.frames.where(row)}); annotate every frame of the episodes you "
                    "import, or leave this one out (episodes: or on_error: skip)"
                )
            values = raw[kept]
        elif lab.language is not None:
            values = _language_labels(context, lab, index, columns.time[kept])
        else:
            values = _sarm_labels(context, lab, index, columns.frame[kept])
        labels[lab.variable] = decode_labels(lab, values, where, context.subtasks)
    if spec.rate is not None:
        clock = uniform_clock(0.0, float(time[-1]), spec.rate)
        if len(clock) < 2:
            raise DataError(f"{root}: episode {index} is shorter than two ticks at {spec.rate} Hz")
        features = interpolate_linear(time, features, clock)
        labels = {v: zero_order_hold(time, values, clock) for v, values in labels.items()}
        time = clock
        notes.append(
            ImportNote(
                name,
                "window",
                f"episode {index}",
                f"resampled from {info.fps:g} to {spec.rate:g} Hz",
            )
        )
    for variable in list(labels):
        labels[variable], glitches = debounce(
            name, variable, time, labels[variable], spec.min_activation
        )
        notes.extend(glitches)
    demo = Demonstration(
        time=time,
        features=features,
        labels=labels,
        feature_names=check_unique_names(blocks, name),
        name=name,
        metadata={
            "source": "lerobot",
            "dataset": str(root),
            "episode_index": int(index),
            "fps": info.fps,
        },
    )
    return ImportedDemo(demo, tuple(notes), f"{root}#episode_{index}")


def _ranges(values: list[int]) -> str:
    """``0-4, 7`` for ``[0, 1, 2, 3, 4, 7]``."""
    parts: list[str] = []
    start = prev = None
    for v in values:
        if start is None:
            start = prev = v
        elif v == prev + 1:  # type: ignore[operator]
            prev = v
        else:
            parts.append(f"{start}-{prev}" if start != prev else f"{start}")
            start = prev = v
    if start is not None:
        parts.append(f"{start}-{prev}" if start != prev else f"{start}")
    return ", ".join(parts)


__all__ = ["TESTED_RELEASES", "LeRobotInfo", "read_info", "read_lerobot"]
