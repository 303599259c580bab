"""robomimic / MimicGen-style HDF5 written with h5py: per-effector subtask termination
signals, the Isaac Lab Mimic layout, per-step label datasets, masks, bad input, and an import
that fits and replays."""

import copy
import shutil

import h5py
import numpy as np
import pytest
from conftest import EXPECTED, MIMICGEN_MAPPING, fit_and_replay

from cpmp.data import list_splits, mp_sequences
from cpmp.errors import ConfigError, CpmpFileError, DataError
from cpmp.importers import SplitSpec, import_recordings, read_recordings, summary_text


def mapping(**changes):
    out = copy.deepcopy(MIMICGEN_MAPPING)
    out.update(changes)
    return out


def copy_file(path, tmp_path):
    return shutil.copy(path, tmp_path / "copy.hdf5")


def test_subtask_signals_label_each_effector(mimicgen_file, episodes):
    result = read_recordings(mapping(), mimicgen_file)
    assert [d.name for d in result.demos] == [f"demo_{k}" for k in range(5)]
    for demo, e in zip(result.demos, episodes, strict=True):
        np.testing.assert_allclose(demo.time, np.arange(demo.n_samples) / 20.0)
        assert demo.feature_names == ["hand_x", "hand_z", "finger", "left_y"]
        t = demo.time
        np.testing.assert_allclose(demo.features[:, 0], e.hand_x(t))
        np.testing.assert_allclose(demo.features[:, 2], 0.04 * (1 - e.gripper(t)))
        # a subtask ends at the first step its signal reads 1: the step where t >= t_grasp
        np.testing.assert_array_equal(demo.labels["right_arm"], e.right_mp(t))
        np.testing.assert_array_equal(demo.labels["left_arm"], e.left_mp(t))
        assert demo.metadata["source"] == "mimicgen"


def test_isaac_lab_mimic_layout_and_label_datasets_and_masks(mimicgen_file, tmp_path, episodes):
    path = copy_file(mimicgen_file, tmp_path)
    with h5py.File(path, "a") as f:  # Isaac Lab Mimic records the signals under obs/
        for name in f["data"]:
            f["data"][name].move("datagen_info", "obs/datagen_info")
    labels = {
        "right_arm": MIMICGEN_MAPPING["labels"]["right_arm"],
        "left_arm": {"dataset": "labels/left_arm"},
    }
    result = read_recordings(mapping(labels=labels, mask="valid"), path)
    (demo,) = result.demos
    assert demo.name == "demo_4"  # mask/valid holds the last demo
    assert mp_sequences(demo) == EXPECTED
    np.testing.assert_array_equal(demo.labels["left_arm"], episodes[4].left_mp(demo.time))
    picked = read_recordings(mapping(demos=["demo_3", "demo_1"]), path)
    assert [d.name for d in picked.demos] == ["demo_1", "demo_3"]
    with pytest.raises(DataError, match=r"looked in datagen_info/subtask_term_signals"):
        read_recordings(mapping(signals="datagen_info/subtask_term_signals"), path)


def test_pose_matrices_flatten_row_major(mimicgen_file, episodes):
    features = [{"key": "datagen_info/eef_pose", "index": [3, 11], "name": "eef"}]
    (demo, *_) = read_recordings(mapping(features=features), mimicgen_file).demos
    assert demo.feature_names == ["eef.0.3", "eef.2.3"]  # the translation column of the 4x4
    np.testing.assert_allclose(demo.features[:, 0], episodes[0].hand_x(demo.time))


def test_import_fits_and_replays_the_labelled_sequences(mimicgen_file, tmp_path):
    out = tmp_path / "mimicgen.hdf5"
    result = import_recordings(mapping(), mimicgen_file, out, SplitSpec(test_fraction=0.4, seed=7))
    assert len(result.splits["test"]) == 2
    again = import_recordings(mapping(), mimicgen_file, tmp_path / "again.hdf5", SplitSpec(0.4, 7))
    assert again.splits == result.splits == list_splits(out)  # the seed fixes the split
    replay = fit_and_replay(out)
    assert replay["all_match"] == 1.0, replay["per_demo"]


def _edit(path, change):
    with h5py.File(path, "a") as f:
        change(f["data"]["demo_2"])


def test_a_missing_signal_is_one_clear_error_and_no_file(mimicgen_file, tmp_path):
    path = copy_file(mimicgen_file, tmp_path)
    _edit(path, lambda g: g["datagen_info/subtask_term_signals"].pop("grasped"))
    out = tmp_path / "out.hdf5"
    with pytest.raises(DataError) as err:
        import_recordings(mapping(), path, out)
    message = str(err.value)
    assert "demo_2: no termination signal grasped for right_arm's subtask 'grasp'" in message
    assert "signals: push_started, reached" in message
    assert "fix the signal name in the mapping" in message
    assert not out.exists()


def test_a_signal_that_never_rises_is_refused(mimicgen_file, tmp_path):
    path = copy_file(mimicgen_file, tmp_path)

    def flatten(g):
        signal = g["datagen_info/subtask_term_signals/reached"]
        signal[...] = 0

    _edit(path, flatten)
    with pytest.raises(DataError, match="demo_2: signal reached never becomes 1, so right_arm"):
        read_recordings(mapping(), path)


def test_subtasks_listed_out_of_order_are_refused(mimicgen_file):
    labels = copy.deepcopy(MIMICGEN_MAPPING["labels"])
    labels["right_arm"]["subtasks"] = [
        {"mp": "grasp", "signal": "grasped"},
        {"mp": "reach", "signal": "reached"},
        {"mp": "lift"},
    ]
    with pytest.raises(DataError, match=r"subtask 'reach' ends at step .* not after"):
        read_recordings(mapping(labels=labels), mimicgen_file)


