"""ROS 2 bags written with rosbags' writer: mixed rates onto one clock, glitches, bad input,
and an import that fits and replays."""

import copy
import json

import numpy as np
import pytest
from conftest import BAG_MAPPING, BAG_START_NS, EXPECTED, fit_and_replay, write_bag

from cpmp.data import list_splits, load_demonstrations, mp_sequences
from cpmp.errors import ConfigError, CpmpFileError, DataError
from cpmp.importers import SplitSpec, find_bags, import_recordings, read_recordings, summary_text


def mapping(**changes):
    out = copy.deepcopy(BAG_MAPPING)
    out.update(changes)
    return out


def bag_times(demo):
    """The demonstration's ticks in the bag's time [s from its first message]."""
    return (demo.metadata["start_ns"] - BAG_START_NS) / 1e9 + demo.time


def test_mixed_rate_bags_land_on_one_clock_with_the_recorded_values(bag_dir, episodes):
    result = read_recordings(mapping(min_activation=0.1), bag_dir)
    assert [d.name for d in result.demos] == [f"demo_run_{k}" for k in range(5)]
    for demo, e in zip(result.demos, episodes, strict=True):
        np.testing.assert_allclose(np.diff(demo.time), 0.02)  # rate: 50 Hz
        assert demo.feature_names == [
            "joint_states.position.right_x",
            "joint_states.position.right_z",
            "joint_states.position.left_y",
            "gripper",
            "box.x",
            "box.y",
            "box.z",
        ]
        t = bag_times(demo)
        # the clock starts when the last topic starts: /gripper, 4 ms after the bag
        assert t[0] == pytest.approx(0.004)
        x = demo.features
        # linear interpolation of the smooth trajectories: 100 Hz joint states within 1e-3,
        # the 30 Hz gripper within 1e-2, the 10 Hz box height within 1e-2
        np.testing.assert_allclose(x[:, 0], e.hand_x(t), atol=1e-3)
        np.testing.assert_allclose(x[:, 2], e.left_y(t), atol=1e-3)
        np.testing.assert_allclose(x[:, 3], e.gripper(t), atol=1e-2)
        np.testing.assert_allclose(x[:, 6], e.hand_z(t), atol=1e-2)
        np.testing.assert_allclose(x[:, 4], e.x_goal + 0.05)
        assert mp_sequences(demo) == EXPECTED
        # zero-order hold of a 20 Hz label topic on a 50 Hz clock: each switch at most one
        # label period (50 ms) plus one tick (20 ms) after the true switch, never before it
        for v, truth in (("right_arm", e.right_mp(t)), ("left_arm", e.left_mp(t))):
            for i in demo.switch_indices(v):
                first_true = np.flatnonzero(truth == demo.labels[v][i])[0]
                assert 0 <= t[i] - t[first_true] <= 0.07 + 1e-9
    sources = [item.source for item in result.imported]
    assert sources[3].endswith("run_3") and any(
        p.suffix == ".mcap" for p in bag_dir.joinpath("run_3").iterdir()
    )
    assert any(p.suffix == ".db3" for p in bag_dir.joinpath("run_0").iterdir())


def test_a_single_mcap_file_is_a_bag(bag_dir):
    (mcap,) = [p for p in (bag_dir / "run_3").iterdir() if p.suffix == ".mcap"]
    assert find_bags(mcap) == [mcap]
    (demo,) = read_recordings(mapping(), mcap).demos
    assert mp_sequences(demo) == EXPECTED


