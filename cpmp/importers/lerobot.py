"""LeRobot datasets on local disk (the v3 layout) as demonstrations, read with pyarrow.

The v3 layout (lerobot >= 0.4; subtasks since v0.4.4): ``meta/info.json`` (``codebase_version``
``v3.x``, ``fps``, ``features`` with each column's dtype, shape and element ``names``), frames
in ``data/chunk-*/file-*.parquet`` (many episodes per file; columns ``timestamp``,
``frame_index``, ``episode_index``, ``observation.state``, ...) and, for datasets annotated
with subtasks, ``meta/subtasks.parquet`` (``subtask_index`` -> the subtask's text, stored as
pandas' index column ``subtask``) referenced by a per-frame ``subtask_index``. Videos are not
read: cpmp's features are low-dimensional columns.

One episode is one demonstration (``demo_<episode_index>``). Labels come from one per-frame
column per control variable (strings, or integer ids with ``names``) or, for a single
variable, from ``subtask_index``.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from cpmp.data import Demonstration
from cpmp.errors import CpmpFileError, DataError
from cpmp.importers.common import (
    FeatureBlock,
    ImportedDemo,
    ImportNote,
    check_unique_names,
    column_names,
    debounce,
    decode_labels,
    pick_columns,
    stream_notes,
)
from cpmp.importers.resample import clean_stream, interpolate_linear, uniform_clock, zero_order_hold
from cpmp.importers.spec import ColumnFeature, ColumnLabel, LeRobotSpec

INFO_PATH = "meta/info.json"
SUBTASKS_PATH = "meta/subtasks.parquet"
DATA_GLOB = "data/*/*.parquet"
_INDEX_COLUMNS = ("episode_index", "frame_index", "timestamp")


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
    features: dict[str, Any]


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
    if not version.startswith("v3"):
        raise CpmpFileError(
            f"{path}: codebase_version is {version or 'missing'}; cpmp reads the LeRobot v3 "
            "layout (many episodes per data/chunk-*/file-*.parquet); convert older datasets "
            "with lerobot's convert_dataset_v21_to_v30 first"
        )
    fps = info.get("fps")
    if isinstance(fps, bool) or not isinstance(fps, (int, float)) or not fps > 0:
        raise CpmpFileError(f"{path}: fps must be a positive number, got {fps!r}")
    features = info.get("features")
    return LeRobotInfo(version, float(fps), features if isinstance(features, dict) else {})


def read_lerobot(root: str | os.PathLike[str], spec: LeRobotSpec) -> list[ImportedDemo]:
    """Import the episodes of the LeRobot dataset at ``root`` with ``spec``.

    Returns:
        One demonstration per episode (``demo_<episode_index>``, in episode order), on the
        recorded frames or, with ``spec.rate``, resampled onto a clock of that rate.

    Raises:
        CpmpFileError: not a v3 dataset, no or unreadable parquet files.
        DataError: a mapped column is missing, not numeric (features) or has nulls, an episode
            asked for is not there, integer labels without names.
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
    table = _read_frames(root, files, spec)
    subtasks = _subtask_names(root, spec)
    episodes = table.column("episode_index").to_numpy()
    available = np.unique(episodes)
    wanted = list(spec.episodes) if spec.episodes is not None else available.tolist()
    missing = sorted(set(wanted) - set(available.tolist()))
    if missing:
        raise DataError(
            f"{root}: episode(s) {missing} are not in the data; episodes present: "
            f"{_ranges(available.tolist())}"
        )
    columns = _columns(table, info, spec)
    return [
        _episode(root, k, np.flatnonzero(episodes == k), columns, subtasks, spec, info)
        for k in wanted
    ]


@dataclass(frozen=True)
class _Columns:
    """The frame table as numpy arrays, converted once (rows of every episode).

    Attributes:
        time: (N,) [s] ``timestamp``.
        frame: (N,) ``frame_index``.
        features: one block per mapped feature, (N, k) each.
        labels: one (N,) array of recorded values per mapped label.
    """

    time: np.ndarray
    frame: np.ndarray
    features: list[FeatureBlock]
    labels: list[np.ndarray]


