"""LeRobot v3 datasets of synthetic demonstrations (cpmp.benchmarks.lerobot_data): the layout's
metadata agrees with the frames, the import mapping reads the demonstrations back with their own
names, labels and (float32) features, and what cannot be stored at a fixed fps is refused."""

from __future__ import annotations

import json

import numpy as np
import pyarrow.parquet as pq
import pytest

from cpmp.benchmarks.lerobot_data import (
    import_mapping,
    write_demonstrations,
    write_import_mapping,
    write_lerobot_v3,
)
from cpmp.data import Demonstration, load_demonstrations
from cpmp.errors import DataError
from cpmp.importers import SplitSpec, import_recordings, load_mapping, read_lerobot
from cpmp.worlds.registry import make_world


@pytest.fixture(scope="module")
def demos() -> list[Demonstration]:
    return make_world("two_point", {}).demonstrations(3, 0)


def test_the_layout_has_several_episodes_per_file_and_consistent_metadata(tmp_path, demos):
    root = write_demonstrations(tmp_path / "ds", demos, episodes_per_file=2)
    info = json.loads((root / "meta" / "info.json").read_text())
    assert info["codebase_version"] == "v3.0" and info["fps"] == 100
    assert info["total_episodes"] == 3
    assert info["total_frames"] == sum(d.n_samples for d in demos)
    state = info["features"]["observation.state"]
    assert state == {"dtype": "float32", "shape": [3], "names": demos[0].feature_names}
    assert info["features"]["a_mp"]["dtype"] == "string"
    files = sorted(p.relative_to(root).as_posix() for p in root.glob("data/*/*.parquet"))
    assert files == ["data/chunk-000/file-000.parquet", "data/chunk-000/file-001.parquet"]
    frames = [pq.read_table(root / f) for f in files]
    assert [sorted(set(t.column("episode_index").to_pylist())) for t in frames] == [[0, 1], [2]]
    episodes = pq.read_table(root / "meta" / "episodes" / "chunk-000" / "file-000.parquet")
    for e in episodes.to_pylist():
        table = frames[e["data/file_index"]]
        rows = np.flatnonzero(table.column("episode_index").to_numpy() == e["episode_index"])
        index = table.column("index").to_numpy()[rows]
        assert e["length"] == len(rows) == demos[e["episode_index"]].n_samples
        np.testing.assert_array_equal(
            index, np.arange(e["dataset_from_index"], e["dataset_to_index"])
        )
        stamps = table.column("timestamp").to_numpy()[rows]
        np.testing.assert_array_equal(stamps, (np.arange(len(rows)) / 100).astype(np.float32))
    tasks = pq.read_table(root / "meta" / "tasks.parquet")
    assert tasks.column("task").to_pylist() == ["Perform the task"]
    assert not (root / "meta" / "subtasks.parquet").exists()


def test_the_mapping_reads_the_demonstrations_back(tmp_path, demos):
    root = write_demonstrations(tmp_path / "ds", demos, episodes_per_file=2)
    mapping = write_import_mapping(tmp_path / "mapping.yaml", import_mapping(demos))
    back = [d.demo for d in read_lerobot(root, load_mapping(mapping))]
    out = tmp_path / "demos.hdf5"
    import_recordings(str(mapping), [str(root)], out, SplitSpec())  # what cpmp-import calls
    for imported in (back, load_demonstrations(out)):
        assert [d.name for d in imported] == [d.name for d in demos]
        for got, want in zip(imported, demos, strict=True):
            assert got.feature_names == want.feature_names
            assert got.variables == want.variables
            # float32 storage: exactly the float32 rounding of the world's features
            np.testing.assert_array_equal(got.features, want.features.astype(np.float32))
            for v in want.variables:
                np.testing.assert_array_equal(got.labels[v], want.labels[v])
            np.testing.assert_allclose(got.time, want.time - want.time[0], atol=1e-6)


def test_demonstrations_off_a_fixed_fps_or_of_two_layouts_are_refused(tmp_path, demos):
    d = demos[0]
    jittered = Demonstration(
        time=d.time + np.where(np.arange(d.n_samples) % 2, 0.003, 0.0),
        features=d.features,
        labels=d.labels,
        feature_names=d.feature_names,
        name="demo_jitter",
    )
    with pytest.raises(DataError, match=r"demo_jitter.*resample"):
        write_demonstrations(tmp_path / "a", [d, jittered])
    renamed = Demonstration(
        time=d.time, features=d.features, labels=d.labels, feature_names=["x", "y", "z"]
    )
    with pytest.raises(DataError, match="one state layout"):
        write_demonstrations(tmp_path / "b", [d, renamed])
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()


def test_the_writer_refuses_mismatched_columns(tmp_path):
    good = {"observation.state": np.zeros((3, 2), np.float32), "x_mp": np.array(["a"] * 3)}
    with pytest.raises(ValueError, match="episode 1 has columns"):
        write_lerobot_v3(
            tmp_path / "a", [good, {"observation.state": good["observation.state"]}], fps=10
        )
    short = {"observation.state": np.zeros((3, 2), np.float32), "x_mp": np.array(["a"] * 2)}
    with pytest.raises(ValueError, match="all equal"):
        write_lerobot_v3(tmp_path / "b", [short], fps=10)
    wide = {"observation.state": np.zeros((3, 4), np.float32), "x_mp": good["x_mp"]}
    with pytest.raises(ValueError, match=r"column observation\.state"):
        write_lerobot_v3(tmp_path / "c", [good, wide], fps=10)
    with pytest.raises(ValueError, match="do not give them"):
        write_lerobot_v3(tmp_path / "d", [{**good, "timestamp": np.zeros(3)}], fps=10)