def test_a_glitching_label_topic_is_repaired_and_reported(bag_dir):
    raw = read_recordings(mapping(), bag_dir / "run_1")
    (demo,) = raw.demos
    # the one-message 'grasp' inside the reach shows up without min_activation
    assert mp_sequences(demo)["right_arm"] == ["reach", "grasp", "reach", "grasp", "lift"]
    kinds = {(n.kind, n.where) for n in raw.notes}
    assert ("duplicates", "topic /right_arm/mp") in kinds
    assert ("out_of_order", "topic /joint_states") in kinds
    fixed = read_recordings(mapping(min_activation=0.1), bag_dir / "run_1")
    assert mp_sequences(fixed.demos[0]) == EXPECTED
    (glitch,) = [n for n in fixed.notes if n.kind == "glitch"]
    # the glitch message is at 0.4 s of the bag; the first tick after it, 0.404 s, is 0.400 s
    # of the demonstration (whose clock starts at 0.004 s); three 20 ms ticks long
    assert glitch.where == "right_arm" and "'grasp' at 0.400 s lasted 0.060 s" in glitch.text
    assert "merged into 'reach'" in glitch.text
    text = summary_text(fixed)
    assert "demo_run_1 [train]" in text and "reach -> grasp -> lift" in text
    assert "merged into 'reach'" in text and "graph right_arm:" in text


def test_import_fits_and_replays_the_labelled_sequences(bag_dir, tmp_path):
    out = tmp_path / "bags.hdf5"
    result = import_recordings(
        mapping(min_activation=0.1), bag_dir, out, SplitSpec(test_fraction=0.2, seed=0)
    )
    assert result.path == out and list_splits(out) == result.splits
    assert len(result.splits["test"]) == 1 and len(result.splits["train"]) == 4
    assert [d.name for d in load_demonstrations(out)] == [f"demo_run_{k}" for k in range(5)]
    replay = fit_and_replay(out)
    assert replay["all_match"] == 1.0, replay["per_demo"]
    # measured mean 0.06 (features span ~[0, 0.5]); 0.15 would be a visibly late switch
    assert replay["distance_mean"] < 0.15


def test_a_missing_topic_is_one_clear_error_and_no_file(tmp_path, episodes):
    bags = tmp_path / "bags"
    write_bag(bags / "run_0", episodes[0])
    write_bag(bags / "run_1", episodes[1], drop_topics=["/gripper"])
    out = tmp_path / "demos.hdf5"
    with pytest.raises(DataError) as err:
        import_recordings(mapping(), bags, out)
    message = str(err.value)
    assert "demo_run_1" in message and "no topic /gripper" in message
    assert "mapped to feature gripper" in message and "/joint_states" in message
    assert "fix the topic in the mapping" in message
    assert not out.exists() and list(tmp_path.iterdir()) == [bags]
    out.write_bytes(b"an earlier import")
    with pytest.raises(DataError):
        import_recordings(mapping(), bags, out)
    assert out.read_bytes() == b"an earlier import"


def test_a_gap_is_reported_or_refused(tmp_path, episodes):
    bag = write_bag(tmp_path / "quiet", episodes[0], silence=("/gripper", 0.5, 0.9))
    result = read_recordings(mapping(), bag)
    (gap,) = [n for n in result.notes if n.kind == "gap"]
    assert gap.where == "topic /gripper" and "silent for 0.4" in gap.text
    with pytest.raises(DataError, match=r"topic /gripper is silent for 0\.4\d+ s"):
        read_recordings(mapping(on_gap="error"), bag)
    assert not any(n.kind == "gap" for n in read_recordings(mapping(max_gap=0.5), bag).notes)


