"""Import demonstrations recorded with a robot's own tools into cpmp's HDF5 format.

Three sources, each described by a YAML mapping (``docs/importing.md``):

- ROS 2 bags (rosbag2, sqlite3 or MCAP; read with ``rosbags``, no ROS install): topics and
  message fields -> features, a label topic per control variable; topics at different rates
  are resampled onto one clock (:mod:`cpmp.importers.resample`).
- LeRobot v3 datasets on disk (parquet; read with ``pyarrow``; lerobot 0.4.4 - 0.6.1):
  columns -> features; per control variable a per-frame label column, ``subtask_index``,
  the ``language_persistent`` subtasks of lerobot >= 0.6 or SARM annotations.
- robomimic-style HDF5 of the MimicGen family: observation keys -> features, per-effector
  subtask termination signals (``datagen_info/subtask_term_signals``) -> labels.

Example::

    from cpmp.importers import SplitSpec, import_recordings, summary_text

    result = import_recordings("mapping.yaml", "bags/", "demos.hdf5", SplitSpec(0.2, seed=0))
    print(summary_text(result))

Every problem raises a :class:`~cpmp.errors.CpmpError` naming the topic, column or key and
the fix; a failed import writes no file. With ``on_error="skip"`` (or ``on_error: skip`` in
the mapping) a bad demonstration is left out and reported instead
(:attr:`ImportResult.skipped`, ``<output>.skipped.json``).
"""

# ruff: noqa: E402
# The extra is checked before the imports that need it.
from cpmp.errors import require as _require

_require("rosbags", "import", "cpmp.importers (ROS 2 bags)")
_require("pyarrow", "import", "cpmp.importers (LeRobot datasets)")

from cpmp.importers.common import ImportedDemo, ImportNote, SkippedDemo
from cpmp.importers.convert import (
    SKIPPED_SUFFIX,
    ImportResult,
    import_recordings,
    make_splits,
    read_recordings,
    skipped_report_path,
)
from cpmp.importers.lerobot import read_lerobot
from cpmp.importers.mimicgen import read_mimicgen
from cpmp.importers.rosbag import find_bags, read_bag, read_rosbags
from cpmp.importers.spec import (
    ON_ERROR,
    SOURCES,
    ColumnFeature,
    ColumnLabel,
    EffectorLabel,
    ImportSpec,
    KeyFeature,
    LeRobotSpec,
    MimicGenSpec,
    RosbagSpec,
    SplitSpec,
    Subtask,
    TopicFeature,
    TopicLabel,
    load_mapping,
    parse_mapping,
)
from cpmp.importers.summary import DemoSummary, demo_summary, summary_text

__all__ = [
    "ON_ERROR",
    "SKIPPED_SUFFIX",
    "SOURCES",
    "ColumnFeature",
    "ColumnLabel",
    "DemoSummary",
    "EffectorLabel",
    "ImportNote",
    "ImportResult",
    "ImportSpec",
    "ImportedDemo",
    "KeyFeature",
    "LeRobotSpec",
    "MimicGenSpec",
    "RosbagSpec",
    "SkippedDemo",
    "SplitSpec",
    "Subtask",
    "TopicFeature",
    "TopicLabel",
    "demo_summary",
    "find_bags",
    "import_recordings",
    "load_mapping",
    "make_splits",
    "parse_mapping",
    "read_bag",
    "read_lerobot",
    "read_mimicgen",
    "read_recordings",
    "read_rosbags",
    "skipped_report_path",
    "summary_text",
]
