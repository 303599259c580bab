"""LeRobot v3 datasets written with pyarrow in the documented layout: per-variable label
columns, subtask_index, resampling, bad input, and an import that fits and replays."""

import copy
import json
import shutil

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from conftest import EXPECTED, LEROBOT_MAPPING, LEROBOT_SUBTASKS, fit_and_replay

from cpmp.data import list_splits, mp_sequences
from cpmp.errors import ConfigError, CpmpFileError, DataError
from cpmp.importers import SplitSpec, import_recordings, read_recordings, summary_text


def mapping(**changes):
    out = copy.deepcopy(LEROBOT_MAPPING)
    out.update(changes)
    return out


def copy_dataset(root, tmp_path):
    return shutil.copytree(root, tmp_path / "dataset")


def test_episodes_become_demonstrations_on_the_recorded_frames(lerobot_root, episodes):
    result = read_recordings(mapping(), lerobot_root)
    assert [d.name for d in result.demos] == [f"demo_{k}" for k in range(5)]
    for demo, e in zip(result.demos, episodes, strict=True):
        # names from info.json's features[observation.state].names under the mapping's prefix
        assert demo.feature_names == [
            "state.hand_x",
            "state.hand_z",
            "state.gripper",
            "state.left_y",
        ]
        np.testing.assert_allclose(np.diff(demo.time), 1 / 30, atol=1e-6)  # float32 stamps
        # float32 storage: values within 1e-6 of the trajectory
        np.testing.assert_allclose(demo.features, e.state(demo.time), atol=1e-6)
        np.testing.assert_array_equal(demo.labels["right_arm"], e.right_mp(demo.time))
        np.testing.assert_array_equal(demo.labels["left_arm"], e.left_mp(demo.time))
        assert demo.metadata["episode_index"] == int(demo.name.split("_")[1])
    assert not result.notes  # regular frames: nothing repaired


def test_subtask_index_labels_one_variable_with_names_from_subtasks_parquet(lerobot_root):
    result = read_recordings(
        mapping(labels={"right_arm": {"column": "subtask_index"}}), lerobot_root
    )
    assert mp_sequences(result.demos[0]) == {"right_arm": LEROBOT_SUBTASKS}
    short = {"Reach for the box": "reach", "Grasp the box": "grasp", "Lift the box": "lift"}
    renamed = read_recordings(
        mapping(labels={"right_arm": {"column": "subtask_index", "rename": short}}), lerobot_root
    )
    assert mp_sequences(renamed.demos[0]) == {"right_arm": EXPECTED["right_arm"]}


def test_resampling_picks_episodes_and_keeps_the_labels(lerobot_root, episodes):
    result = read_recordings(mapping(rate=50.0, episodes=[3, 1]), lerobot_root)
    assert [d.name for d in result.demos] == ["demo_3", "demo_1"]
    demo, e = result.demos[0], episodes[3]
    np.testing.assert_allclose(np.diff(demo.time), 0.02)
    # linear interpolation of 30 Hz frames of the smooth trajectories: within 1e-2
    np.testing.assert_allclose(demo.features, e.state(demo.time), atol=1e-2)
    assert mp_sequences(demo) == EXPECTED
    assert "resampled from 30 to 50 Hz" in result.imported[0].notes[0].text


def test_import_fits_and_replays_the_labelled_sequences(lerobot_root, tmp_path):
    out = tmp_path / "lerobot.hdf5"
    result = import_recordings(mapping(), lerobot_root, out, SplitSpec(test=("demo_2",)))
    assert list_splits(out) == {
        "train": ["demo_0", "demo_1", "demo_3", "demo_4"],
        "test": ["demo_2"],
    }
    assert "demo_2 [test]" in summary_text(result)
    replay = fit_and_replay(out)
    assert replay["all_match"] == 1.0, replay["per_demo"]
    assert replay["sequence_match"] == {"left_arm": 1.0, "right_arm": 1.0}