@pytest.mark.parametrize(
    ("change", "error", "match"),
    [
        (
            {"features": [{"topic": "/box_pose", "field": "pose.positon"}]},
            DataError,
            "geometry_msgs/msg/Pose has no field 'positon'; its fields are position, orientation",
        ),
        (
            {"features": [{"topic": "/joint_states", "field": "position", "index": [0, 9]}]},
            DataError,
            r"has 4 element\(s\) but the mapping's index asks for \[9\]",
        ),
        (
            {"features": [{"topic": "/joint_states", "field": "position", "joints": ["elbow"]}]},
            DataError,
            "joint 'elbow' is in no message of the topic; the joints seen are right_x, "
            "right_z, left_y, wrist",
        ),
        (
            {"labels": {"right_arm": {"topic": "/gripper"}}},
            DataError,
            "label topic /gripper field data is a float at .* not an MP name",
        ),
        (
            {
                "labels": {
                    "left_arm": {
                        "topic": "/left_arm/switch",
                        "kind": "events",
                        "sequence": ["hold", "push", "wave"],
                    }
                }
            },
            DataError,
            r"1 switch event\(s\) but the mapping's sequence for 'left_arm' lists 2",
        ),
        (
            {"labels": {"right_arm": {"topic": "/right_arm/mp", "mps": ["reach", "grasp"]}}},
            DataError,
            r"topic /right_arm/mp names MP\(s\) \['lift'\] that are not in the mapping's mps",
        ),
        (
            {"labels": {"right_arm": {"topic": "/right_arm/mp", "kind": "events"}}},
            ConfigError,
            "an events topic needs either sequence",
        ),
        ({"rate": 0}, ConfigError, r"rate \[Hz\] must be > 0"),
        ({"stamp": "header"}, ConfigError, "unknown key.* stamp; known keys: .*stamps"),
    ],
)
def test_bad_mappings_name_what_to_fix(bag_dir, tmp_path, change, error, match):
    out = tmp_path / "demos.hdf5"
    with pytest.raises(error, match=match):
        import_recordings(mapping(**change), bag_dir / "run_0", out)
    assert not out.exists()


def test_not_a_bag_is_a_file_error(tmp_path):
    (tmp_path / "notes.txt").write_text("hello")
    with pytest.raises(CpmpFileError, match="is not a ROS 2 bag and holds none"):
        read_recordings(mapping(), tmp_path)
    with pytest.raises(CpmpFileError, match="does not exist"):
        read_recordings(mapping(), tmp_path / "missing")
    broken = tmp_path / "broken"
    broken.mkdir()
    (broken / "metadata.yaml").write_text("rosbag2_bagfile_information: {version: 9}\n")
    with pytest.raises(CpmpFileError, match=r"cannot read .*broken as a ROS 2 bag"):
        read_recordings(mapping(), broken)


def test_a_damaged_bag_is_a_file_error_and_no_file(tmp_path, episodes):
    bag = write_bag(tmp_path / "run_0", episodes[0])
    (db3,) = bag.glob("*.db3")
    db3.write_bytes(db3.read_bytes()[:4096])  # cut short, as by a full disk
    out = tmp_path / "out.hdf5"
    with pytest.raises(CpmpFileError, match=r"cannot read .*run_0 as a ROS 2 bag .*malformed"):
        import_recordings(mapping(), bag, out)
    assert not out.exists()


# ------------------------------------------------------------------- recordings as robots make them
# Issue #33: bags as a real robot's tools leave them, written with rosbags' Writer and the
# message types of ROS 2 Humble (rosbag2 version 8) and Jazzy (version 9): /joint_states shared
# by an arm's and a gripper's driver, the box's pose on /tf (transform order varying, the table
# on /tf_static), mocap quaternion sign flips, a label topic that starts late, an interrupted
# recording, an empty bag, unicode folder names.
from rosbags.rosbag2 import StoragePlugin, Writer  # noqa: E402
from rosbags.typesys import Stores, get_typestore  # noqa: E402

from cpmp.importers.common import demo_name  # noqa: E402

STORES = {"humble": get_typestore(Stores.ROS2_HUMBLE), "jazzy": get_typestore(Stores.ROS2_JAZZY)}
TABLE = (np.array([1.0, 0.5, 0.7]), np.array([0.0, 0.0, np.sqrt(0.5), np.sqrt(0.5)]))
"""world -> table on /tf_static: translation, and a quarter turn about z (x, y, z, w)."""


def _yaw(angle):
    """(n, 4) quaternions x, y, z, w of rotations by ``angle`` [rad] about z."""
    angle = np.asarray(angle, dtype=float)
    return np.column_stack([0 * angle, 0 * angle, np.sin(angle / 2), np.cos(angle / 2)])


def box_in_table(e, t):
    """The box's pose in the table frame at times t: lifted with the hand, turning about z."""
    t = np.asarray(t, dtype=float)
    position = np.column_stack([0.1 + 0 * t, 0.2 + 0 * t, 0.05 + e.hand_z(t)])
    return position, _yaw(0.4 * t)


