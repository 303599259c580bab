"""Import demonstrations recorded with a robot's own tools into cpmp's HDF5 format.

Three sources, each described by a YAML mapping (``docs/importing.md``):

- ROS 2 bags (rosbag2, sqlite3 or MCAP; read with ``rosbags``, no ROS install): topics and
  message fields -> features, a label topic per control variable; topics at different rates
  are resampled onto one clock (:mod:`cpmp.importers.resample`).
- LeRobot v3 datasets on disk (parquet; read with ``pyarrow``): columns -> features, a
  per-frame label column per control variable or ``subtask_index``.
- robomimic-style HDF5 of the MimicGen family: observation keys -> features, per-effector
  subtask termination signals (``datagen_info/subtask_term_signals``) -> labels.

Example::

    from cpmp.importers import SplitSpec, import_recordings, summary_text

    result = import_recordings("mapping.yaml", "bags/", "demos.hdf5", SplitSpec(0.2, seed=0))
    print(summary_text(result))

Every problem raises a :class:`~cpmp.errors.CpmpError` naming the topic, column or key and
the fix; a failed import writes no file.
"""

from cpmp.importers.common import ImportedDemo, ImportNote
from cpmp.importers.convert import ImportResult, import_recordings, make_splits, read_recordings
from cpmp.importers.lerobot import read_lerobot
from cpmp.importers.mimicgen import read_mimicgen
from cpmp.importers.rosbag import find_bags, read_bag, read_rosbags
from cpmp.importers.spec import (
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
    "summary_text",
]
