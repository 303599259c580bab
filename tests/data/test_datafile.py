"""Tests for cpmp.data.datafile, the HDF5 file format of demonstrations: round trip, layout, splits,
atomic saves, refused input and refused files, and the examples of docs/data_format.md."""

from __future__ import annotations

import json
import re
from collections.abc import Callable
from dataclasses import replace
from operator import delitem, setitem
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pytest
from test_demonstration import make_demo

from cpmp.data.datafile import list_splits, load_demonstrations, save_demonstrations
from cpmp.data.demonstration import Demonstration
from cpmp.errors import CpmpFileError, DataError

DOC = Path(__file__).resolve().parents[2] / "docs" / "data_format.md"


def assert_same(a: Demonstration, b: Demonstration) -> None:
    assert a.name == b.name
    assert a.time.dtype == b.time.dtype == np.float64
    assert a.features.dtype == b.features.dtype == np.float64
    assert np.array_equal(a.time, b.time)
    assert np.array_equal(a.features, b.features)
    assert a.feature_names == b.feature_names
    assert a.variables == b.variables
    for v in a.variables:
        assert a.labels[v].tolist() == b.labels[v].tolist()
    assert a.metadata == b.metadata


# --- round trip ---------------------------------------------------------------------------


def test_round_trip_bit_exact_with_splits_and_metadata(tmp_path: Path) -> None:
    demos = [
        make_demo(seed=0, metadata={"box_size": 0.1 + 0.2, "strategy": "right", "ok": True}),
        make_demo(seed=1, n=20, name="demo_big", metadata={"count": 3, "note": None}),
        make_demo(seed=2, n=7),
    ]
    path = tmp_path / "demos.hdf5"
    save_demonstrations(path, demos, splits={"train": [0, "demo_big"], "test": [2]})

    assert list_splits(path) == {"train": ["demo_0", "demo_big"], "test": ["demo_2"]}
    loaded = load_demonstrations(path)
    assert [d.name for d in loaded] == ["demo_0", "demo_2", "demo_big"]
    expected = {"demo_0": demos[0], "demo_big": demos[1], "demo_2": demos[2]}
    for demo in loaded:
        assert_same(replace(expected[demo.name], name=demo.name), demo)
    assert loaded[0].metadata["box_size"] == 0.1 + 0.2


def test_file_layout(tmp_path: Path) -> None:
    path = tmp_path / "demos.hdf5"
    save_demonstrations(path, [make_demo(metadata={"a": 1})], splits={"train": [0]})
    with h5py.File(path, "r") as f:
        data = f["data"]
        assert data.attrs["format"] == "cpmp-demonstrations"
        assert data.attrs["format_version"] == 1
        assert list(data.attrs["feature_names"]) == ["x0", "x1", "x2"]
        assert list(data.attrs["variables"]) == ["left", "right"]
        catalogue = json.loads(data.attrs["mp_catalogue"])
        assert catalogue == {"left": ["hold", "reach"], "right": ["grasp", "lift", "reach"]}
        group = data["demo_0"]
        assert group.attrs["num_samples"] == 12
        assert group.attrs["name"] == "demo_0"
        assert json.loads(group.attrs["metadata"]) == {"a": 1}
        assert group["labels/right"].dtype == np.int32
        assert group["labels/right"][()].tolist() == [2] * 4 + [0] * 4 + [1] * 4
        assert group["features"].shape == (12, 3)
        assert [bytes(x) for x in f["mask/train"][()]] == [b"demo_0"]


def test_load_split(tmp_path: Path) -> None:
    path = tmp_path / "demos.hdf5"
    demos = [make_demo(seed=i) for i in range(4)]
    save_demonstrations(path, demos, splits={"train": [3, 1], "test": ["demo_0"], "none": []})
    train = load_demonstrations(path, split="train")
    assert [d.name for d in train] == ["demo_1", "demo_3"]
    assert np.array_equal(train[1].features, demos[3].features)
    assert [d.name for d in load_demonstrations(path, split="test")] == ["demo_0"]
    assert load_demonstrations(path, split="none") == []