def box_in_world(e, t):
    """world -> table (a quarter turn about z) composed with table -> box."""
    position, _ = box_in_table(e, t)
    offset, _ = TABLE
    world = offset + np.column_stack([-position[:, 1], position[:, 0], position[:, 2]])
    return world, _yaw(np.pi / 2 + 0.4 * np.asarray(t, dtype=float))


def write_robot_bag(
    path,
    e,
    *,
    store="jazzy",
    storage="mcap",
    label_start=0.0,
    flips=False,
    tf_shuffle=True,
):
    """A bag as a bimanual robot with mocap records it.

    ``/joint_states``: the arm driver at 100 Hz (``right_x, right_z, left_y``), the gripper
    driver at 30 Hz (``finger``) and a torque sensor at 10 Hz (``wrist`` efforts, empty
    positions); ``/tf`` at 50 Hz with ``world -> base`` (fixed values), ``base -> ee`` and
    ``table -> box`` in an order that changes per message (and the box's quaternion negated
    in every third message with ``flips``); ``/tf_static`` once with ``world -> table``;
    ``/right_arm/mp`` (String, 20 Hz from ``label_start``) and ``/left_arm/switch`` (Empty).
    """
    typestore = STORES[store]
    types = typestore.types
    Header, Time = types["std_msgs/msg/Header"], types["builtin_interfaces/msg/Time"]
    JointState = types["sensor_msgs/msg/JointState"]
    TFMessage = types["tf2_msgs/msg/TFMessage"]
    TransformStamped, Transform = (
        types["geometry_msgs/msg/TransformStamped"],
        types["geometry_msgs/msg/Transform"],
    )
    Vector3, Quaternion = types["geometry_msgs/msg/Vector3"], types["geometry_msgs/msg/Quaternion"]
    String, Empty = types["std_msgs/msg/String"], types["std_msgs/msg/Empty"]

    def header(t, frame):
        ns = BAG_START_NS + round(t * 1e9)
        return Header(stamp=Time(sec=ns // 10**9, nanosec=ns % 10**9), frame_id=frame)

    def joints(t, names, position, effort=()):
        return JointState(
            header=header(t, ""),
            name=list(names),
            position=np.asarray(position, dtype=np.float64),
            velocity=np.zeros(0),
            effort=np.asarray(effort, dtype=np.float64),
        )

    def transform(t, parent, child, position, q):
        return TransformStamped(
            header=header(t, parent),
            child_frame_id=child,
            transform=Transform(
                translation=Vector3(
                    x=float(position[0]), y=float(position[1]), z=float(position[2])
                ),
                rotation=Quaternion(x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3])),
            ),
        )

    records = []  # (receive time [s], topic, message)
    for t in np.arange(0.0, e.t_end, 0.01):
        msg = joints(t, ["right_x", "right_z", "left_y"], [e.hand_x(t), e.hand_z(t), e.left_y(t)])
        records.append((t + 0.002, "/joint_states", msg))
    for t in np.arange(0.005, e.t_end, 1 / 30):
        records.append((t + 0.001, "/joint_states", joints(t, ["finger"], [e.gripper(t)])))
    for t in np.arange(0.003, e.t_end, 0.1):
        records.append((t, "/joint_states", joints(t, ["wrist"], [], [1.5])))
    rng = np.random.default_rng(0)
    for k, t in enumerate(np.arange(0.0, e.t_end, 0.02)):
        position, q = box_in_table(e, [t])
        box_q = -q[0] if flips and k % 3 == 1 else q[0]
        transforms = [
            transform(t, "world", "base", [0.0, 0.0, 0.3], [0, 0, 0, 1]),
            transform(t, "base", "ee", [e.hand_x(t), 0.0, e.hand_z(t)], [0, 0, 0, 1]),
            transform(t, "table", "box", position[0], box_q),
        ]
        order = rng.permutation(3) if tf_shuffle else range(3)
        records.append((t + 0.004, "/tf", TFMessage(transforms=[transforms[i] for i in order])))
    static = TFMessage(transforms=[transform(0.0, "world", "table", TABLE[0], TABLE[1])])
    records.append((0.0, "/tf_static", static))
    for t in np.arange(label_start, e.t_end, 0.05):
        records.append((t, "/right_arm/mp", String(data=str(e.right_mp(np.array(t))))))
    records.append((e.t_push, "/left_arm/switch", Empty()))
    return write_records(path, records, store=store, storage=storage)