@pytest.mark.parametrize(
    ("change", "error", "match"),
    [
        (
            {"features": [{"key": "obs/robot0_eef_vel"}]},
            DataError,
            r"demo_0 has no dataset obs/robot0_eef_vel; obs/ holds obs/agentview_image, "
            r"obs/robot0_eef_pos",
        ),
        (
            {"features": [{"key": "obs/agentview_image"}]},
            DataError,
            r"obs/agentview_image has shape \(\d+, 8, 8, 3\) \(uint8\), which looks like images",
        ),
        (
            {"labels": {"left_arm": {"subtasks": [{"mp": "hold", "signal": "push_started"}]}}},
            ConfigError,
            r"the last subtask \('hold'\) runs to the end of the demo; remove its signal",
        ),
        (
            {"labels": {"left_arm": {"subtasks": [{"mp": "hold"}, {"mp": "push"}]}}},
            ConfigError,
            r"subtask 0 \('hold'\) has no signal",
        ),
        ({"mask": "test"}, DataError, r"has no mask/test; masks in the file: train, valid"),
        ({"demos": ["demo_9"]}, DataError, r"demo_9 is not in /data"),
        ({"rate": None}, ConfigError, r"rate \[Hz\] must be a finite number"),
    ],
)
def test_bad_mappings_name_what_to_fix(mimicgen_file, tmp_path, change, error, match):
    out = tmp_path / "out.hdf5"
    with pytest.raises(error, match=match):
        import_recordings(mapping(**change), mimicgen_file, out)
    assert not out.exists()


def test_not_a_robomimic_file_is_a_file_error(tmp_path):
    with pytest.raises(CpmpFileError, match="does not exist"):
        read_recordings(mapping(), tmp_path / "missing.hdf5")
    (tmp_path / "text.hdf5").write_text("not hdf5")
    with pytest.raises(CpmpFileError, match=r"cannot open .* as HDF5"):
        read_recordings(mapping(), tmp_path / "text.hdf5")
    with h5py.File(tmp_path / "empty.hdf5", "w") as f:
        f.create_group("demos")
    with pytest.raises(CpmpFileError, match=r"has no /data group; robomimic files keep"):
        read_recordings(mapping(), tmp_path / "empty.hdf5")


def test_a_chattering_signal_switches_at_its_first_rise_with_a_note(mimicgen_file, tmp_path):
    path = copy_file(mimicgen_file, tmp_path)
    with h5py.File(path, "a") as f:  # reached: 1 four steps (0.2 s) early, then 0 again
        signal = f["data/demo_2/datagen_info/subtask_term_signals/reached"]
        values = signal[()]
        settled = int(np.flatnonzero(values)[0])
        values[settled - 4] = 1
        signal[...] = values
    result = read_recordings(mapping(), path)
    demo = result.demos[2]
    first = int(np.flatnonzero(demo.labels["right_arm"] == "grasp")[0])
    assert first == settled - 4  # MimicGen's rule: the first 0 -> 1 step
    (note,) = [n for n in result.notes if n.kind == "chatter"]
    assert note.demo == "demo_2" and note.where == "right_arm"
    assert f"'reach' ends at its first 0 -> 1 step {settled - 4}" in note.text
    assert f"stays 1 only from step {settled}" in note.text
    assert "the switch is 0.200 s earlier than there" in note.text
    assert note.text in summary_text(import_recordings(mapping(), path, tmp_path / "out.hdf5"))


def test_debouncing_notes_how_far_it_moved_a_switch(mimicgen_file, tmp_path, episodes):
    path = copy_file(mimicgen_file, tmp_path)
    with h5py.File(path, "a") as f:  # push, back to hold for 3 steps, then push for good
        labels = f["data/demo_0/labels/left_arm"]
        values = labels[()]
        start = int(np.flatnonzero(values == b"push")[0])
        values[start + 1 : start + 4] = b"hold"
        labels[...] = values
    labels = {"left_arm": {"dataset": "labels/left_arm"}}
    result = read_recordings(mapping(labels=labels, min_activation=0.1, demos=["demo_0"]), path)
    (demo,) = result.demos
    assert int(np.flatnonzero(demo.labels["left_arm"] == "push")[0]) == start + 4
    (moved,) = [n for n in result.notes if n.kind == "switch_moved"]
    assert moved.text == (
        f"left_arm: the switch hold -> push moved from {start / 20:.3f} s (first recorded) to "
        f"{(start + 4) / 20:.3f} s (+0.200 s, min_activation)"
    )


def test_a_missing_velocity_says_how_to_derive_it(mimicgen_file, episodes):
    with pytest.raises(DataError) as err:
        read_recordings(mapping(features=[{"key": "obs/robot0_eef_vel_lin"}]), mimicgen_file)
    assert "{key: obs/robot0_eef_pos, derive: velocity}" in str(err.value)
    features = [{"key": "obs/robot0_eef_pos", "index": [0], "derive": "velocity"}]
    (demo, *_) = read_recordings(mapping(features=features), mimicgen_file).demos
    assert demo.feature_names == ["obs.robot0_eef_pos.0.vel"]
    np.testing.assert_allclose(
        demo.features[:, 0], np.gradient(episodes[0].hand_x(demo.time), demo.time)
    )


def test_a_nan_names_the_demo_the_step_and_the_file(mimicgen_file, tmp_path):
    path = copy_file(mimicgen_file, tmp_path)
    _edit(path, lambda g: g["obs/robot0_eef_pos"].__setitem__((5, 2), np.nan))
    with pytest.raises(DataError) as err:
        read_recordings(mapping(), path)
    message = str(err.value)
    assert f"demo_2: obs/robot0_eef_pos is NaN/inf at step 5 (element 2) in {path}" in message