def test_unknown_split_lists_available(tmp_path: Path) -> None:
    path = tmp_path / "demos.hdf5"
    save_demonstrations(path, [make_demo()], splits={"train": [0], "test": []})
    with pytest.raises(DataError, match=r"no split 'val'; available splits: test, train"):
        load_demonstrations(path, split="val")


def test_split_without_masks(tmp_path: Path) -> None:
    path = tmp_path / "demos.hdf5"
    save_demonstrations(path, [make_demo()])
    assert list_splits(path) == {}
    with pytest.raises(DataError, match=r"available splits: none"):
        load_demonstrations(path, split="train")


def test_natural_sort_order(tmp_path: Path) -> None:
    names = ["demo_10", "demo_2", "demo_1", "demo_b", "demo_a"]
    demos = [make_demo(seed=i, name=name) for i, name in enumerate(names)]
    path = tmp_path / "demos.hdf5"
    save_demonstrations(path, demos)
    loaded = [d.name for d in load_demonstrations(path)]
    assert loaded == ["demo_1", "demo_2", "demo_10", "demo_a", "demo_b"]


def test_default_names_keep_save_order_beyond_ten(tmp_path: Path) -> None:
    demos = [make_demo(seed=i) for i in range(12)]
    path = tmp_path / "demos.hdf5"
    save_demonstrations(path, demos)
    loaded = load_demonstrations(path)
    assert [d.name for d in loaded] == [f"demo_{i}" for i in range(12)]
    for original, demo in zip(demos, loaded, strict=True):
        assert np.array_equal(original.features, demo.features)


def test_round_trip_unicode_and_mixed_case_mp_names(tmp_path: Path) -> None:
    labels = ["Zeta", "alpha", "Ärm", "beta", "alpha"]
    demo = Demonstration(np.arange(5.0), np.zeros((5, 1)), {"v": labels}, name="demo_u")
    path = tmp_path / "demos.hdf5"
    save_demonstrations(path, [demo])
    assert load_demonstrations(path)[0].labels["v"].tolist() == labels


# --- save errors --------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("demos", "splits", "pattern"),
    [
        ([], None, r"no demonstrations"),
        ([make_demo(), make_demo(feature_names=["a", "b", "c"])], None, r"demo_1: feature_names"),
        (
            [make_demo(), make_demo(labels={"right": ["r"] * 12})],
            None,
            r"demo_1: control variables \['right'\] differ",
        ),
        ([make_demo(name="demo_x"), make_demo(name="demo_x")], None, r"share this name"),
        ([make_demo(), make_demo(name="demo_0")], None, r"share this name"),
        ([make_demo(name="cheese")], None, r"cheese: cannot be stored.*rename"),
        ([make_demo(name="demo_a/b")], None, r"cannot be stored"),
        ([make_demo()], {"train": [1]}, r"index 1 is out of range"),
        ([make_demo()], {"train": ["demo_9"]}, r"'demo_9' is neither"),
        ([make_demo()], {"train": [0, "demo_0"]}, r"more than once"),
        ([make_demo()], {"a/b": [0]}, r"split name 'a/b' is invalid"),
        ([make_demo()], {"train": "demo_0"}, r"must be a list"),
        (["not a demo"], None, r"expected Demonstration"),
    ],
)
def test_save_rejects_bad_input(
    tmp_path: Path, demos: list[Any], splits: dict[str, Any] | None, pattern: str
) -> None:
    path = tmp_path / "demos.hdf5"
    with pytest.raises(DataError, match=pattern):
        save_demonstrations(path, demos, splits=splits)
    assert list(tmp_path.iterdir()) == []


def test_failed_save_revalidates_and_keeps_old_file(tmp_path: Path) -> None:
    path = tmp_path / "demos.hdf5"
    save_demonstrations(path, [make_demo(seed=0)])
    before = path.read_bytes()
    broken = make_demo(seed=1)
    broken.features[3, 1] = np.inf
    with pytest.raises(DataError, match=r"demonstration: features is NaN/inf at sample 3"):
        save_demonstrations(path, [make_demo(seed=2), broken])
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["demos.hdf5"]