def write_records(path, records, *, store="jazzy", storage="mcap"):
    """Write ``(receive time [s], topic, message)`` records as a rosbag2 bag."""
    typestore = STORES[store]
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    version = 8 if store == "humble" else 9
    records = sorted(records, key=lambda r: r[0])
    with Writer(path, version=version, storage_plugin=plugin) as writer:
        connections = {}
        for when, topic, msg in records:
            if topic not in connections:
                connections[topic] = writer.add_connection(
                    topic, msg.__msgtype__, typestore=typestore
                )
            data = typestore.serialize_cdr(msg, msg.__msgtype__)
            writer.write(connections[topic], BAG_START_NS + round(when * 1e9), data)
    return path


ROBOT_MAPPING = {
    "source": "rosbag",
    "rate": 50.0,
    "max_gap": 0.25,
    "features": [
        {"topic": "/joint_states", "field": "position", "joints": ["right_x", "finger", "left_y"]},
        {"tf": {"child": "box", "parent": "world"}, "name": "box", "rotation": "matrix6"},
    ],
    "labels": {
        "right_arm": {"topic": "/right_arm/mp", "mps": ["reach", "grasp", "lift"]},
        "left_arm": {"topic": "/left_arm/switch", "kind": "events", "sequence": ["hold", "push"]},
    },
}


def robot_mapping(**changes):
    out = copy.deepcopy(ROBOT_MAPPING)
    out.update(changes)
    return out


@pytest.mark.parametrize(("store", "storage"), [("humble", "sqlite3"), ("jazzy", "mcap")])
def test_joint_states_from_two_publishers_merge_by_joint_name(tmp_path, episodes, store, storage):
    e = episodes[0]
    bag = write_robot_bag(tmp_path / "split", e, store=store, storage=storage)
    result = read_recordings(
        robot_mapping(features=[ROBOT_MAPPING["features"][0]], max_gap=0.5), bag
    )
    (demo,) = result.demos
    assert demo.feature_names == [
        "joint_states.position.right_x",
        "joint_states.position.finger",
        "joint_states.position.left_y",
    ]
    t = bag_times(demo)
    # the arm's 100 Hz joints and the gripper's 30 Hz joint, each interpolated at its own
    # stamps: the finger is not held between the arm's messages (that would err by ~0.1)
    np.testing.assert_allclose(demo.features[:, 0], e.hand_x(t), atol=1e-3)
    np.testing.assert_allclose(demo.features[:, 1], e.gripper(t), atol=1e-2)
    np.testing.assert_allclose(demo.features[:, 2], e.left_y(t), atol=1e-3)
    assert t[0] == pytest.approx(0.005)  # when the gripper's series starts
    assert mp_sequences(demo) == EXPECTED
    # one series per publisher's set of joints; no gap (each series at its own rate)
    assert not [n for n in result.notes if n.kind in ("gap", "out_of_order", "duplicates")]
    with pytest.raises(DataError) as err:
        read_recordings(
            robot_mapping(
                features=[{"topic": "/joint_states", "field": "position", "joints": ["elbow"]}]
            ),
            bag,
        )
    assert "joint 'elbow' is in no message of the topic" in str(err.value)
    assert "joints seen are right_x, right_z, left_y, wrist, finger" in str(err.value)
    with pytest.raises(DataError, match="joint 'wrist' has no value in the topic"):
        read_recordings(
            robot_mapping(
                features=[{"topic": "/joint_states", "field": "position", "joints": ["wrist"]}]
            ),
            bag,
        )


