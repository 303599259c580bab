"""Checkpoints: a sequencer's are validated against their own spec and checksum on load, and
:func:`cpmp.evaluation.checkpoints.load_sequencer` reads either kind, telling a file of another
format from a damaged one."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from cpmp.baselines.goal_nearest import GoalNearestSequencer
from cpmp.errors import CpmpFileError
from cpmp.evaluation.checkpoints import load_sequencer
from cpmp.io import CHECKSUM_KEY, payload_digest, save_checkpoint, to_builtin
from cpmp.sequencer.sequencer import ConcurrentSequencer


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
    # signed again: content checks stand behind the checksum (a file written by a faulty writer)
    p[CHECKSUM_KEY] = payload_digest(p)
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


def test_a_version_1_checkpoint_is_refused_as_too_old(payload, tmp_path):
    """Version 1 files (before the switching rules, coupling and recovery) are not upgraded."""
    path = tmp_path / "v1.pt"
    old = {k: v for k, v in payload.items() if k != CHECKSUM_KEY}
    save_checkpoint(path, {**old, "version": 1})
    for load in (ConcurrentSequencer.load, load_sequencer):
        with pytest.raises(CpmpFileError, match=r"version 1, a format too old .* re-fit the model"):
            load(path)


def test_load_sequencer_refuses_other_files_by_name(tmp_path, train_demos):
    import torch

    other = tmp_path / "other.pt"
    torch.save({"format": "something-else", "weights": torch.zeros(2)}, other)
    with pytest.raises(CpmpFileError, match="neither a cpmp sequencer nor a goal_nearest"):
        load_sequencer(other)
    junk = tmp_path / "junk.pt"
    junk.write_bytes(b"not a checkpoint")
    with pytest.raises(CpmpFileError, match="not a readable") as err:
        load_sequencer(junk)
    assert "neither" not in str(err.value)  # a damaged file is not called a format mismatch
    with pytest.raises(CpmpFileError, match="does not exist"):
        load_sequencer(tmp_path / "missing.pt")
    # a damaged checkpoint of a known format keeps its loader's own message
    seq = GoalNearestSequencer.fit(train_demos)
    payload = torch.load(seq.save(tmp_path / "gn.pt"), weights_only=True)
    del payload["entries"]
    torch.save(payload, tmp_path / "gn_damaged.pt")
    with pytest.raises(CpmpFileError, match="damaged goal_nearest checkpoint"):
        load_sequencer(tmp_path / "gn_damaged.pt")
    loaded = load_sequencer(tmp_path / "gn.pt")
    x = train_demos[0].features[:5]
    assert np.array_equal(loaded.progress(x), seq.progress(x))


def test_every_single_bit_flip_is_refused_or_changes_nothing(fitted_klr, tmp_path, test_demos):
    """A sample of single-bit flips over the whole file: each raises a CpmpFileError or loads a
    sequencer with bit-identical progress (a flip in zip metadata torch does not read)."""
    data = fitted_klr.save(tmp_path / "m.pt").read_bytes()
    x = test_demos[0].features
    reference = fitted_klr.progress(x)
    rng = np.random.default_rng(0)
    refused = 0
    for bit in rng.choice(len(data) * 8, size=120, replace=False):
        flipped = bytearray(data)
        flipped[bit // 8] ^= 1 << (bit % 8)
        path = tmp_path / "flipped.pt"
        path.write_bytes(bytes(flipped))
        try:
            loaded = ConcurrentSequencer.load(path)
        except CpmpFileError:
            refused += 1
            continue
        assert np.array_equal(loaded.progress(x), reference), f"bit {bit} changed phi silently"
    assert refused > 60  # most bytes are content: most flips must be caught


def test_a_damaged_format_entry_is_called_damage_not_another_format(payload, tmp_path):
    """A flip inside the format entry leaves a foreign format and a checksum that does not match:
    the file is reported damaged, not as a checkpoint of neither kind."""
    path = tmp_path / "m.pt"
    torch.save({**payload, "format": "cpmp-sequencez"}, path)
    with pytest.raises(CpmpFileError, match="is a damaged checkpoint") as info:
        load_sequencer(path)
    assert "neither" not in str(info.value)


def test_a_checkpoint_with_the_fit_summary_as_a_dict_still_loads(payload, tmp_path, fitted_klr):
    """Checkpoints written before the fit's report was a record hold it as the fit's dict."""
    old_summary = to_builtin(fitted_klr.fit_summary.to_dict())  # as the old code saved it
    old = {k: v for k, v in payload.items() if k != CHECKSUM_KEY}
    path = save_checkpoint(tmp_path / "dict.pt", {**old, "fit_summary": old_summary})
    loaded = ConcurrentSequencer.load(path)
    assert loaded.fit_summary == fitted_klr.fit_summary
    assert loaded.fit_summary.to_dict() == old_summary
    # saved again, the same dict comes back
    again = torch.load(loaded.save(tmp_path / "again.pt"), weights_only=True)
    assert again["fit_summary"] == old_summary
    # older still: before the validation, Newton and branch entries; or without a summary
    older = {
        k: v
        for k, v in old_summary.items()
        if k not in {"val_mae_final", "lr_history", "monitor", "device", "stay_choices"}
        and not k.startswith("newton_")
        and k != "entry_scale"
    }
    path = save_checkpoint(tmp_path / "older.pt", {**old, "fit_summary": older})
    report = ConcurrentSequencer.load(path).fit_summary
    assert (report.loss, report.n_support_total) == (older["loss"], older["n_support_total"])
    assert report.newton is None and report.stay_choices == () and report.entry_scale == {}
    none = {k: v for k, v in old.items() if k != "fit_summary"}
    assert ConcurrentSequencer.load(save_checkpoint(tmp_path / "none.pt", none)).fit_summary is None


def test_a_damaged_fit_summary_is_a_file_error(payload, tmp_path):
    old = {k: v for k, v in payload.items() if k != CHECKSUM_KEY}
    path = save_checkpoint(tmp_path / "bad.pt", {**old, "fit_summary": {"kind": "klr"}})
    with pytest.raises(CpmpFileError, match="not a fit report"):
        ConcurrentSequencer.load(path)


def _with_options(payload, **options):
    old = {k: v for k, v in payload.items() if k != CHECKSUM_KEY}
    return {**old, "sequencer": {**old["sequencer"], **options}}


def test_a_checkpoint_from_before_min_exit_was_removed_loads_as_before(payload, tmp_path):
    """``min_exit`` at 0 (off, its default) did nothing: such a checkpoint loads unchanged."""
    path = tmp_path / "old.pt"
    save_checkpoint(path, _with_options(payload, min_exit=0.0))
    loaded = ConcurrentSequencer.load(path)
    assert not hasattr(loaded.config, "min_exit")
    assert loaded.config == ConcurrentSequencer.load(_saved(payload, tmp_path)).config


def test_a_checkpoint_from_before_start_kernel_was_removed_loads_as_before(payload, tmp_path):
    """``start_kernel: shared`` (its default) read the nodes' own predictors, as every
    sequencer now does: such a checkpoint loads unchanged."""
    path = tmp_path / "old.pt"
    save_checkpoint(path, _with_options(payload, start_kernel="shared"))
    loaded = ConcurrentSequencer.load(path)
    assert not hasattr(loaded.config, "start_kernel")
    now = ConcurrentSequencer.load(_saved(payload, tmp_path))
    assert loaded.config == now.config
    x = np.zeros(len(now.feature_names))
    np.testing.assert_array_equal(loaded.progress(x), now.progress(x))


def _saved(payload, tmp_path):
    path = tmp_path / "now.pt"
    torch.save(payload, path)
    return path


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"min_exit": 0.9}, r"removed sequencer option\(s\) min_exit .*refit the checkpoint"),
        ({"switch_rule": "plateau"}, r"'plateau'.*plateau rule .* was removed .* use peak"),
        (
            {"start_kernel": "isotropic"},
            r"removed sequencer option\(s\) start_kernel .*isotropic start heads .* were "
            r"removed .*refit the checkpoint",
        ),
    ],
)
def test_a_checkpoint_that_used_a_removed_option_is_refused_by_name(
    payload, tmp_path, options, message
):
    path = tmp_path / "used.pt"
    save_checkpoint(path, _with_options(payload, **options))
    with pytest.raises(CpmpFileError, match=message):
        ConcurrentSequencer.load(path)
