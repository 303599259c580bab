"""The checks on what the sequencers are given (cpmp.sequencer.inputs): each mistake a DataError
that says what is wrong."""

import numpy as np
import pytest
import torch

from cpmp.data.demonstration import Demonstration
from cpmp.errors import DataError
from cpmp.sequencer.inputs import checked_demonstrations, checked_features, checked_time


def test_checked_time():
    assert checked_time(np.float32(0.5)) == 0.5 and type(checked_time(1)) is float
    for bad in (float("nan"), float("inf")):
        with pytest.raises(DataError, match="time must be finite"):
            checked_time(bad)


def test_checked_features_converts_and_names_the_expected_width():
    x = checked_features(torch.tensor([[1.0, 2.0]], dtype=torch.float32), ["a", "b"])
    assert x.dtype == np.float64 and x.tolist() == [[1.0, 2.0]]
    with pytest.raises(DataError, match=r"2 entries \(a, b, \.\.\.\), got shape \(3,\)"):
        checked_features(np.zeros(3), ["a", "b"])
    with pytest.raises(DataError, match="got shape \\(\\)"):
        checked_features(np.float64(1.0), ["a"])
    with pytest.raises(DataError, match="NaN or inf"):
        checked_features([0.0, np.inf], ["a", "b"])


def _demo(names, name):
    return Demonstration(
        np.arange(3) * 0.1, np.zeros((3, len(names))), {"v": np.array(["A"] * 3)}, names, name
    )


def test_checked_demonstrations():
    demos, names = checked_demonstrations(iter([_demo(["a"], "d0"), _demo(["a"], "d1")]), "F")
    assert [d.name for d in demos] == ["d0", "d1"] and names == ["a"]
    with pytest.raises(DataError, match=r"^F needs at least one demonstration, got none$"):
        checked_demonstrations([], "F")
    with pytest.raises(DataError, match=r"d1 has features \['b'\] but .* \['a'\]; all must match"):
        checked_demonstrations([_demo(["a"], "d0"), _demo(["b"], "d1")], "F")
