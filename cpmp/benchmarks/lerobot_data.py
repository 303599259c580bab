"""LeRobot v3 datasets written with pyarrow, and the mapping that imports them back.

The scale benchmark's ``lerobot`` leg (:mod:`cpmp.benchmarks.scale`) writes demonstrations of a
synthetic world as a LeRobot dataset and imports it with ``cpmp-import``; the importer tests
(``tests/importers/conftest.py``) write their recordings with :func:`write_lerobot_v3`. The
``lerobot`` package is not used (it pins another torch than cpmp's); the layout is the one
documented for lerobot v0.4.4 - v0.5.1 (``docs/source/lerobot-dataset-v3.mdx``, the releases
:func:`cpmp.importers.read_lerobot` is tested against):

- ``meta/info.json``: ``codebase_version`` ``v3.0``, ``fps``, totals, ``data_path`` and
  ``features`` (each column's dtype, shape and element ``names``);
- ``meta/tasks.parquet`` (and ``meta/subtasks.parquet`` when subtasks are given): pandas' index
  column holds the text, ``task_index`` (``subtask_index``) the id;
- ``meta/episodes/chunk-000/file-000.parquet``: per episode its length, tasks, data file and
  the frame range ``dataset_from_index`` .. ``dataset_to_index``;
- ``data/chunk-CCC/file-FFF.parquet``: the frames, several episodes per file, with LeRobot's
  default columns ``timestamp`` (``frame_index / fps`` [s], float32), ``frame_index``,
  ``episode_index``, ``index`` (the frame's index in the dataset) and ``task_index``.

:func:`write_demonstrations` stores a demonstration's features as ``observation.state``
(float32, as LeRobot stores states; element names the feature names) and the active MP of
control variable ``v`` as a per-frame string column ``v_mp``; :func:`import_mapping` is the
``cpmp-import`` mapping that reads them back under the demonstrations' own feature, variable and
MP names. Every file is written atomically (:func:`cpmp.io.atomic_path`).
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import yaml

from cpmp.data import Demonstration
from cpmp.errors import ConfigError, DataError
from cpmp.io import atomic_path, atomic_write_text
from cpmp.records import JsonValue

CODEBASE_VERSION = "v3.0"
"""The ``codebase_version`` written to ``meta/info.json``."""
DATA_PATH = "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
"""``info.json``'s ``data_path``: where the frames of data file ``(chunk, file)`` are."""
EPISODES_PATH = "meta/episodes/chunk-000/file-000.parquet"
"""The per-episode metadata (one file)."""
CHUNKS_SIZE = 1000
"""Data files per chunk folder (LeRobot's default)."""
DEFAULT_COLUMNS = ("timestamp", "frame_index", "episode_index", "index", "task_index")
"""LeRobot's per-frame columns, written by the writer (not given by the caller)."""
STATE_COLUMN = "observation.state"
"""The column :func:`write_demonstrations` stores features in."""
LABEL_SUFFIX = "_mp"
"""Control variable ``v``'s labels are column ``v + LABEL_SUFFIX``."""
TIME_TOLERANCE = 1e-6
"""[s] a demonstration's sample ``i`` must lie this close to ``i / fps`` after its first."""


def _arrow_column(values: np.ndarray, column: str) -> tuple[pa.Array, dict[str, JsonValue]]:
    """A frame column as an arrow array and its ``info.json`` entry (``names`` left ``None``).

    Args:
        values: ``(n,)`` numbers or strings, or ``(n, k)`` numbers (a fixed-size list column).
        column: its name, for messages.
    """
    values = np.asarray(values)
    if values.ndim == 2 and values.dtype.kind in "fiu":
        flat = pa.array(values.reshape(-1))
        array = pa.FixedSizeListArray.from_arrays(flat, values.shape[1])
        return array, {"dtype": values.dtype.name, "shape": [values.shape[1]], "names": None}
    if values.ndim == 1 and values.dtype.kind in "fiub":
        array = pa.array(values)
        return array, {"dtype": values.dtype.name, "shape": [1], "names": None}
    if values.ndim == 1 and values.dtype.kind in "US":
        return pa.array(values.astype(str).tolist(), pa.string()), {
            "dtype": "string",
            "shape": [1],
            "names": None,
        }
    raise DataError(
        f"column {column}: give (n,) numbers or strings or (n, k) numbers, got shape "
        f"{values.shape} of dtype {values.dtype}"
    )