@pytest.mark.parametrize("rotation", ["quat", "rotvec", "matrix6"])
def test_a_box_on_tf_is_found_in_any_order_and_composed_to_the_world(tmp_path, episodes, rotation):
    e = episodes[1]
    bag = write_robot_bag(tmp_path / "tf", e, store="humble", storage="sqlite3")
    features = [{"tf": {"child": "box", "parent": "world"}, "name": "box", "rotation": rotation}]
    result = read_recordings(robot_mapping(features=features), bag)
    (demo,) = result.demos
    t = bag_times(demo)
    width = {"quat": 4, "rotvec": 3, "matrix6": 6}[rotation]
    assert demo.feature_names[:3] == ["box.translation.x", "box.translation.y", "box.translation.z"]
    assert len(demo.feature_names) == 3 + width
    position, q = box_in_world(e, t)
    # the table turns the box's (0.1, 0.2) into (-0.2, 0.1) before its offset (1.0, 0.5, 0.7)
    np.testing.assert_allclose(demo.features[:, :3], position, atol=2e-3)
    angle = np.pi / 2 + 0.4 * t
    expected = {
        "quat": q,
        "rotvec": np.column_stack([0 * t, 0 * t, angle]),
        "matrix6": np.column_stack(
            [np.cos(angle), np.sin(angle), 0 * t, -np.sin(angle), np.cos(angle), 0 * t]
        ),
    }[rotation]
    np.testing.assert_allclose(demo.features[:, 3:], expected, atol=1e-6)
    # the box's own transform, in its parent (the table) as published
    (direct,) = read_recordings(
        robot_mapping(features=[{"tf": {"child": "box"}, "index": [0, 1, 2]}]), bag
    ).demos
    assert direct.feature_names == [
        "tf.box.translation.x",
        "tf.box.translation.y",
        "tf.box.translation.z",
    ]
    np.testing.assert_allclose(direct.features, box_in_table(e, bag_times(direct))[0], atol=2e-3)
    # the box seen from the end effector: up to the world and down through base -> ee
    (seen,) = read_recordings(
        robot_mapping(features=[{"tf": {"child": "box", "parent": "ee"}, "index": [0]}]), bag
    ).demos
    ts = bag_times(seen)
    np.testing.assert_allclose(
        seen.features[:, 0], box_in_world(e, ts)[0][:, 0] - e.hand_x(ts), atol=2e-3
    )
    with pytest.raises(DataError) as err:
        read_recordings(robot_mapping(features=[{"tf": {"child": "bx", "parent": "world"}}]), bag)
    assert "no transform has child_frame_id 'bx' on /tf and /tf_static" in str(err.value)
    assert "frames there are base, box, ee, table, world" in str(err.value)


def test_a_late_label_topic_names_itself_and_the_cut(tmp_path, episodes):
    e = episodes[2]
    bag = write_robot_bag(tmp_path / "late", e, label_start=0.6)
    result = read_recordings(robot_mapping(), bag)
    (demo,) = result.demos
    assert bag_times(demo)[0] == pytest.approx(0.6)
    (window,) = [n for n in result.notes if n.kind == "window"]
    text = window.text
    assert "it starts when label topic /right_arm/mp starts" in text
    assert "label topic /right_arm/mp starts 0.600 s after the first feature data (0.000 s)" in text
    recorded = max(np.arange(0.0, e.t_end, 0.01)[-1], np.arange(0.0, e.t_end, 0.02)[-1])
    assert f"the recorded {recorded:.3f} s become {demo.duration:.3f} s" in text
    assert "every feature topic" not in text
    (on_time,) = [
        n
        for n in read_recordings(robot_mapping(), write_robot_bag(tmp_path / "ok", e)).notes
        if n.kind == "window"
    ]
    assert "cutting" not in on_time.text and "become" not in on_time.text