def _columns(table: pa.Table, info: LeRobotInfo, spec: LeRobotSpec) -> _Columns:
    return _Columns(
        time=table.column("timestamp").to_numpy().astype(np.float64),
        frame=table.column("frame_index").to_numpy(),
        features=[_feature_block(table, f, info) for f in spec.features],
        labels=[_label_column(table, lab) for lab in spec.labels],
    )


def _read_frames(root: Path, files: list[Path], spec: LeRobotSpec) -> pa.Table:
    """The needed columns of every data file, concatenated."""
    needed = list(
        dict.fromkeys(
            [
                *_INDEX_COLUMNS,
                *(f.column for f in spec.features),
                *(lab.column for lab in spec.labels),
            ]
        )
    )
    tables = []
    for path in files:
        try:
            schema = pq.read_schema(path)
        except (OSError, pa.ArrowException) as err:
            raise CpmpFileError(f"cannot read {path} as parquet: {err}") from None
        missing = [c for c in needed if c not in schema.names]
        if missing:
            raise DataError(
                f"{root}: column {missing[0]} is not in {path.relative_to(root)} (its columns: "
                f"{', '.join(schema.names)}); fix the column name in the mapping"
            )
        try:
            tables.append(pq.read_table(path, columns=needed))
        except (OSError, pa.ArrowException) as err:
            raise CpmpFileError(f"cannot read {path}: {err}") from None
    try:
        return pa.concat_tables(tables)
    except pa.ArrowException as err:
        raise DataError(f"{root}: the data files disagree on column types ({err})") from None


def _feature_block(table: pa.Table, feature: ColumnFeature, info: LeRobotInfo) -> FeatureBlock:
    """A feature column as (n_frames, k) float64 and its names."""
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
        if len(lengths) != 1:
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
    bad = np.argwhere(~np.isfinite(values))
    if bad.size:
        raise DataError(f"{where} is NaN/inf in row {int(bad[0][0])}; repair or drop those frames")
    width = values.shape[1]
    picked = pick_columns(feature, width, where)
    elements = _element_names(info.features.get(feature.column, {}), width)
    names = column_names(feature, feature.default_prefix, elements, picked, where)
    return FeatureBlock(values[:, picked], names)


def _element_names(entry: Any, width: int) -> list[str]:
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


def _label_column(table: pa.Table, label: ColumnLabel) -> np.ndarray:
    column = table.column(label.column).combine_chunks()
    if column.null_count:
        rows = np.flatnonzero(column.is_null().to_numpy(zero_copy_only=False))
        raise DataError(
            f"column {label.column} is empty (null) in {column.null_count} frame(s), first in "
            f"row {int(rows[0])}; annotate every frame of the episodes you import"
        )
    kind = column.type
    if pa.types.is_string(kind) or pa.types.is_large_string(kind):
        return np.asarray(column.to_pylist(), dtype=str)
    if pa.types.is_integer(kind):
        return column.to_numpy(zero_copy_only=False)
    raise DataError(
        f"column {label.column} has type {kind}; label columns hold MP names (strings) or "
        "integer ids"
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


def _episode(
    root: Path,
    index: int,
    rows: np.ndarray,
    columns: _Columns,
    subtasks: dict[int, str] | None,
    spec: LeRobotSpec,
    info: LeRobotInfo,
) -> ImportedDemo:
    name = f"demo_{index}"
    rows = rows[np.argsort(columns.frame[rows], kind="stable")]
    max_gap = spec.max_gap if spec.max_gap is not None else 1.5 / info.fps
    stream = clean_stream("frames (timestamp)", columns.time[rows], rows, max_gap)
    notes = stream_notes(name, stream.report, spec.on_gap, offset=float(stream.time[0]))
    kept = stream.values.astype(np.int64)
    time = stream.time - stream.time[0]
    if len(time) < 2:
        raise DataError(f"{root}: episode {index} has {len(time)} frame(s); cpmp needs at least 2")
    features = np.hstack([block.values[kept] for block in columns.features])
    labels = {
        lab.variable: decode_labels(
            lab, raw[kept], f"episode {index}: column {lab.column}", subtasks
        )
        for lab, raw in zip(spec.labels, columns.labels, strict=True)
    }
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
        feature_names=check_unique_names(columns.features, name),
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


__all__ = ["LeRobotInfo", "read_info", "read_lerobot"]