def _column_order(columns: Sequence[str]) -> list[str]:
    """The robot's columns (``observation.*``, ``action``), LeRobot's defaults, then the rest.

    The order lerobot writes them in: a dataset's features first, its default columns
    appended, columns added afterwards (``subtask_index``, label columns) last.
    """
    robot = [c for c in columns if c == "action" or c.startswith("observation.")]
    rest = [c for c in columns if c not in robot]
    return [*robot, *DEFAULT_COLUMNS, *rest]


def _pandas_indexed(name: str, values: Sequence[str]) -> pa.Table:
    """A pandas-indexed table of ``values``, as ``DataFrame.to_parquet`` writes it.

    ``pandas.DataFrame({f"{name}_index": ...}, index=Index(values, name=name))``: the index
    becomes a column named ``name``, recorded in the ``pandas`` schema metadata.
    """
    table = pa.table(
        {f"{name}_index": pa.array(range(len(values)), pa.int64()), name: list(values)}
    )
    pandas_meta = {
        "index_columns": [name],
        "column_indexes": [],
        "columns": [
            {
                "name": f"{name}_index",
                "field_name": f"{name}_index",
                "pandas_type": "int64",
                "numpy_type": "int64",
                "metadata": None,
            },
            {
                "name": name,
                "field_name": name,
                "pandas_type": "unicode",
                "numpy_type": "object",
                "metadata": None,
            },
        ],
        "creator": {"library": "pyarrow", "version": pa.__version__},
        "pandas_version": "2.2.3",
    }
    return table.replace_schema_metadata({"pandas": json.dumps(pandas_meta)})


