"""``on_error: skip``: one bad demonstration no longer refuses the import, for every source.

The good demonstrations are written, each skipped one is reported with its reason (the
summary, ``<output>.skipped.json``); with every demonstration bad it is still an error and no
file; ``raise`` (the default) stays all or nothing.
"""

import copy
import json
import shutil

import h5py
import pytest
from conftest import BAG_MAPPING, LEROBOT_MAPPING, MIMICGEN_MAPPING

from cpmp.data import list_splits
from cpmp.errors import CpmpFileError, DataError
from cpmp.importers import import_recordings, load_mapping, summary_text


def test_a_bad_mimicgen_demo_is_skipped_and_reported(mimicgen_file, tmp_path):
    path = shutil.copy(mimicgen_file, tmp_path / "copy.hdf5")
    with h5py.File(path, "a") as f:
        del f["data/demo_2/datagen_info/subtask_term_signals/grasped"]
    out = tmp_path / "out.hdf5"
    with pytest.raises(DataError, match="demo_2: no termination signal grasped"):
        import_recordings(MIMICGEN_MAPPING, path, out)  # raise: all or nothing
    assert not out.exists() and not (tmp_path / "out.hdf5.skipped.json").exists()
    result = import_recordings({**MIMICGEN_MAPPING, "on_error": "skip"}, path, out)
    assert list_splits(out)["train"] == ["demo_0", "demo_1", "demo_3", "demo_4"]
    (skipped,) = result.skipped
    assert skipped.demo == "demo_2" and skipped.source == f"{path}#demo_2"
    assert skipped.error == "DataError" and "no termination signal grasped" in skipped.reason
    report = json.loads((tmp_path / "out.hdf5.skipped.json").read_text())
    assert result.skipped_path == tmp_path / "out.hdf5.skipped.json"
    assert report["imported"] == ["demo_0", "demo_1", "demo_3", "demo_4"]
    assert report["skipped"] == [skipped.to_dict()]
    text = summary_text(result)
    assert text.startswith("imported 4 demonstration(s), skipped 1 from mimicgen")
    assert f"  demo_2 ({path}#demo_2): demo_2: no termination signal grasped" in text


def test_the_argument_overrides_the_mapping(mimicgen_file, tmp_path):
    path = shutil.copy(mimicgen_file, tmp_path / "copy.hdf5")
    with h5py.File(path, "a") as f:
        f["data/demo_0/obs/robot0_eef_pos"][3, 0] = float("nan")
    mapping = {**MIMICGEN_MAPPING, "on_error": "skip"}
    with pytest.raises(DataError, match="NaN/inf at step 3"):
        import_recordings(mapping, path, tmp_path / "out.hdf5", on_error="raise")
    result = import_recordings(MIMICGEN_MAPPING, path, tmp_path / "out.hdf5", on_error="skip")
    assert [s.demo for s in result.skipped] == ["demo_0"]


def test_every_demo_bad_is_still_an_error_and_no_file(mimicgen_file, tmp_path):
    mapping = copy.deepcopy(MIMICGEN_MAPPING)
    mapping["features"][0]["key"] = "obs/robot0_eef_pos_typo"
    out = tmp_path / "out.hdf5"
    with pytest.raises(DataError) as err:
        import_recordings({**mapping, "on_error": "skip"}, mimicgen_file, out)
    message = str(err.value)
    assert message.startswith("every demonstration failed to import (5 skipped, none left)")
    assert "demo_0: demo_0 has no dataset obs/robot0_eef_pos_typo" in message
    assert not out.exists() and not (tmp_path / "out.hdf5.skipped.json").exists()


def test_a_bad_lerobot_episode_is_skipped(lerobot_root, tmp_path):
    import pyarrow as pa
    import pyarrow.parquet as pq

    root = shutil.copytree(lerobot_root, tmp_path / "dataset")
    path = root / "data" / "chunk-000" / "file-000.parquet"
    table = pq.read_table(path)
    labels = table.column("left_arm_mp").to_pylist()
    labels[table.column("episode_index").to_pylist().index(1) + 3] = None  # episode 1
    index = table.schema.get_field_index("left_arm_mp")
    pq.write_table(table.set_column(index, "left_arm_mp", pa.array(labels, pa.string())), path)
    result = import_recordings({**LEROBOT_MAPPING, "on_error": "skip"}, root, tmp_path / "out.hdf5")
    assert [d.name for d in result.demos] == ["demo_0", "demo_2", "demo_3", "demo_4"]
    (skipped,) = result.skipped
    assert skipped.demo == "demo_1" and skipped.source == f"{root}#episode_1"
    assert "column left_arm_mp is empty (null) in 1 frame(s) of episode 1" in skipped.reason


def test_a_bad_bag_is_skipped(bag_dir, tmp_path):
    bags = shutil.copytree(bag_dir, tmp_path / "bags")
    (db3,) = (bags / "run_2").glob("*.db3")
    db3.write_bytes(b"not a sqlite database" * 10)
    out = tmp_path / "out.hdf5"
    with pytest.raises(CpmpFileError):
        import_recordings(BAG_MAPPING, bags, out)
    assert not out.exists()
    spec = load_mapping({**BAG_MAPPING, "on_error": "skip"})
    result = import_recordings(spec, bags, out)
    assert [d.name for d in result.demos] == [f"demo_run_{k}" for k in (0, 1, 3, 4)]
    (skipped,) = result.skipped
    assert skipped.demo == "demo_run_2" and skipped.source == str(bags / "run_2")
    assert skipped.error == "CpmpFileError" and "run_2" in skipped.reason
    assert json.loads(result.skipped_path.read_text())["skipped"][0]["demo"] == "demo_run_2"
