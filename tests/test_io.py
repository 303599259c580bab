import os
import stat

import pytest
import torch

from cpmp.errors import CheckpointFormatError, CpmpFileError
from cpmp.io import (
    CHECKSUM_KEY,
    CheckpointSpec,
    atomic_path,
    atomic_write_text,
    load_checkpoint,
    payload_digest,
    save_checkpoint,
)


def test_atomic_write_replaces_and_keeps_normal_mode(tmp_path):
    target = tmp_path / "a.txt"
    atomic_write_text(target, "one")
    atomic_write_text(target, "two")
    assert target.read_text() == "two"
    mask = os.umask(0)
    os.umask(mask)
    assert stat.S_IMODE(target.stat().st_mode) == 0o666 & ~mask
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.txt"]


def test_failed_write_leaves_old_file_and_no_temp(tmp_path):
    target = tmp_path / "a.txt"
    target.write_text("old")
    with pytest.raises(RuntimeError), atomic_path(target) as tmp:
        tmp.write_text("half")
        raise RuntimeError("boom")
    assert target.read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.txt"]


def test_missing_directory_is_a_clear_error(tmp_path):
    with pytest.raises(CpmpFileError, match="does not exist"):
        atomic_write_text(tmp_path / "nope" / "a.txt", "x")


def test_killed_save_leaves_a_temporary_that_the_next_save_removes(tmp_path):
    """A writer killed with SIGKILL cannot clean up; the next save to the same target does."""
    import signal
    import subprocess
    import sys
    import time

    target = tmp_path / "model.pt"
    target.write_text("old")
    script = (
        "import sys, time\n"
        "from cpmp.io import atomic_path\n"
        "with atomic_path(sys.argv[1]) as tmp:\n"
        "    tmp.write_bytes(b'x' * 1000)\n"
        "    print(tmp, flush=True)\n"
        "    time.sleep(60)\n"
    )
    proc = subprocess.Popen([sys.executable, "-c", script, str(target)], stdout=subprocess.PIPE)
    tmp = proc.stdout.readline().decode().strip()
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=30)
    proc.stdout.close()
    assert os.path.exists(tmp) and target.read_text() == "old"
    other = tmp_path / ".model.pt.12345x.tmp"  # not one of ours: left alone
    other.write_text("keep")
    time.sleep(0.01)
    atomic_write_text(target, "new")
    assert not os.path.exists(tmp)
    assert target.read_text() == "new"
    assert sorted(p.name for p in tmp_path.iterdir()) == [other.name, "model.pt"]


def test_live_writers_temporaries_are_kept(tmp_path):
    target = tmp_path / "a.txt"
    with atomic_path(target) as tmp:
        tmp.write_text("in progress")
        atomic_write_text(target, "other writer")  # same process, still alive: kept
        assert tmp.exists()
    assert target.read_text() == "in progress"


def test_read_only_directory_is_a_cpmp_file_error(tmp_path):
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o500)
    try:
        if os.access(locked, os.W_OK):  # running as root: permissions are not enforced
            pytest.skip("the directory stays writable for this user")
        with pytest.raises(CpmpFileError, match="choose a writable directory"):
            atomic_write_text(locked / "a.txt", "x")
    finally:
        locked.chmod(0o700)


def test_data_reaches_the_disk_before_the_rename(tmp_path, monkeypatch):
    import cpmp.io

    calls = []
    real_fsync, real_replace = os.fsync, os.replace
    monkeypatch.setattr(cpmp.io.os, "fsync", lambda fd: calls.append("fsync") or real_fsync(fd))
    monkeypatch.setattr(
        cpmp.io.os, "replace", lambda a, b: calls.append("replace") or real_replace(a, b)
    )
    atomic_write_text(tmp_path / "a.txt", "x")
    assert calls[:2] == ["fsync", "replace"]


def _rebuild(payload, version):
    if "value" not in payload:
        raise KeyError("value")
    return payload["value"], version


def _load(path, versions=(1, 2)):
    return load_checkpoint(path, CheckpointSpec("fmt-x", versions, "x model", "R"), _rebuild)


def test_checkpoint_round_trip_passes_the_version_to_rebuild(tmp_path):
    path = save_checkpoint(tmp_path / "m.pt", {"format": "fmt-x", "version": 1, "value": 7})
    assert path == tmp_path / "m.pt"
    assert _load(path) == (7, 1)


def test_checkpoint_of_another_format_carries_the_format_found(tmp_path):
    path = save_checkpoint(tmp_path / "m.pt", {"format": "fmt-y", "version": 1})
    with pytest.raises(CheckpointFormatError, match="not a x model checkpoint") as info:
        _load(path)
    assert info.value.found == "fmt-y"


