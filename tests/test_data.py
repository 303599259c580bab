"""Tests for cpmp.data (Demonstration validation, activations, transitions) and its file
format cpmp.datafile (HDF5 round trip, splits, failure modes); both build on ``make_demo``."""

from __future__ import annotations

import json
import re
from dataclasses import replace
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pytest

import cpmp.data
import cpmp.datafile
from cpmp.data import Demonstration, DemonstrationLog, mp_sequences
from cpmp.datafile import list_splits, load_demonstrations, save_demonstrations
from cpmp.errors import CpmpError, CpmpFileError, DataError, UnknownMPError

DOC = Path(__file__).resolve().parents[1] / "docs" / "data_format.md"


def make_demo(n: int = 12, d: int = 3, seed: int = 0, **kwargs: Any) -> Demonstration:
    """A synthetic demo: two variables, random features, irregular but increasing time."""
    rng = np.random.default_rng(seed)
    time = np.cumsum(rng.uniform(0.01, 0.1, size=n))
    right = ["reach"] * (n // 3) + ["grasp"] * (n // 3) + ["lift"] * (n - 2 * (n // 3))
    left = ["hold"] * (n // 2) + ["reach"] * (n - n // 2)
    args: dict[str, Any] = {
        "time": time,
        "features": rng.normal(size=(n, d)),
        "labels": {"right": right, "left": left},
        "feature_names": [f"x{j}" for j in range(d)],
    }
    args.update(kwargs)
    return Demonstration(**args)


def kwargs_of(demo: Demonstration) -> dict[str, Any]:
    return {
        "time": demo.time,
        "features": demo.features,
        "labels": demo.labels,
        "feature_names": demo.feature_names,
        "name": demo.name,
    }


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


# --- construction -------------------------------------------------------------------------


def test_valid_demo_properties_and_conversion() -> None:
    demo = Demonstration(
        time=[0, 1, 3],
        features=[[1, 2], [3, 4], [5, 6]],
        labels={"b": ["m", "m", "n"], "a": np.array(["p", "q", "q"])},
        metadata={"size": np.float32(0.5), "strategy": "left"},
    )
    assert demo.n_samples == 3
    assert demo.n_features == 2
    assert demo.variables == ["a", "b"]
    assert demo.duration == 3.0
    assert demo.feature_names == ["f0", "f1"]
    assert demo.time.dtype == np.float64
    assert demo.features.dtype == np.float64
    assert demo.labels["b"].tolist() == ["m", "m", "n"]
    assert demo.metadata == {"size": 0.5, "strategy": "left"}
    assert isinstance(demo.metadata["size"], float)


def test_demo_copies_inputs() -> None:
    time = np.array([0.0, 1.0])
    demo = Demonstration(time, np.zeros((2, 1)), {"v": ["a", "b"]})
    time[1] = -5.0
    assert demo.time[1] == 1.0


@pytest.mark.parametrize(
    ("kwargs", "pattern"),
    [
        ({"features": np.zeros((11, 3))}, r"features has 11 rows but time has 12 samples"),
        ({"features": np.zeros(12)}, r"features must be 2-D"),
        ({"features": np.zeros((12, 0))}, r"0 columns"),
        ({"time": np.zeros((12, 1))}, r"time must be 1-D"),
        ({"time": np.r_[np.arange(11.0), np.nan]}, r"time is NaN/inf at sample 11"),
        ({"time": np.r_[np.arange(11.0), np.inf]}, r"time is NaN/inf at sample 11"),
        ({"time": np.r_[np.arange(6.0), 5.0, np.arange(7.0, 12.0)]}, r"not strictly increasing"),
        ({"time": np.r_[np.arange(6.0), 4.0, np.arange(7.0, 12.0)]}, r"at sample 6"),
        ({"time": ["a"] * 12}, r"time must be numeric"),
        ({"labels": {}}, r"label at least one control variable"),
        ({"labels": {"right": ["reach"] * 11}}, r"labels\['right'\] has 11 entries"),
        ({"labels": {"right": ["reach"] * 11 + [None]}}, r"labels\['right'\]\[11\] is None"),
        ({"labels": {"right": ["reach"] * 11 + [""]}}, r"empty at step 11"),
        ({"labels": {"right": ["reach"] * 5 + [" "] * 7}}, r"empty at step 5 \(7 step"),
        ({"labels": {"right": list(range(12))}}, r"labels must be MP names"),
        ({"labels": {"right": "reach"}}, r"must be 1-D"),
        ({"labels": {"a/b": ["reach"] * 12}}, r"without '/'"),
        ({"feature_names": ["a", "b"]}, r"feature_names has 2 entries but features has 3"),
        ({"feature_names": ["a", "b", "a"]}, r"not unique \(a repeated\)"),
        ({"feature_names": ["a", "", "c"]}, r"feature_names\[1\]"),
        ({"feature_names": "abc"}, r"not one string"),
        ({"metadata": {"size": np.zeros(3)}}, r"metadata\['size'\] is a ndarray"),
        ({"metadata": {"size": float("nan")}}, r"finite"),
        ({"metadata": [1, 2]}, r"metadata must be a dict"),
    ],
)
def test_invalid_construction_raises_data_error(kwargs: dict[str, Any], pattern: str) -> None:
    with pytest.raises(DataError, match=pattern) as info:
        make_demo(name="demo_3", **kwargs)
    assert isinstance(info.value, CpmpError)
    assert str(info.value).startswith("demo_3: ")


def test_too_few_samples() -> None:
    with pytest.raises(DataError, match=r"has 1 sample\(s\) but at least 2"):
        Demonstration([0.0], np.zeros((1, 2)), {"v": ["a"]})


def test_features_nan_reports_position_and_fix() -> None:
    demo = make_demo()
    features = demo.features.copy()
    features[4, 2] = np.nan
    with pytest.raises(DataError, match=r"sample 4, column 2.*interpolate"):
        Demonstration(**{**kwargs_of(demo), "features": features})


def test_unnamed_demo_error_says_demonstration() -> None:
    with pytest.raises(DataError, match=r"^demonstration: features has 2 rows but time has 3"):
        Demonstration([0.0, 1.0, 2.0], np.zeros((2, 1)), {"v": ["a"] * 3})


def test_message_gives_the_fix() -> None:
    with pytest.raises(DataError, match=r"give one feature row per time step"):
        make_demo(name="demo_3", features=np.zeros((11, 3)))


# --- segments -----------------------------------------------------------------------------


def test_segments_and_switch_indices() -> None:
    labels = ["a", "a", "b", "b", "b", "a", "c"]
    features = np.arange(14.0).reshape(7, 2)
    demo = Demonstration(np.arange(7.0) / 10, features, {"v": labels, "w": ["z"] * 7})
    segments = demo.segments("v")
    assert [(s.mp, s.start, s.stop, s.demo) for s in segments] == [
        ("a", 0, 2, None),
        ("b", 2, 5, None),
        ("a", 5, 6, None),
        ("c", 6, 7, None),
    ]
    assert [s.n_samples for s in segments] == [2, 3, 1, 1]
    assert np.array_equal(segments[1].features, features[2:5])
    assert np.array_equal(segments[1].time, demo.time[2:5])
    assert demo.switch_indices("v").tolist() == [2, 5, 6]
    assert [(s.mp, s.start, s.stop) for s in demo.segments("w")] == [("z", 0, 7)]
    assert demo.switch_indices("w").tolist() == []
    assert mp_sequences(demo) == {"v": ["a", "b", "a", "c"], "w": ["z"]}


def test_activations_compare_by_position_not_arrays() -> None:
    demo = make_demo()
    a, b = demo.segments("right")[0], make_demo(seed=5).segments("right")[0]
    assert a == b  # same MP and samples; the arrays differ and are not compared
    assert a != demo.segments("right")[1]


def test_transitions_are_the_label_switches_in_time_order() -> None:
    demo = Demonstration(
        np.arange(6.0) * 0.5,
        np.arange(12.0).reshape(6, 2),
        {"u": ["a", "a", "b", "b", "b", "c"], "v": ["x", "x", "x", "y", "y", "y"]},
    )
    events = demo.transitions()
    assert [(e.t, e.variable, e.source, e.target) for e in events] == [
        (1.0, "u", "a", "b"),
        (1.5, "v", "x", "y"),
        (2.5, "u", "b", "c"),
    ]
    assert [e.state.tolist() for e in events] == [[4.0, 5.0], [6.0, 7.0], [10.0, 11.0]]
    assert all(np.isnan(e.probability) and e.kind == "switch" for e in events)
    assert demo.transitions("v") == [events[1]]


def test_transitions_at_equal_times_keep_variable_order() -> None:
    demo = Demonstration(np.arange(3.0), np.zeros((3, 1)), {"b": list("xyy"), "a": list("pqq")})
    assert [e.variable for e in demo.transitions()] == ["a", "b"]


def test_demonstration_log_builds_a_validated_demonstration() -> None:
    log = DemonstrationLog(["u", "v"])
    for k in range(4):
        log.append(0.1 * k, [k, -k], {"u": "a" if k < 2 else "b", "v": "x", "extra": "ignored"})
    demo = log.to_demonstration(["p", "q"], "demo_7", {"k": 1})
    assert demo.name == "demo_7" and demo.metadata == {"k": 1}
    assert demo.feature_names == ["p", "q"]
    assert demo.features.dtype == np.float64 and demo.features[:, 1].tolist() == [0, -1, -2, -3]
    assert mp_sequences(demo) == {"u": ["a", "b"], "v": ["x"]}
    with pytest.raises(DataError, match="at least 2 are needed"):
        DemonstrationLog(["u"]).to_demonstration()


def test_file_functions_importable_from_the_record_module() -> None:
    """The README and docs import save/load/list_splits from cpmp.data; they are datafile's."""
    for name in ("save_demonstrations", "load_demonstrations", "list_splits"):
        assert getattr(cpmp.data, name) is getattr(cpmp.datafile, name)
    with pytest.raises(AttributeError, match="no attribute 'nonexistent'"):
        cpmp.data.nonexistent  # noqa: B018


def test_segments_unknown_variable() -> None:
    with pytest.raises(UnknownMPError, match=r"unknown control variable 'nope'.*left, right"):
        make_demo().segments("nope")


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


def test_missing_data_group(tmp_path: Path) -> None:
    path = tmp_path / "demos.hdf5"
    with h5py.File(path, "w") as f:
        f.create_group("observations")
    with pytest.raises(CpmpFileError, match=r"has no /data group"):
        load_demonstrations(path)


@pytest.mark.parametrize(
    ("attr", "value", "pattern"),
    [
        ("format", "robomimic", r"format is 'robomimic'"),
        ("format_version", 2, r"format_version 2 is not supported"),
        ("mp_catalogue", "{not json", r"mp_catalogue is not valid JSON"),
        ("mp_catalogue", json.dumps({"right": ["a"]}), r"one key per variable"),
        ("mp_catalogue", json.dumps({"right": ["a"], "left": [""]}), r"non-empty MP names"),
    ],
)
def test_bad_header(tmp_path: Path, attr: str, value: Any, pattern: str) -> None:
    path = tmp_path / "demos.hdf5"
    write_valid(path)
    with h5py.File(path, "a") as f:
        f["data"].attrs[attr] = value
    with pytest.raises(CpmpFileError, match=pattern):
        load_demonstrations(path)


def test_missing_header_attribute(tmp_path: Path) -> None:
    path = tmp_path / "demos.hdf5"
    write_valid(path)
    with h5py.File(path, "a") as f:
        del f["data"].attrs["variables"]
    with pytest.raises(CpmpFileError, match=r"missing the 'variables' attribute"):
        load_demonstrations(path)


def test_label_id_out_of_catalogue(tmp_path: Path) -> None:
    path = tmp_path / "demos.hdf5"
    write_valid(path)
    with h5py.File(path, "a") as f:
        f["data/demo_1/labels/left"][5] = 2  # left has 2 MPs: the first invalid id
    with pytest.raises(DataError, match=r"demo_1: labels/left has MP id 2 at step 5.*ids 0..1"):
        load_demonstrations(path)


def test_negative_label_id(tmp_path: Path) -> None:
    path = tmp_path / "demos.hdf5"
    write_valid(path)
    with h5py.File(path, "a") as f:
        f["data/demo_0/labels/right"][0] = -1
    with pytest.raises(DataError, match=r"MP id -1 at step 0"):
        load_demonstrations(path)


def test_missing_label_dataset(tmp_path: Path) -> None:
    path = tmp_path / "demos.hdf5"
    write_valid(path)
    with h5py.File(path, "a") as f:
        del f["data/demo_0/labels/left"]
    with pytest.raises(CpmpFileError, match=r"demo_0/labels has \['right'\]"):
        load_demonstrations(path)


def test_malformed_stored_demo_names_the_demo(tmp_path: Path) -> None:
    path = tmp_path / "demos.hdf5"
    write_valid(path)
    with h5py.File(path, "a") as f:
        f["data/demo_1/time"][3] = np.nan
    with pytest.raises(DataError, match=r"^demo_1: time is NaN/inf at sample 3"):
        load_demonstrations(path)


def test_num_samples_mismatch(tmp_path: Path) -> None:
    path = tmp_path / "demos.hdf5"
    write_valid(path)
    with h5py.File(path, "a") as f:
        f["data/demo_0"].attrs["num_samples"] = 99
    with pytest.raises(DataError, match=r"num_samples attribute is 99"):
        load_demonstrations(path)


def test_mask_naming_missing_demo(tmp_path: Path) -> None:
    path = tmp_path / "demos.hdf5"
    write_valid(path)
    with h5py.File(path, "a") as f:
        f.create_dataset("mask/test", data=np.array([b"demo_7"]))
    with pytest.raises(DataError, match=r"mask/test lists demo_7 which is not in /data"):
        load_demonstrations(path, split="test")


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


def test_complex_features_or_time_are_refused() -> None:
    demo = make_demo()
    with pytest.raises(DataError, match="features must be real numbers, got complex"):
        make_demo(features=demo.features + 1j)
    with pytest.raises(DataError, match="time must be real seconds"):
        make_demo(time=demo.time + 0j)


def test_names_with_a_trailing_newline_are_refused(tmp_path: Path) -> None:
    with pytest.raises(DataError, match="cannot be stored as an HDF5 group"):
        save_demonstrations(tmp_path / "a.h5", [make_demo(name="demo_1\n")])
    with pytest.raises(DataError, match="split name"):
        save_demonstrations(tmp_path / "a.h5", [make_demo()], splits={"train\n": [0]})