def test_quaternion_sign_flips_are_aligned_and_slerped(tmp_path, episodes):
    e = episodes[3]
    bag = write_robot_bag(tmp_path / "flips", e, flips=True)
    features = [{"tf": {"child": "box"}, "slice": [3, 7], "names": ["qx", "qy", "qz", "qw"]}]
    result = read_recordings(robot_mapping(features=features), bag)
    (demo,) = result.demos
    q = demo.features
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-12)
    truth = box_in_table(e, bag_times(demo))[1]
    # one hemisphere throughout: the flipped samples do not show
    np.testing.assert_allclose(q * np.sign(q[0, 3] * truth[0, 3]), truth, atol=1e-6)
    (flip,) = [n for n in result.notes if n.kind == "flip"]
    n_tf = len(np.arange(0.0, e.t_end, 0.02))
    # every third message (k = 1, 4, ...) is negated: a flip into it and one out of it
    assert flip.where == "/tf table -> box"
    assert f"{len(range(1, n_tf, 3)) * 2 - (n_tf % 3 == 2)} quaternion sign flip(s)" in flip.text


def test_an_interrupted_recording_is_named_with_its_repair(tmp_path, episodes):
    bags = tmp_path / "bags"
    write_robot_bag(bags / "run_0", episodes[0], store="humble", storage="sqlite3")
    interrupted = write_robot_bag(bags / "run_1", episodes[1], storage="mcap")
    (interrupted / "metadata.yaml").unlink()  # ros2 bag record writes it when it closes
    assert find_bags(bags) == [bags / "run_0", interrupted]
    for given in (bags, interrupted):
        with pytest.raises(DataError) as err:
            read_recordings(robot_mapping(), given)
        message = str(err.value)
        assert f"demo_run_1: bag folder {interrupted} has no metadata.yaml" in message
        assert f"`ros2 bag reindex {interrupted} -s mcap`" in message


