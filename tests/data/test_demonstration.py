"""Tests for cpmp.data.demonstration: Demonstration validation, activations, transitions and the
recording log. ``make_demo`` builds the demonstrations of these tests and of
tests/data/test_datafile.py."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from cpmp.data.demonstration import Demonstration, DemonstrationLog, mp_sequences
from cpmp.errors import CpmpError, DataError, UnknownMPError


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


def test_complex_features_or_time_are_refused() -> None:
    demo = make_demo()
    with pytest.raises(DataError, match="features must be real numbers, got complex"):
        make_demo(features=demo.features + 1j)
    with pytest.raises(DataError, match="time must be real seconds"):
        make_demo(time=demo.time + 0j)


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


def test_segments_unknown_variable() -> None:
    with pytest.raises(UnknownMPError, match=r"unknown control variable 'nope'.*left, right"):
        make_demo().segments("nope")


def test_the_record_module_is_apart_from_the_file_format() -> None:
    """The record's module imports no h5py, and the file functions are :mod:`cpmp.data.datafile`'s
    alone (the package :mod:`cpmp.data` shows both)."""
    import ast

    import cpmp.data
    import cpmp.data.demonstration as record

    tree = ast.parse(Path(record.__file__).read_text(encoding="utf-8"))
    imported = {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    imported |= {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module}
    assert not any(m.split(".")[0] == "h5py" for m in imported)
    assert not hasattr(record, "load_demonstrations")
    assert cpmp.data.load_demonstrations is cpmp.data.datafile.load_demonstrations


def test_no_mp_name_prefix_is_reserved() -> None:
    """``start:<mp>`` named the sequencer's start heads until they were removed (issue #32);
    an MP may now be called so."""
    labels = {"v": ["start:a_go", "start:a_go", "b"]}
    demo = Demonstration([0.0, 1.0, 2.0], np.zeros((3, 1)), labels, name="demo_0")
    assert [s.mp for s in demo.segments("v")] == ["start:a_go", "b"]
