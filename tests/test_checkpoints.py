"""Checkpoints are validated against their own spec; non-finite options are reported where
they enter."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from cpmp.config import predictor_config
from cpmp.errors import ConfigError, CpmpFileError
from cpmp.sequencer import ConcurrentSequencer


@pytest.fixture(scope="module")
def payload(fitted_klr, tmp_path_factory):
    path = fitted_klr.save(tmp_path_factory.mktemp("ckpt") / "m.pt")
    return torch.load(path, weights_only=True)


def _corrupt(payload, how):
    p = {**payload, "predictor": {**payload["predictor"]}}
    state = dict(p["predictor"]["state"])
    p["predictor"]["state"] = state
    if how == "nan_weights":
        state["weight"] = state["weight"].clone().fill_(float("nan"))
    elif how == "missing_key":
        del state["bias"]
    elif how == "extra_key":
        state["surprise"] = torch.zeros(2)
    elif how == "wrong_shape":
        state["weight"] = state["weight"][:, :2].clone()
    elif how == "extra_option":
        p["sequencer"] = {**p["sequencer"], "warp_drive": True}
    elif how == "bad_option":
        p["sequencer"] = {**p["sequencer"], "threshold": float("nan")}
    elif how == "no_graphs":
        del p["graphs"]
    elif how == "bad_range":
        p["feature_range"] = [1.0]
    return p


@pytest.mark.parametrize(
    ("how", "message"),
    [
        ("nan_weights", "non-finite predictor parameters: weight"),
        ("missing_key", "missing bias"),
        ("extra_key", "unexpected surprise"),
        ("wrong_shape", "weight has shape"),
        ("extra_option", "unknown sequencer options \\['warp_drive'\\]"),
        ("bad_option", "threshold"),
        ("no_graphs", "missing entries \\['graphs'\\]"),
        ("bad_range", "feature_range"),
    ],
)
def test_corrupt_checkpoints_are_file_errors(payload, tmp_path, how, message):
    path = tmp_path / f"{how}.pt"
    torch.save(_corrupt(payload, how), path)
    with pytest.raises(CpmpFileError, match=message):
        ConcurrentSequencer.load(path)


def test_intact_checkpoint_still_loads(payload, tmp_path, fitted_klr, test_demos):
    path = tmp_path / "ok.pt"
    torch.save(payload, path)
    x = test_demos[0].features[:5]
    assert np.array_equal(ConcurrentSequencer.load(path).progress(x), fitted_klr.progress(x))


@pytest.mark.parametrize(
    ("kind", "option", "value"),
    [
        ("klr", "gamma", float("inf")),
        ("klr", "l2", float("nan")),
        ("klr", "support_scale", float("nan")),
        ("klr", "max_support", 4.5),
        ("klr", "min_support", "3"),
        ("klr", "weight_floor", float("-inf")),
        ("mlp", "lr", float("nan")),
        ("mlp", "epochs", 10.5),
        ("klr_sparse", "l1", float("inf")),
    ],
)
def test_non_finite_or_fractional_predictor_options_are_config_errors(kind, option, value):
    with pytest.raises(ConfigError, match=option):
        predictor_config(kind, **{option: value})


def test_whole_number_floats_are_accepted_as_counts():
    assert predictor_config("klr", min_support=4.0).min_support == 4