def test_failed_write_midway_leaves_no_file(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    calls = {"n": 0}
    original = h5py.Group.create_dataset

    def failing(self: h5py.Group, name: str, *args: Any, **kwargs: Any) -> Any:
        calls["n"] += 1
        if calls["n"] > 3:
            raise OSError("disk full")
        return original(self, name, *args, **kwargs)

    monkeypatch.setattr(h5py.Group, "create_dataset", failing)
    path = tmp_path / "demos.hdf5"
    with pytest.raises(CpmpFileError, match=r"could not write.*disk full"):
        save_demonstrations(path, [make_demo(seed=0), make_demo(seed=1)])
    assert calls["n"] == 4
    assert list(tmp_path.iterdir()) == []


def test_failed_write_midway_keeps_old_file(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = tmp_path / "demos.hdf5"
    save_demonstrations(path, [make_demo(seed=0)])
    before = path.read_bytes()

    def failing(self: h5py.Group, name: str, *args: Any, **kwargs: Any) -> Any:
        raise OSError("disk full")

    monkeypatch.setattr(h5py.Group, "create_dataset", failing)
    with pytest.raises(CpmpFileError):
        save_demonstrations(path, [make_demo(seed=5)])
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["demos.hdf5"]


def test_save_into_missing_directory(tmp_path: Path) -> None:
    with pytest.raises(CpmpFileError, match=r"does not exist"):
        save_demonstrations(tmp_path / "nope" / "demos.hdf5", [make_demo()])


# --- load errors --------------------------------------------------------------------------


def write_valid(path: Path) -> None:
    save_demonstrations(path, [make_demo(seed=0), make_demo(seed=1)], splits={"train": [0]})


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(CpmpFileError, match=r"no such file"):
        load_demonstrations(tmp_path / "missing.hdf5")
    with pytest.raises(CpmpFileError, match=r"no such file"):
        list_splits(tmp_path / "missing.hdf5")


def test_directory_is_not_a_file(tmp_path: Path) -> None:
    with pytest.raises(CpmpFileError, match=r"is not a file"):
        load_demonstrations(tmp_path)


def test_not_hdf5(tmp_path: Path) -> None:
    path = tmp_path / "demos.hdf5"
    path.write_text("time,feature\n0,1\n")
    with pytest.raises(CpmpFileError, match=r"is not an HDF5 file"):
        load_demonstrations(path)


def test_truncated_hdf5(tmp_path: Path) -> None:
    path = tmp_path / "demos.hdf5"
    write_valid(path)
    path.write_bytes(path.read_bytes()[:600])
    with pytest.raises(CpmpFileError):
        load_demonstrations(path)


def _broken(
    edit: Callable[[h5py.File], Any],
    error: type[Exception],
    pattern: str,
    name: str,
    split: str | None = None,
) -> Any:
    """A case of :func:`test_load_refuses_a_broken_file`: ``edit`` breaks a valid file, and
    loading ``split`` of it raises ``error`` matching ``pattern``."""
    return pytest.param(edit, split, error, pattern, id=name)


BROKEN_FILES = [
    # (each edits write_valid's file: demo_0 (in mask/train) and demo_1; left has 2 MPs, right 3)
    _broken(lambda f: delitem(f, "data"), CpmpFileError, r"has no /data group", name="no-data"),
    _broken(
        lambda f: setitem(f["data"].attrs, "format", "robomimic"),
        CpmpFileError,
        r"format is 'robomimic'",
        name="format",
    ),
    _broken(
        lambda f: setitem(f["data"].attrs, "format_version", 2),
        CpmpFileError,
        r"format_version 2 is not supported",
        name="version",
    ),
    _broken(
        lambda f: delitem(f["data"].attrs, "variables"),
        CpmpFileError,
        r"missing the 'variables' attribute",
        name="no-variables",
    ),
    _broken(
        lambda f: setitem(f["data"].attrs, "mp_catalogue", "{not json"),
        CpmpFileError,
        r"mp_catalogue is not valid JSON",
        name="catalogue-json",
    ),
    _broken(
        lambda f: setitem(f["data"].attrs, "mp_catalogue", json.dumps({"right": ["a"]})),
        CpmpFileError,
        r"one key per variable",
        name="catalogue-keys",
    ),
    _broken(
        lambda f: setitem(
            f["data"].attrs, "mp_catalogue", json.dumps({"right": ["a"], "left": [""]})
        ),
        CpmpFileError,
        r"non-empty MP names",
        name="catalogue-empty-name",
    ),
    _broken(
        lambda f: setitem(f["data/demo_1/labels/left"], 5, 2),  # the first id past the catalogue
        DataError,
        r"demo_1: labels/left has MP id 2 at step 5.*ids 0..1",
        name="label-id-too-big",
    ),
    _broken(
        lambda f: setitem(f["data/demo_0/labels/right"], 0, -1),
        DataError,
        r"MP id -1 at step 0",
        name="label-id-negative",
    ),
    _broken(
        lambda f: delitem(f, "data/demo_0/labels/left"),
        CpmpFileError,
        r"demo_0/labels has \['right'\]",
        name="label-missing",
    ),
    _broken(
        lambda f: setitem(f["data/demo_1/time"], 3, np.nan),
        DataError,
        r"^demo_1: time is NaN/inf at sample 3",
        name="stored-demo-invalid",
    ),
    _broken(
        lambda f: setitem(f["data/demo_0"].attrs, "num_samples", 99),
        DataError,
        r"num_samples attribute is 99",
        name="num-samples",
    ),
    _broken(
        lambda f: f.create_dataset("mask/test", data=np.array([b"demo_7"])),
        DataError,
        r"mask/test lists demo_7 which is not in /data",
        split="test",
        name="mask-names-missing-demo",
    ),
]


@pytest.mark.parametrize(("edit", "split", "error", "pattern"), BROKEN_FILES)
def test_load_refuses_a_broken_file(
    tmp_path: Path,
    edit: Callable[[h5py.File], Any],
    split: str | None,
    error: type[Exception],
    pattern: str,
) -> None:
    path = tmp_path / "demos.hdf5"
    write_valid(path)
    with h5py.File(path, "a") as f:
        edit(f)
    with pytest.raises(error, match=pattern):
        load_demonstrations(path, split=split)


def test_str_mask_and_extra_groups_are_accepted(tmp_path: Path) -> None:
    path = tmp_path / "demos.hdf5"
    write_valid(path)
    with h5py.File(path, "a") as f:
        f.create_dataset("mask/val", data=["demo_1"], dtype=h5py.string_dtype())
        f.create_group("data/raw_recording")
    assert list_splits(path)["val"] == ["demo_1"]
    assert [d.name for d in load_demonstrations(path, split="val")] == ["demo_1"]
    assert len(load_demonstrations(path)) == 2


# --- docs ---------------------------------------------------------------------------------


def test_doc_snippets_run(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The hand-written file and the API example in docs/data_format.md work as documented."""
    blocks = re.findall(r"```python\n(.*?)```", DOC.read_text(encoding="utf-8"), re.DOTALL)
    assert len(blocks) == 2
    monkeypatch.chdir(tmp_path)
    namespace: dict[str, Any] = {}
    exec(blocks[0], namespace)
    (demo,) = load_demonstrations("my_robot.hdf5", split="train")
    assert demo.metadata == {"box_size": 0.3, "strategy": "right"}
    assert [s.mp for s in demo.segments("right_hand")] == ["reach", "grasp"]
    assert demo.labels["left_hand"].tolist() == ["hold"] * 201
    exec(blocks[1], namespace)
    assert namespace["demo"].switch_indices("right_hand").tolist() == [100]
    assert [d.name for d in namespace["train"]] == ["demo_0"]


def test_names_with_a_trailing_newline_are_refused(tmp_path: Path) -> None:
    with pytest.raises(DataError, match="cannot be stored as an HDF5 group"):
        save_demonstrations(tmp_path / "a.h5", [make_demo(name="demo_1\n")])
    with pytest.raises(DataError, match="split name"):
        save_demonstrations(tmp_path / "a.h5", [make_demo()], splits={"train\n": [0]})