def _write_parquet(table: pa.Table, path: Path) -> None:
    """``pq.write_table`` to ``path`` atomically (parent folders created)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        pq.write_table(table, tmp)


def write_lerobot_v3(
    root: str | os.PathLike[str],
    episodes: Sequence[Mapping[str, np.ndarray]],
    *,
    fps: int,
    names: Mapping[str, Sequence[str]] | None = None,
    task: str = "Perform the task",
    subtasks: Sequence[str] | None = None,
    episodes_per_file: int = 50,
    robot_type: str = "cpmp_synthetic",
) -> Path:
    """Write a LeRobot v3 dataset of ``episodes`` at ``root`` (the layout of the module docstring).

    Args:
        root: the dataset's folder, created; give a new or empty one (the files written
            replace theirs, other files there are left, and the importer reads every data file).
        episodes: per episode its frame columns, each ``(n,)`` numbers or strings or ``(n, k)``
            numbers (``n`` frames, the same in every column; float arrays keep their precision,
            so give float32 for LeRobot's usual ``float32`` states); every episode has the same
            columns, none of :data:`DEFAULT_COLUMNS`.
        fps: [frames/s] the frame rate; frame ``i`` is stamped ``i / fps`` [s] (float32).
        names: column -> element names of an ``(n, k)`` column, written to ``info.json``.
        task: the one task text of every episode (``task_index`` 0).
        subtasks: texts of ``meta/subtasks.parquet`` (``subtask_index`` ``i`` is
            ``subtasks[i]``); ``None``: no such file.
        episodes_per_file: episodes per data file (the last file holds the rest).
        robot_type: ``info.json``'s ``robot_type``.

    Returns:
        ``root``.

    Raises:
        DataError: no episodes, episodes with other columns or fewer than two frames, a
            column of another length or kind, a default column given.
        ConfigError: ``fps`` or ``episodes_per_file`` below 1.
    """
    root = Path(root)
    if not episodes:
        raise DataError("a LeRobot dataset needs at least one episode")
    if int(fps) < 1 or int(episodes_per_file) < 1:
        raise ConfigError(f"fps and episodes_per_file must be >= 1, got {fps}, {episodes_per_file}")
    given = list(episodes[0])
    if set(given) & set(DEFAULT_COLUMNS):
        raise DataError(f"the writer adds {', '.join(DEFAULT_COLUMNS)}; do not give them")
    order = _column_order(given)
    names = dict(names or {})
    files: list[list[pa.Table]] = []
    entries: dict[str, dict[str, JsonValue]] = {}
    episode_rows = []
    index = 0
    for k, frames in enumerate(episodes):
        if list(frames) != given:
            raise DataError(f"episode {k} has columns {list(frames)}, episode 0 {given}")
        lengths = {c: len(np.asarray(v)) for c, v in frames.items()}
        n = next(iter(lengths.values()))
        if n < 2 or any(m != n for m in lengths.values()):
            raise DataError(f"episode {k}: columns of {lengths} frames; give >= 2, all equal")
        frame = np.arange(n, dtype=np.int64)
        columns = {
            **frames,
            "timestamp": (frame / fps).astype(np.float32),
            "frame_index": frame,
            "episode_index": np.full(n, k, np.int64),
            "index": index + frame,
            "task_index": np.zeros(n, np.int64),
        }
        arrays = []
        for column in order:
            array, entry = _arrow_column(columns[column], column)
            if column in names:
                entry["names"] = list(names[column])
            if entries.setdefault(column, entry) != entry:
                raise DataError(
                    f"column {column}: episode {k} has {entry}, episode 0 {entries[column]}"
                )
            arrays.append(array)
        file_index = k // int(episodes_per_file)
        if file_index == len(files):
            files.append([])
        files[file_index].append(pa.Table.from_arrays(arrays, names=order))
        episode_rows.append(
            {
                "episode_index": k,
                "tasks": [task],
                "length": n,
                "data/chunk_index": file_index // CHUNKS_SIZE,
                "data/file_index": file_index % CHUNKS_SIZE,
                "dataset_from_index": index,
                "dataset_to_index": index + n,
            }
        )
        index += n
    for file_index, tables in enumerate(files):
        path = DATA_PATH.format(
            chunk_index=file_index // CHUNKS_SIZE, file_index=file_index % CHUNKS_SIZE
        )
        _write_parquet(pa.concat_tables(tables), root / path)
    _write_parquet(pa.Table.from_pylist(episode_rows), root / EPISODES_PATH)
    _write_parquet(_pandas_indexed("task", [task]), root / "meta" / "tasks.parquet")
    if subtasks is not None:
        _write_parquet(_pandas_indexed("subtask", subtasks), root / "meta" / "subtasks.parquet")
    info = {
        "codebase_version": CODEBASE_VERSION,
        "robot_type": robot_type,
        "total_episodes": len(episodes),
        "total_frames": index,
        "total_tasks": 1,
        "chunks_size": CHUNKS_SIZE,
        "data_files_size_in_mb": 100,
        "video_files_size_in_mb": 200,
        "fps": int(fps),
        "splits": {"train": f"0:{len(episodes)}"},
        "data_path": DATA_PATH,
        "video_path": None,
        "features": entries,
    }
    atomic_write_text(root / "meta" / "info.json", json.dumps(info, indent=4))
    return root


def demonstration_fps(demos: Sequence[Demonstration]) -> int:
    """The frame rate [frames/s] the demonstrations are sampled at (LeRobot's ``fps``).

    Raises:
        DataError: no demonstrations, a rate that is not a whole number of frames per second,
            or a demonstration off the clock ``time[0] + i / fps`` by more than
            :data:`TIME_TOLERANCE` [s] (resample it first).
    """
    if not demos:
        raise DataError("no demonstrations to write")
    step = float(np.median(np.diff(demos[0].time)))
    fps = round(1.0 / step)
    for demo in demos:
        clock = np.arange(demo.n_samples) / fps
        if fps < 1 or np.max(np.abs(demo.time - demo.time[0] - clock)) > TIME_TOLERANCE:
            raise DataError(
                f"{demo.name}: not sampled every 1/{fps} s (the first demonstration's median "
                "step, rounded to whole frames per second); LeRobot stores frames at one fixed "
                "fps, so resample the demonstrations onto that clock"
            )
    return fps


def write_demonstrations(
    root: str | os.PathLike[str],
    demos: Sequence[Demonstration],
    *,
    episodes_per_file: int = 50,
    task: str = "Perform the task",
) -> Path:
    """Write ``demos`` as a LeRobot v3 dataset, one episode per demonstration, in their order.

    Features go to ``observation.state`` (float32; element names the feature names), the
    labels of control variable ``v`` to the string column ``v_mp``; the frame rate is
    :func:`demonstration_fps`. Names and metadata of the demonstrations are not stored (the
    importer names episode ``k`` ``demo_k``).

    Args:
        root: the dataset's folder.
        demos: demonstrations with the same feature names and control variables.
        episodes_per_file: episodes per data file.
        task: the task text of every episode.

    Returns:
        ``root``.

    Raises:
        DataError: the demonstrations disagree on features or variables, or are not on a
            uniform clock (:func:`demonstration_fps`).
    """
    fps = demonstration_fps(demos)
    feature_names = list(demos[0].feature_names or [])
    variables = demos[0].variables
    episodes = []
    for demo in demos:
        if list(demo.feature_names or []) != feature_names or demo.variables != variables:
            raise DataError(
                f"{demo.name}: features {demo.feature_names} and variables {demo.variables} "
                f"differ from {demos[0].name}'s ({feature_names}, {variables}); a dataset has one "
                "state layout"
            )
        episodes.append(
            {
                STATE_COLUMN: demo.features.astype(np.float32),
                **{v + LABEL_SUFFIX: np.asarray(demo.labels[v], dtype=str) for v in variables},
            }
        )
    return write_lerobot_v3(
        root,
        episodes,
        fps=fps,
        names={STATE_COLUMN: feature_names},
        task=task,
        episodes_per_file=episodes_per_file,
    )


def import_mapping(demos: Sequence[Demonstration]) -> dict[str, JsonValue]:
    """The ``cpmp-import`` mapping of a dataset :func:`write_demonstrations` wrote of ``demos``.

    It maps ``observation.state`` to the demonstrations' feature names and each ``v_mp``
    column to control variable ``v`` (MP names as recorded), on the recorded frames.

    Args:
        demos: the written demonstrations (their first one's names are used).

    Returns:
        The mapping as a plain dict (:func:`cpmp.importers.load_mapping` takes it, or its YAML).
    """
    first = demos[0]
    return {
        "source": "lerobot",
        "features": [{"column": STATE_COLUMN, "names": list(first.feature_names or [])}],
        "labels": {v: {"column": v + LABEL_SUFFIX} for v in first.variables},
    }


def write_import_mapping(path: str | os.PathLike[str], mapping: Mapping[str, JsonValue]) -> Path:
    """Write ``mapping`` as the YAML file ``cpmp-import mapping=<path>`` reads (atomically).

    Returns:
        ``path``.
    """
    atomic_write_text(path, yaml.safe_dump(dict(mapping), sort_keys=False))
    return Path(path)


__all__ = [
    "CODEBASE_VERSION",
    "DATA_PATH",
    "LABEL_SUFFIX",
    "STATE_COLUMN",
    "demonstration_fps",
    "import_mapping",
    "write_demonstrations",
    "write_import_mapping",
    "write_lerobot_v3",
]