def test_checkpoint_version_and_damage_are_file_errors(tmp_path):
    path = save_checkpoint(tmp_path / "m.pt", {"format": "fmt-x", "version": 3, "value": 1})
    with pytest.raises(
        CpmpFileError, match="x model checkpoint version 3; this cpmp reads versions 1 and 2"
    ):
        _load(path)
    with pytest.raises(CpmpFileError, match=r"reads version 1$"):
        _load(path, versions=(1,))
    old = save_checkpoint(tmp_path / "old.pt", {"format": "fmt-x", "version": 1, "value": 1})
    with pytest.raises(
        CpmpFileError,
        match=r"old.pt is a x model checkpoint of version 1, a format too old for this cpmp "
        r"\(it reads version 2\); re-fit the model and save it again$",
    ):
        _load(old, versions=(2,))
    damaged = save_checkpoint(tmp_path / "d.pt", {"format": "fmt-x", "version": 2})
    with pytest.raises(
        CpmpFileError, match=r"damaged x model checkpoint .*\(KeyError: 'value'\); R$"
    ):
        _load(damaged)
    with pytest.raises(CpmpFileError, match="does not exist; R"):
        _load(tmp_path / "missing.pt")


def test_saving_onto_a_directory_names_the_directory_not_a_temporary(tmp_path):
    target = tmp_path / "runs"
    target.mkdir()
    with pytest.raises(CpmpFileError, match="it is a directory") as info:
        save_checkpoint(target, {"format": "fmt-x", "version": 1, "value": 1})
    assert str(target) in str(info.value) and ".tmp" not in str(info.value)
    assert list(target.iterdir()) == []
    with pytest.raises(CpmpFileError, match="is a directory"):
        _load(target)


def test_empty_and_truncated_checkpoints_say_so_and_what_to_do(tmp_path):
    path = save_checkpoint(
        tmp_path / "m.pt", {"format": "fmt-x", "version": 1, "value": torch.arange(500.0)}
    )
    data = path.read_bytes()
    half = tmp_path / "half.pt"
    half.write_bytes(data[: len(data) // 2])
    with pytest.raises(CpmpFileError, match=r"truncated or damaged \(\d+ bytes; .*\); .*R$"):
        _load(half)
    empty = tmp_path / "empty.pt"
    empty.write_bytes(b"")
    with pytest.raises(CpmpFileError, match=r"is empty \(0 bytes\).*; R$"):
        _load(empty)


def test_checkpoint_stores_the_payload_checksum_and_verifies_it(tmp_path):
    payload = {"format": "fmt-x", "version": 1, "value": torch.tensor([1.0, 2.0])}
    path = save_checkpoint(tmp_path / "m.pt", payload)
    raw = torch.load(path, weights_only=True)
    assert raw[CHECKSUM_KEY] == payload_digest(payload)
    value, _ = _load(path)
    assert torch.equal(value, payload["value"])
    raw["value"] = torch.tensor([1.0, 2.5])  # content changed after writing
    torch.save(raw, path)
    with pytest.raises(CpmpFileError, match=r"does not match the SHA-256 stored in it.*R$"):
        _load(path)


def test_digest_sees_every_value_and_its_type():
    base = {"a": [1, 2.0, "x", None, True], "t": torch.zeros(3)}
    changed = [
        {"a": [1, 2.0, "x", None, False], "t": torch.zeros(3)},
        {"a": [1, 2, "x", None, True], "t": torch.zeros(3)},  # int, not float
        {"a": (1, 2.0, "x", None, True), "t": torch.zeros(3)},
        {"a": [1, 2.0, "x", None, True], "t": torch.zeros(3, dtype=torch.float64)},
        {"a": [1, 2.0, "x", None, True], "t": torch.zeros(1, 3)},
        {"a": [1, 2.0, "x", None, True], "t": torch.tensor([0.0, -0.0, 0.0])},
        {"t": torch.zeros(3), "a": [1, 2.0, "x", None, True]},  # key order
    ]
    digests = {payload_digest(p) for p in [base, *changed]}
    assert len(digests) == len(changed) + 1
    assert payload_digest({**base, CHECKSUM_KEY: "anything"}) == payload_digest(base)
    with pytest.raises(TypeError, match="holds a set at /a"):
        payload_digest({"a": {1}})


def test_checkpoint_without_checksum_loads_with_a_warning(tmp_path, caplog):
    """Checkpoints written before cpmp stored checksums still load, unverified, and say so."""
    path = tmp_path / "old.pt"
    torch.save({"format": "fmt-x", "version": 1, "value": 3}, path)
    with caplog.at_level("WARNING", logger="cpmp.io"):
        assert _load(path) == (3, 1)
    assert "has no checksum" in caplog.text and "save it again" in caplog.text


def test_a_payload_that_holds_itself_is_refused_not_walked_forever() -> None:
    """A damaged pickle can nest a container in itself: the digest refuses it (a TypeError, so
    the checksum does not match) instead of recursing without end."""
    loop: list[object] = []
    loop.append(loop)
    with pytest.raises(TypeError, match="holds itself at /a\\[0\\]"):
        payload_digest({"a": loop})
    shared = [1.0]  # held twice, not in itself: a digest as any other
    assert payload_digest({"a": shared, "b": shared}) == payload_digest({"a": [1.0], "b": [1.0]})