def _rewrite_data(root, change):
    """Apply ``change(table) -> table`` to every data file."""
    for path in sorted(root.glob("data/*/*.parquet")):
        pq.write_table(change(pq.read_table(path)), path)


def _set_info(root, **values):
    info_path = root / "meta" / "info.json"
    info = json.loads(info_path.read_text())
    info.update(values)
    info_path.write_text(json.dumps(info))


def test_a_missing_column_is_one_clear_error_and_no_file(lerobot_root, tmp_path):
    out = tmp_path / "out.hdf5"
    with pytest.raises(DataError) as err:
        import_recordings(mapping(features=[{"column": "observation.effort"}]), lerobot_root, out)
    message = str(err.value)
    assert "column observation.effort is not in data/chunk-000/file-000.parquet" in message
    assert "observation.state" in message and "fix the column name in the mapping" in message
    assert not out.exists()


def test_unannotated_frames_are_refused(lerobot_root, tmp_path):
    root = copy_dataset(lerobot_root, tmp_path)

    def blank_one(table):
        column = table.column("left_arm_mp").to_pylist()
        column[5] = None
        index = table.schema.get_field_index("left_arm_mp")
        return table.set_column(index, "left_arm_mp", pa.array(column, pa.string()))

    _rewrite_data(root, blank_one)
    out = tmp_path / "out.hdf5"
    with pytest.raises(DataError) as err:
        import_recordings(mapping(), root, out)
    message = str(err.value)
    assert (
        "column left_arm_mp is empty (null) in 1 frame(s) of episode 0, first at frame 5" in message
    )
    assert "(row 5 of data/chunk-000/file-000.parquet)" in message
    assert not out.exists()


def test_subtask_index_without_subtasks_parquet_says_what_to_do(lerobot_root, tmp_path):
    root = copy_dataset(lerobot_root, tmp_path)
    (root / "meta" / "subtasks.parquet").unlink()
    with pytest.raises(DataError, match=r"meta/subtasks.parquet \(the subtask names\) is missing"):
        read_recordings(mapping(labels={"phase": {"column": "subtask_index"}}), root)
    named = read_recordings(
        mapping(labels={"phase": {"column": "subtask_index", "names": ["a", "b", "c"]}}), root
    )
    assert mp_sequences(named.demos[0]) == {"phase": ["a", "b", "c"]}


@pytest.mark.parametrize(
    ("change", "error", "match"),
    [
        (
            {"labels": {"right_arm": {"column": "right_arm_mp"}}},
            DataError,
            "column right_arm_mp holds integer ids; give the control variable 'right_arm' names",
        ),
        (
            {"labels": {"right_arm": {"column": "right_arm_mp", "names": ["grasp", "lift"]}}},
            DataError,
            r"holds id\(s\) \[2\] that have no name",
        ),
        ({"episodes": [0, 9]}, DataError, r"episode\(s\) \[9\] are not in the data; .*0-4"),
        (
            {"features": [{"column": "left_arm_mp"}]},
            DataError,
            "column left_arm_mp has type string; features need numbers",
        ),
        (
            {"features": [{"column": "observation.state", "slice": [2, 6]}]},
            DataError,
            r"has 4 element\(s\) but the mapping's slice is \[2, 6\]",
        ),
        (
            {"features": [{"column": "observation.state", "names": ["a", "b"]}]},
            DataError,
            r"column observation.state: the mapping gives 2 names but 4 element\(s\) are selected",
        ),
        ({"rate": -1}, ConfigError, r"rate \[Hz\] must be > 0"),
        ({"labels": {}}, ConfigError, "labels must map each control variable"),
    ],
)
def test_bad_mappings_name_what_to_fix(lerobot_root, tmp_path, change, error, match):
    out = tmp_path / "out.hdf5"
    with pytest.raises(error, match=match):
        import_recordings(mapping(**change), lerobot_root, out)
    assert not out.exists()


