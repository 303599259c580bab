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
    with pytest.raises(DataError, match=r"column left_arm_mp is empty \(null\) in 2 frame"):
        import_recordings(mapping(), root, out)
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
        CpmpFileError, match=r"codebase_version is v2.1; .*convert_dataset_v21_to_v30"
    ):
        read_recordings(mapping(), root)
    _set_info(
        root,
        codebase_version="v3.0",
        features={"observation.images.top": {"dtype": "video", "shape": [480, 640, 3]}},
    )
    with pytest.raises(DataError, match=r"column observation.images.top is a video"):
        read_recordings(mapping(features=[{"column": "observation.images.top"}]), root)
    with pytest.raises(ConfigError, match="reads one dataset folder, got 2 inputs"):
        read_recordings(mapping(), [root, lerobot_root])
