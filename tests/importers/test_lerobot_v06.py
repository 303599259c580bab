"""lerobot 0.6 datasets (written with pyarrow in lerobot 0.6.1's exact schema): subtasks and
motions from ``language_persistent``, SARM annotations from ``meta/episodes``, and an import
that fits and replays."""

import copy
import shutil

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from conftest import EXPECTED, LEROBOT_06_MAPPING, fit_and_replay

from cpmp.data import list_splits, mp_sequences
from cpmp.errors import ConfigError, DataError
from cpmp.importers import SplitSpec, import_recordings, read_recordings, summary_text

SHORT = {"Reach for the box": "reach", "Grasp the box": "grasp", "Lift the box": "lift"}


def mapping(**changes):
    out = copy.deepcopy(LEROBOT_06_MAPPING)
    out.update(changes)
    return out


def test_language_persistent_subtasks_and_motions_label_each_variable(lerobot_v06_root, episodes):
    result = read_recordings(mapping(), lerobot_v06_root)
    assert [d.name for d in result.demos] == [f"demo_{k}" for k in range(5)]
    for demo, e in zip(result.demos, episodes, strict=True):
        t = np.arange(demo.n_samples) / 30  # the frames' float64 times
        np.testing.assert_array_equal(demo.labels["right_arm"], e.right_mp(t))
        np.testing.assert_array_equal(demo.labels["left_arm"], e.left_mp(t))
        assert mp_sequences(demo) == EXPECTED
    assert not result.notes


def test_a_lerobot_06_dataset_imports_trains_and_replays(lerobot_v06_root, tmp_path):
    out = tmp_path / "v06.hdf5"
    result = import_recordings(mapping(), lerobot_v06_root, out, SplitSpec(test=("demo_4",)))
    assert list_splits(out)["test"] == ["demo_4"]
    assert "* reach [5 activations] -> grasp" in summary_text(result)
    replay = fit_and_replay(out)  # ConcurrentSequencer.fit on mask/train, replay of all five
    assert replay["all_match"] == 1.0, replay["per_demo"]
    assert replay["sequence_match"] == {"left_arm": 1.0, "right_arm": 1.0}


def test_sarm_sparse_annotations_label_a_variable(lerobot_v06_root, episodes):
    labels = {"right_arm": {"sarm": "sparse", "rename": SHORT}}
    result = read_recordings(mapping(labels=labels), lerobot_v06_root)
    for demo, e in zip(result.demos, episodes, strict=True):
        t = np.arange(demo.n_samples) / 30
        np.testing.assert_array_equal(demo.labels["right_arm"], e.right_mp(t))


def test_subtask_index_on_a_06_dataset_says_to_read_language_persistent(lerobot_v06_root):
    with pytest.raises(DataError) as err:
        read_recordings(mapping(labels={"arm": {"column": "subtask_index"}}), lerobot_v06_root)
    message = str(err.value)
    assert "column subtask_index is not in data/chunk-000/file-000.parquet" in message
    assert "lerobot >= 0.6 no longer writes subtask_index" in message
    assert "language: subtask" in message
    with pytest.raises(DataError, match="label the variable with language: subtask"):
        read_recordings(
            mapping(labels={"arm": {"column": "language_persistent"}}), lerobot_v06_root
        )


def test_unannotated_episodes_and_bad_label_mappings_name_the_fix(
    lerobot_v06_root, lerobot_root, tmp_path
):
    with pytest.raises(DataError, match=r"has no such column .* lerobot-annotate"):
        read_recordings(mapping(), lerobot_root)  # a 0.5 dataset: no language_persistent
    with pytest.raises(DataError, match=r"no sparse_subtask_names and .* subtask_annotation"):
        read_recordings(mapping(labels={"arm": {"sarm": "sparse"}}), lerobot_root)
    with pytest.raises(ConfigError, match="give exactly one of column"):
        read_recordings(mapping(labels={"arm": {"column": "x", "language": "subtask"}}), "x")
    with pytest.raises(ConfigError, match="language must be one of subtask, motion, got 'plan'"):
        read_recordings(mapping(labels={"arm": {"language": "plan"}}), lerobot_v06_root)
    root = shutil.copytree(lerobot_v06_root, tmp_path / "dataset")
    path = root / "data" / "chunk-000" / "file-000.parquet"
    table = pq.read_table(path)
    rows = [
        [r for r in frame if not (k == 1 and r["style"] == "motion")]
        for k, frame in zip(
            table.column("episode_index").to_pylist(),
            table.column("language_persistent").to_pylist(),
            strict=True,
        )
    ]
    index = table.schema.get_field_index("language_persistent")
    pq.write_table(table.set_column(index, "language_persistent", pa.array(rows)), path)
    with pytest.raises(DataError) as err:
        read_recordings(mapping(), root)
    message = str(err.value)
    assert "episode 1 has no language_persistent row of style motion" in message
    assert "styles there: plan, subtask, task_aug" in message
    result = read_recordings(mapping(on_error="skip"), root)
    assert [d.name for d in result.demos] == ["demo_0", "demo_2", "demo_3", "demo_4"]
    assert result.skipped[0].demo == "demo_1" and "style motion" in result.skipped[0].reason