def test_an_empty_bag_says_it_is_empty(tmp_path):
    with Writer(tmp_path / "empty", version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        writer.add_connection(
            "/joint_states", "sensor_msgs/msg/JointState", typestore=STORES["jazzy"]
        )
    with pytest.raises(DataError) as err:
        read_recordings(robot_mapping(), tmp_path / "empty")
    message = str(err.value)
    assert f"demo_empty: bag {tmp_path / 'empty'} is empty: it holds no messages" in message
    assert "record it or remove it from the mapping" not in message


def test_unicode_folder_names_stay_distinct(tmp_path, episodes):
    bags = tmp_path / "bags"
    for name in ("試行_2", "実験_2"):
        write_robot_bag(bags / name, episodes[0])
    names = [d.name for d in read_recordings(robot_mapping(), bags).demos]
    assert len(set(names)) == 2
    decoded = {n.removeprefix("demo_xn--").encode().decode("punycode") for n in names}
    assert decoded == {"試行_2", "実験_2"}
    assert demo_name("run_1") == "demo_run_1"
    write_robot_bag(bags / "試行 2", episodes[0])  # a space becomes '_' after encoding too
    clash = bags / "clash"
    write_robot_bag(clash / "run 1", episodes[0])
    write_robot_bag(clash / "run_1", episodes[0])
    with pytest.raises(CpmpFileError) as err:
        read_recordings(robot_mapping(), clash)
    assert f"bags {clash / 'run 1'} and {clash / 'run_1'} would both become demo_run_1" in str(
        err.value
    )


def test_a_folder_of_real_world_bags_imports_in_one_call(tmp_path, episodes):
    bags = tmp_path / "bags"
    quirks = [
        ("run_0", {"store": "humble", "storage": "sqlite3"}),
        ("run_1", {"store": "jazzy", "storage": "mcap", "flips": True}),
        ("run_2", {"store": "jazzy", "storage": "sqlite3", "label_start": 0.3}),
        ("試行_3", {"store": "humble", "storage": "mcap", "flips": True}),
        ("実験_3", {"store": "jazzy", "storage": "mcap"}),
    ]
    for (name, options), e in zip(quirks, episodes, strict=True):
        write_robot_bag(bags / name, e, **options)
    out = tmp_path / "demos.hdf5"
    result = import_recordings(robot_mapping(min_activation=0.1), bags, out)
    assert len(result.demos) == 5 and out.exists()
    for demo in load_demonstrations(out):
        assert demo.n_features == 3 + 3 + 6
        assert mp_sequences(demo) == EXPECTED
    flipped = {"run_1", "試行_3"}
    assert {n.demo for n in result.notes if n.kind == "flip"} == {
        item.demo.name for item in result.imported if item.source.rsplit("/", 1)[-1] in flipped
    }
    (late,) = [n for n in result.notes if n.kind == "window" and "cutting" in n.text]
    assert late.demo == "demo_run_2"
    interrupted = write_robot_bag(bags / "run_9", episodes[4])
    (interrupted / "metadata.yaml").unlink()
    with pytest.raises(DataError, match=r"demo_run_9: bag folder .*run_9 has no metadata\.yaml"):
        import_recordings(robot_mapping(min_activation=0.1), bags, tmp_path / "again.hdf5")


def test_the_issues_folder_of_eight_bags_imports_the_good_ones_with_skip(tmp_path, episodes):
    """#33's target: eight bags with a lab's quirks (split /joint_states, the box on /tf in a
    varying order, a late label topic, quaternion flips, unicode names, one interrupted
    recording) import with one call in skip mode, with the notes and the skipped bag named."""
    bags = tmp_path / "bags"
    quirks = [
        ("run_0", {"store": "humble", "storage": "sqlite3"}),
        ("run_1", {"store": "jazzy", "storage": "mcap", "flips": True}),
        ("run_2", {"store": "jazzy", "storage": "sqlite3", "label_start": 0.3}),
        ("試行_3", {"store": "humble", "storage": "mcap", "flips": True}),
        ("実験_3", {"store": "jazzy", "storage": "mcap"}),
        ("run_5", {"store": "humble", "storage": "mcap", "label_start": 0.2, "flips": True}),
        ("run_6", {"store": "jazzy", "storage": "sqlite3", "tf_shuffle": False}),
    ]
    for k, (name, options) in enumerate(quirks):
        write_robot_bag(bags / name, episodes[k % len(episodes)], **options)
    (write_robot_bag(bags / "run_7", episodes[0]) / "metadata.yaml").unlink()
    out = tmp_path / "demos.hdf5"
    result = import_recordings(robot_mapping(min_activation=0.1), bags, out, on_error="skip")
    assert len(result.demos) == 7 and out.exists()
    assert all(mp_sequences(d) == EXPECTED for d in load_demonstrations(out))
    (skipped,) = result.skipped
    assert skipped.demo == "demo_run_7" and "ros2 bag reindex" in skipped.reason
    report = json.loads(result.skipped_path.read_text())
    assert [row["demo"] for row in report["skipped"]] == ["demo_run_7"]
    late = {n.demo for n in result.notes if n.kind == "window" and "cutting" in n.text}
    assert late == {"demo_run_2", "demo_run_5"}
    flips = {n.demo for n in result.notes if n.kind == "flip"}
    assert len(flips) == 3 and "demo_run_5" in flips


@pytest.mark.parametrize(
    ("feature", "match"),
    [
        ({"topic": "/tf", "tf": {"child": "box"}}, "give topic .* or tf: .* exactly one"),
        ({"tf": {"child": "box"}, "field": "transform"}, "field and joints are for topic features"),
        ({"tf": {"child": "box", "parnt": "world"}}, "unknown key.* parnt; known keys: child"),
        ({"tf": {"child": "box"}, "names": ["x"]}, "names has 1 entries but 7 elements"),
        ({"tf": {"child": "box"}, "rotation": "euler"}, "rotation must be one of quat, rotvec"),
        ({"tf": {"child": "box", "parent": "/box"}}, "parent and child are both 'box'"),
    ],
)
def test_bad_tf_and_rotation_entries_are_config_errors(feature, match):
    with pytest.raises(ConfigError, match=match):
        read_recordings(robot_mapping(features=[feature]), "unused")


def test_rotation_without_a_quaternion_names_the_field(tmp_path, episodes):
    bag = write_robot_bag(tmp_path / "bag", episodes[0])
    feature = {"topic": "/joint_states", "field": "header.stamp", "rotation": "rotvec"}
    with pytest.raises(DataError, match=r"field header\.stamp holds no quaternion .* rotvec"):
        read_recordings(robot_mapping(features=[feature]), bag)