def test_other_layouts_and_videos_are_refused(lerobot_root, tmp_path):
    with pytest.raises(CpmpFileError, match=r"meta/info.json is missing"):
        read_recordings(mapping(), tmp_path)
    root = copy_dataset(lerobot_root, tmp_path)
    _set_info(root, codebase_version="v2.1")
    with pytest.raises(
        CpmpFileError, match=r"codebase_version is v2.1, older than .*convert_dataset_v21_to_v30"
    ):
        read_recordings(mapping(), root)
    _set_info(root, codebase_version="v4.0")
    with pytest.raises(CpmpFileError) as err:
        read_recordings(mapping(), root)
    message = str(err.value)
    assert "codebase_version is v4.0, newer than the layouts cpmp knows" in message
    assert "v3.x, lerobot 0.4.4 - 0.6.1" in message and "convert" not in message
    _set_info(
        root,
        codebase_version="v3.0",
        features={"observation.images.top": {"dtype": "video", "shape": [480, 640, 3]}},
    )
    with pytest.raises(DataError, match=r"column observation.images.top is a video"):
        read_recordings(mapping(features=[{"column": "observation.images.top"}]), root)
    with pytest.raises(ConfigError, match="reads one dataset folder, got 2 inputs"):
        read_recordings(mapping(), [root, lerobot_root])


def test_a_data_file_without_rows_is_named(lerobot_root, tmp_path):
    root = copy_dataset(lerobot_root, tmp_path)
    _rewrite_data(root, lambda table: table.slice(0, 0))
    with pytest.raises(DataError) as err:
        read_recordings(mapping(), root)
    message = str(err.value)
    assert (
        "data/chunk-000/file-000.parquet, data/chunk-000/file-001.parquet have no rows" in message
    )
    assert "lists of lengths" not in message
    (root / "data" / "chunk-000" / "file-001.parquet").unlink()
    with pytest.raises(DataError, match=r"file-000.parquet has no rows \(no frames\)"):
        read_recordings(mapping(), root)


def test_a_nan_names_the_episode_the_frame_and_the_file(lerobot_root, tmp_path):
    root = copy_dataset(lerobot_root, tmp_path)
    path = root / "data" / "chunk-000" / "file-001.parquet"
    table = pq.read_table(path)
    states = table.column("observation.state").to_pylist()
    episodes = table.column("episode_index").to_pylist()
    row = episodes.index(4) + 7  # episode 4, frame 7
    states[row][2] = float("nan")
    index = table.schema.get_field_index("observation.state")
    column = pa.array(states, table.schema.field(index).type)
    pq.write_table(table.set_column(index, "observation.state", column), path)
    with pytest.raises(DataError) as err:
        read_recordings(mapping(), root)
    message = str(err.value)
    assert f"column observation.state is NaN/inf in episode 4 at frame 7 (row {row} of " in message
    assert "data/chunk-000/file-001.parquet" in message and "on_error: skip" in message


def test_a_missing_velocity_says_how_to_derive_it(lerobot_root, episodes):
    features = [{"column": "observation.velocity"}]
    with pytest.raises(DataError) as err:
        read_recordings(mapping(features=features), lerobot_root)
    assert "derive one from the positions: {column: observation.state, derive: velocity}" in str(
        err.value
    )
    features = [
        {"column": "observation.state", "name": "state"},
        {"column": "observation.state", "name": "state", "derive": "velocity", "index": [0]},
    ]
    result = read_recordings(mapping(features=features), lerobot_root)
    demo, e = result.demos[0], episodes[0]
    assert demo.feature_names[-1] == "state.hand_x.vel"
    # central differences of the smooth reach (up to 0.6 m/s), away from its end where the
    # smoothstep's curvature jumps: within 3e-3 m/s of the derivative
    h = 1e-6
    truth = (e.hand_x(demo.time + h) - e.hand_x(demo.time - h)) / (2 * h)
    inside = (demo.time > 0.05) & (demo.time < e.t_grasp - 0.05)
    np.testing.assert_allclose(demo.features[inside, -1], truth[inside], atol=3e-3)
