"""ROS 2 bags written with rosbags' writer: mixed rates onto one clock, glitches, bad input,
and an import that fits and replays."""

import copy

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
            "no joint 'elbow' in the message; its joints are right_x, right_z, left_y, wrist",
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
