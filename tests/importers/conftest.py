"""Small recordings of one synthetic task, written with the real libraries of each format.

The task: the right arm reaches (``hand_x`` to the box), grasps (``gripper`` closes) and lifts
(``hand_z`` rises); the left arm holds, then pushes (``left_y`` moves) while the right arm
grasps. Every recording of an :class:`Episode` samples the same continuous trajectories, so
the imported demonstrations of every source must show the same MP sequences.

Writers: :func:`write_bag` (``rosbags``' writer, sqlite3 or MCAP, topics at 100/30/10 Hz,
optional glitches), :func:`write_lerobot` (pyarrow, the LeRobot v3 layout as documented for
lerobot v0.4.4 - v0.5.1, the releases with ``meta/subtasks.parquet``; the ``lerobot`` package
itself pins ``torch<2.12`` and cannot be installed beside cpmp's torch 2.13), and
:func:`write_mimicgen` (h5py, MimicGen's robomimic layout with
``datagen_info/subtask_term_signals``).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from cpmp.benchmarks.lerobot_data import write_lerobot_v3
from cpmp.data import list_splits, load_demonstrations
from cpmp.evaluation import replay_demonstrations
from cpmp.sequencer import ConcurrentSequencer

TYPESTORE = get_typestore(Stores.ROS2_HUMBLE)
JOINTS = ["right_x", "right_z", "left_y", "wrist"]
BAG_START_NS = 1_700_000_000_000_000_000  # an absolute ROS time, as real bags have


def _smooth(u: np.ndarray) -> np.ndarray:
    u = np.clip(u, 0.0, 1.0)
    return u * u * (3.0 - 2.0 * u)


@dataclass(frozen=True)
class Episode:
    """One execution of the task; times [s] from its start, positions [m]."""

    t_grasp: float
    t_lift: float
    t_push: float
    t_end: float
    x_goal: float

    def hand_x(self, t: np.ndarray) -> np.ndarray:
        return self.x_goal * _smooth(t / self.t_grasp)

    def gripper(self, t: np.ndarray) -> np.ndarray:
        return _smooth((t - self.t_grasp) / (self.t_lift - self.t_grasp))

    def hand_z(self, t: np.ndarray) -> np.ndarray:
        return 0.3 * _smooth((t - self.t_lift) / (self.t_end - self.t_lift))

    def left_y(self, t: np.ndarray) -> np.ndarray:
        return 0.2 * _smooth((t - self.t_push) / 0.8)

    def right_mp(self, t: np.ndarray) -> np.ndarray:
        return np.where(t < self.t_grasp, "reach", np.where(t < self.t_lift, "grasp", "lift"))

    def left_mp(self, t: np.ndarray) -> np.ndarray:
        return np.where(t < self.t_push, "hold", "push")

    def state(self, t: np.ndarray) -> np.ndarray:
        """(n, 4): hand_x, hand_z, gripper, left_y."""
        return np.column_stack([self.hand_x(t), self.hand_z(t), self.gripper(t), self.left_y(t)])


def make_episodes(n: int, seed: int) -> list[Episode]:
    rng = np.random.default_rng(seed)
    episodes = []
    for _ in range(n):
        t_grasp = rng.uniform(0.8, 1.2)
        t_lift = t_grasp + rng.uniform(0.4, 0.6)
        t_end = t_lift + rng.uniform(0.6, 0.9)
        t_push = t_grasp + rng.uniform(0.1, 0.3)
        episodes.append(Episode(t_grasp, t_lift, t_push, t_end, rng.uniform(0.3, 0.5)))
    return episodes


# ----------------------------------------------------------------------------------- bags
def _ticks(rate: float, t_end: float, offset: float = 0.0) -> np.ndarray:
    return offset + np.arange(int(np.floor((t_end - offset) * rate)) + 1) / rate


def write_bag(
    path: Path,
    episode: Episode,
    *,
    storage: str = "sqlite3",
    glitch: bool = False,
    drop_topics: Sequence[str] = (),
    label_offset: float = 0.0,
    silence: tuple[str, float, float] | None = None,
) -> Path:
    """A rosbag2 recording of ``episode``.

    Topics: ``/joint_states`` (JointState, 100 Hz, header stamps), ``/gripper`` (Float64,
    30 Hz), ``/box_pose`` (PoseStamped, 10 Hz, header stamps), ``/right_arm/mp`` (String,
    the active MP, 20 Hz) and ``/left_arm/switch`` (Empty, one message when the push starts).
    ``drop_topics`` are left out; ``silence = (topic, start, stop)`` drops that topic's
    messages received between ``start`` and ``stop`` [s].
    With ``glitch``: ``/right_arm/mp`` says ``grasp`` for one message (50 ms) during the
    reach and repeats one message with the same stamp, and two ``/joint_states`` messages
    arrive with their header stamps swapped.
    """
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    types = TYPESTORE.types
    JointState, Header, Time = (
        types["sensor_msgs/msg/JointState"],
        types["std_msgs/msg/Header"],
        types["builtin_interfaces/msg/Time"],
    )
    Float64, String, Empty = (
        types["std_msgs/msg/Float64"],
        types["std_msgs/msg/String"],
        types["std_msgs/msg/Empty"],
    )
    PoseStamped, Pose, Point, Quaternion = (
        types["geometry_msgs/msg/PoseStamped"],
        types["geometry_msgs/msg/Pose"],
        types["geometry_msgs/msg/Point"],
        types["geometry_msgs/msg/Quaternion"],
    )

    def ns(t: float) -> int:
        return BAG_START_NS + round(t * 1e9)

    def header(t: float) -> object:
        stamp = ns(t)
        return Header(stamp=Time(sec=stamp // 10**9, nanosec=stamp % 10**9), frame_id="world")

    records: list[tuple[int, str, object, str]] = []  # (receive ns, topic, msg, type)
    e = episode
    js = _ticks(100.0, e.t_end)
    stamps = js.copy()
    if glitch:  # two header stamps swapped: they arrive out of order
        stamps[40], stamps[41] = stamps[41], stamps[40]
    for t, stamp in zip(js, stamps, strict=True):
        s = float(stamp)
        position = np.array([e.hand_x(s), e.hand_z(s), e.left_y(s), 0.1])
        msg = JointState(
            header=header(s),
            name=list(JOINTS),
            position=position,
            velocity=np.zeros(0),
            effort=np.zeros(0),
        )
        records.append((ns(t + 0.002), "/joint_states", msg, JointState.__msgtype__))
    for t in _ticks(30.0, e.t_end, 0.004):
        records.append((ns(t), "/gripper", Float64(data=float(e.gripper(t))), Float64.__msgtype__))
    for t in _ticks(10.0, e.t_end):
        pose = Pose(
            position=Point(x=e.x_goal + 0.05, y=0.0, z=float(e.hand_z(t))),
            orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0),
        )
        msg = PoseStamped(header=header(t), pose=pose)
        records.append((ns(t + 0.01), "/box_pose", msg, PoseStamped.__msgtype__))
    label_ticks = _ticks(20.0, e.t_end, label_offset)
    for k, t in enumerate(label_ticks):
        mp = str(e.right_mp(np.array(t)))
        if glitch and k == 8:  # 0.4 s, inside the reach
            mp = "grasp"
        records.append((ns(t), "/right_arm/mp", String(data=mp), String.__msgtype__))
        if glitch and k == 3:
            records.append((ns(t), "/right_arm/mp", String(data=mp), String.__msgtype__))
    records.append((ns(e.t_push), "/left_arm/switch", Empty(), Empty.__msgtype__))
    records = [r for r in records if r[1] not in drop_topics]
    if silence is not None:
        topic, quiet_from, quiet_to = silence
        records = [r for r in records if r[1] != topic or not ns(quiet_from) <= r[0] < ns(quiet_to)]
    records.sort(key=lambda r: r[0])
    with Writer(path, version=9, storage_plugin=plugin) as writer:
        connections = {}
        for _, topic, _, msgtype in records:
            if topic not in connections:
                connections[topic] = writer.add_connection(topic, msgtype, typestore=TYPESTORE)
        for when, topic, msg, msgtype in records:
            writer.write(connections[topic], when, TYPESTORE.serialize_cdr(msg, msgtype))
    return path


BAG_MAPPING = {
    "source": "rosbag",
    "rate": 50.0,
    "max_gap": 0.25,
    "features": [
        {"topic": "/joint_states", "field": "position", "joints": ["right_x", "right_z", "left_y"]},
        {"topic": "/gripper", "field": "data", "name": "gripper"},
        {"topic": "/box_pose", "field": "pose.position", "name": "box"},
    ],
    "labels": {
        "right_arm": {"topic": "/right_arm/mp", "mps": ["reach", "grasp", "lift"]},
        "left_arm": {"topic": "/left_arm/switch", "kind": "events", "sequence": ["hold", "push"]},
    },
}


# ------------------------------------------------------------------------------- LeRobot
LEROBOT_SUBTASKS = ["Reach for the box", "Grasp the box", "Lift the box"]
STATE_NAMES = ["hand_x", "hand_z", "gripper", "left_y"]


def write_lerobot(root: Path, episodes: Sequence[Episode], fps: int = 30) -> Path:
    """A LeRobot v3 dataset (``codebase_version`` v3.0) of ``episodes`` at ``fps``.

    Written by :func:`cpmp.benchmarks.lerobot_data.write_lerobot_v3` in the layout documented
    for lerobot v0.4.4 - v0.5.1 (``docs/source/lerobot-dataset-v3.mdx``,
    ``docs/source/dataset_subtask.mdx``): ``meta/info.json``, ``meta/tasks.parquet``,
    ``meta/subtasks.parquet`` (``subtask_index`` and the ``subtask`` string, pandas' index
    column), ``meta/episodes/chunk-000/file-000.parquet`` and frames in
    ``data/chunk-000/file-00{0,1}.parquet`` (several episodes per file). Frame columns:
    ``observation.state`` and ``action`` (fixed-size float32 lists), ``timestamp``,
    ``frame_index``, ``episode_index``, ``index``, ``task_index``, ``subtask_index``, and two
    custom per-frame label columns, ``right_arm_mp`` (int ids) and ``left_arm_mp`` (strings).
    """
    frames = []
    for e in episodes:
        t = np.arange(int(np.floor(e.t_end * fps)) + 1) / fps
        state = e.state(t).astype(np.float32)
        right = e.right_mp(t)
        frames.append(
            {
                "observation.state": state,
                "action": state[np.minimum(np.arange(len(t)) + 1, len(t) - 1)],
                "subtask_index": np.array([["reach", "grasp", "lift"].index(m) for m in right]),
                "right_arm_mp": np.searchsorted(["grasp", "lift", "reach"], right),  # sorted ids
                "left_arm_mp": e.left_mp(t),
            }
        )
    return write_lerobot_v3(
        root,
        frames,
        fps=fps,
        names={"observation.state": STATE_NAMES, "action": STATE_NAMES},
        task="Pick up the box",
        subtasks=LEROBOT_SUBTASKS,
        episodes_per_file=(len(episodes) + 1) // 2,
        robot_type="synthetic_bimanual",
    )


LEROBOT_MAPPING = {
    "source": "lerobot",
    "features": [{"column": "observation.state", "name": "state"}],
    "labels": {
        "right_arm": {"column": "right_arm_mp", "names": ["grasp", "lift", "reach"]},
        "left_arm": {"column": "left_arm_mp"},
    },
}


# ------------------------------------------------------------------------------ MimicGen
def write_mimicgen(path: Path, episodes: Sequence[Episode], rate: float = 20.0) -> Path:
    """A MimicGen-style robomimic HDF5 file of ``episodes`` stepped at ``rate`` Hz.

    Per ``/data/demo_<i>``: ``obs/robot0_eef_pos`` (T, 3), ``obs/robot0_gripper_qpos`` (T, 2),
    ``obs/robot1_eef_pos`` (T, 3), ``obs/agentview_image`` (T, 8, 8, 3) uint8, ``actions``,
    ``states``, ``datagen_info/eef_pose`` (T, 4, 4) and
    ``datagen_info/subtask_term_signals/{reached,grasped,push_started}`` (T,) 0/1 flags that
    switch to 1 when the subtask is done (MimicGen uses each one's first 0 -> 1 transition),
    plus a per-step label dataset ``labels/left_arm`` (strings) and ``mask/{train,valid}``.
    """
    with h5py.File(path, "w") as f:
        data = f.create_group("data")
        data.attrs["env_args"] = json.dumps({"env_name": "SyntheticPickLift", "type": 1})
        total = 0
        for k, e in enumerate(episodes):
            t = np.arange(int(np.floor(e.t_end * rate)) + 1) / rate
            n = len(t)
            total += n
            g = data.create_group(f"demo_{k}")
            g.attrs["num_samples"] = n
            zeros = np.zeros(n)
            g.create_dataset(
                "obs/robot0_eef_pos", data=np.column_stack([e.hand_x(t), zeros, e.hand_z(t)])
            )
            opening = 0.04 * (1.0 - e.gripper(t))
            g.create_dataset("obs/robot0_gripper_qpos", data=np.column_stack([opening, -opening]))
            g.create_dataset(
                "obs/robot1_eef_pos", data=np.column_stack([zeros, e.left_y(t), zeros])
            )
            g.create_dataset("obs/agentview_image", data=np.zeros((n, 8, 8, 3), dtype=np.uint8))
            g.create_dataset("actions", data=np.zeros((n, 7)))
            g.create_dataset("states", data=np.zeros((n, 10)))
            pose = np.tile(np.eye(4), (n, 1, 1))
            pose[:, 0, 3], pose[:, 2, 3] = e.hand_x(t), e.hand_z(t)
            g.create_dataset("datagen_info/eef_pose", data=pose)
            signals = g.create_group("datagen_info/subtask_term_signals")
            signals.create_dataset("reached", data=(t >= e.t_grasp).astype(np.int64))
            signals.create_dataset("grasped", data=(t >= e.t_lift).astype(np.int64))
            signals.create_dataset("push_started", data=(t >= e.t_push).astype(np.int64))
            g.create_dataset("labels/left_arm", data=e.left_mp(t).astype("S"))
        data.attrs["total"] = total
        names = [f"demo_{k}" for k in range(len(episodes))]
        f.create_dataset("mask/train", data=np.array(names[:-1], dtype="S"))
        f.create_dataset("mask/valid", data=np.array(names[-1:], dtype="S"))
    return path


MIMICGEN_MAPPING = {
    "source": "mimicgen",
    "rate": 20.0,
    "features": [
        {"key": "obs/robot0_eef_pos", "index": [0, 2], "names": ["hand_x", "hand_z"]},
        {"key": "obs/robot0_gripper_qpos", "index": [0], "names": ["finger"]},
        {"key": "obs/robot1_eef_pos", "index": [1], "names": ["left_y"]},
    ],
    "labels": {
        "right_arm": {
            "subtasks": [
                {"mp": "reach", "signal": "reached"},
                {"mp": "grasp", "signal": "grasped"},
                {"mp": "lift"},
            ]
        },
        "left_arm": {"subtasks": [{"mp": "hold", "signal": "push_started"}, {"mp": "push"}]},
    },
}


# ------------------------------------------------------------------------------ fixtures
@pytest.fixture(scope="session")
def episodes() -> list[Episode]:
    """Five executions of the task."""
    return make_episodes(5, seed=3)


@pytest.fixture(scope="session")
def bag_dir(tmp_path_factory, episodes) -> Path:
    """A folder of five bags: three sqlite3, two MCAP; the second has glitches."""
    root = tmp_path_factory.mktemp("bags")
    for k, e in enumerate(episodes):
        write_bag(root / f"run_{k}", e, storage="mcap" if k >= 3 else "sqlite3", glitch=k == 1)
    return root


@pytest.fixture(scope="session")
def lerobot_root(tmp_path_factory, episodes) -> Path:
    return write_lerobot(tmp_path_factory.mktemp("lerobot") / "pick_lift", episodes)


@pytest.fixture(scope="session")
def mimicgen_file(tmp_path_factory, episodes) -> Path:
    return write_mimicgen(tmp_path_factory.mktemp("mimicgen") / "pick_lift.hdf5", episodes)


EXPECTED = {"left_arm": ["hold", "push"], "right_arm": ["reach", "grasp", "lift"]}
"""The MP sequences of every episode."""


def fit_and_replay(path: Path) -> dict:
    """Fit cpmp's default sequencer on the file's ``mask/train`` demonstrations and replay
    every demonstration of the file through it (:func:`replay_demonstrations`'s result)."""
    train = load_demonstrations(path, split="train")
    seq = ConcurrentSequencer.fit(train, seed=0)
    everything = load_demonstrations(path)
    assert len(everything) == sum(len(v) for v in list_splits(path).values())
    return replay_demonstrations(seq, everything)


# ------------------------------------------------------------------- LeRobot 0.6 and SARM
LEROBOT_06_MAPPING = {
    "source": "lerobot",
    "features": [{"column": "observation.state", "name": "state"}],
    "labels": {
        "right_arm": {
            "language": "subtask",
            "rename": {
                "Reach for the box": "reach",
                "Grasp the box": "grasp",
                "Lift the box": "lift",
            },
        },
        "left_arm": {"language": "motion"},
    },
}
"""Labels from lerobot 0.6's ``language_persistent``: subtasks (right arm), motions (left)."""


def _frame_stamp(t: np.ndarray, at: float) -> float:
    """The stored (float32) timestamp of the first frame at or after ``at`` [s]."""
    return float(np.float32(t[np.searchsorted(t, at - 1e-9)]))


def write_lerobot_v06(root: Path, episodes: Sequence[Episode], fps: int = 30) -> Path:
    """A dataset as lerobot 0.6.1 leaves it after ``lerobot-annotate`` and SARM annotation.

    Starts from :func:`write_lerobot` and applies what lerobot 0.6.1 writes
    (``src/lerobot/annotations/steerable_pipeline/writer.py``, ``LanguageColumnsWriter``):
    ``subtask_index`` dropped from the frames, ``language_persistent`` and ``language_events``
    added, their arrow types inferred by ``pa.array`` from the row dicts (``role``,
    ``content``, ``style``, ``timestamp``, ``camera``, ``tool_calls``, persistent rows sorted by
    timestamp and broadcast to every frame of the episode), and ``meta/info.json`` features
    gaining both with dtype ``language``. ``meta/subtasks.parquet`` is gone. The persistent rows
    per episode: a ``task_aug`` row, ``subtask`` rows (the right arm's three subtasks), ``plan``
    rows, and ``motion`` rows (the left arm: ``hold``, ``push``), stamped at the first frame of
    each span. ``meta/episodes`` also gets SARM's sparse columns as its
    ``subtask_annotation.py`` writes them with pandas (``sparse_subtask_names``,
    ``sparse_subtask_start_times`` / ``_end_times`` / ``_start_frames`` / ``_end_frames`` and the
    legacy unprefixed copies), with the right arm's subtasks.
    """
    write_lerobot(root, episodes, fps)
    (root / "meta" / "subtasks.parquet").unlink()
    persistent: dict[int, list[dict]] = {}
    sarm: list[dict] = []
    for k, e in enumerate(episodes):
        t = np.arange(int(np.floor(e.t_end * fps)) + 1) / fps
        spans = [
            (0.0, "Reach for the box"),
            (e.t_grasp, "Grasp the box"),
            (e.t_lift, "Lift the box"),
        ]
        rows = [
            {"role": "user", "content": "Pick up the box", "style": "task_aug", "timestamp": 0.0},
            *(
                {
                    "role": "assistant",
                    "content": text,
                    "style": "subtask",
                    "timestamp": _frame_stamp(t, at),
                }
                for at, text in spans
            ),
            *(
                {
                    "role": "assistant",
                    "content": f"plan {i}",
                    "style": "plan",
                    "timestamp": _frame_stamp(t, at),
                }
                for i, (at, _) in enumerate(spans)
            ),
            {"role": "assistant", "content": "hold", "style": "motion", "timestamp": 0.0},
            {
                "role": "assistant",
                "content": "push",
                "style": "motion",
                "timestamp": _frame_stamp(t, e.t_push),
            },
        ]
        rows.sort(key=lambda r: (float(r["timestamp"]), r["style"], r["role"]))
        persistent[k] = [{**r, "camera": None, "tool_calls": None} for r in rows]
        starts = [_frame_stamp(t, at) for at, _ in spans]
        ends = [*starts[1:], float(t[-1])]
        sarm.append(
            {
                "names": [text for _, text in spans],
                "start_times": starts,
                "end_times": ends,
                "start_frames": [int(np.searchsorted(t, at - 1e-9)) for at, _ in spans],
                "end_frames": [
                    *(int(np.searchsorted(t, at - 1e-9)) for at, _ in spans[1:]),
                    len(t) - 1,
                ],
            }
        )
    for path in sorted(root.glob("data/*/*.parquet")):
        table = pq.read_table(path).drop_columns(["subtask_index"])
        episode = table.column("episode_index").to_pylist()
        table = table.append_column(
            "language_persistent", pa.array([persistent[k] for k in episode])
        )
        table = table.append_column("language_events", pa.array([[] for _ in episode]))
        pq.write_table(table, path)
    episodes_path = root / "meta" / "episodes" / "chunk-000" / "file-000.parquet"
    table = pq.read_table(episodes_path)
    for key in ("names", "start_times", "end_times", "start_frames", "end_frames"):
        values = [s[key] for s in sarm]
        table = table.append_column(f"sparse_subtask_{key}", pa.array(values))
        table = table.append_column(f"subtask_{key}", pa.array(values))
    pq.write_table(table, episodes_path)
    info_path = root / "meta" / "info.json"
    info = json.loads(info_path.read_text())
    del info["features"]["subtask_index"]
    for name in ("language_persistent", "language_events"):
        info["features"][name] = {"dtype": "language", "shape": [1], "names": None}
    info_path.write_text(json.dumps(info, indent=4))
    return root


@pytest.fixture(scope="session")
def lerobot_v06_root(tmp_path_factory, episodes) -> Path:
    """:func:`write_lerobot_v06` of the five episodes."""
    return write_lerobot_v06(tmp_path_factory.mktemp("lerobot06") / "pick_lift", episodes)
