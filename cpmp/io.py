"""Atomic file writing: a failed write never leaves a partial file behind."""

from __future__ import annotations

import contextlib
import glob
import math
import os
import tempfile
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from cpmp.errors import CheckpointFormatError, CpmpFileError


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it onto ``path`` only on success.

    The caller writes the whole file to the yielded path. If the block raises, the temporary
    file is removed and ``path`` (if it existed) is left untouched. The temporary file's name
    carries the writer's process id, so temporary files of saves whose process was killed
    (``SIGKILL``, power loss) are recognised and removed by the next save to ``path``.
    """
    target = Path(path)
    directory = target.parent if str(target.parent) else Path(".")
    if not directory.exists():
        raise CpmpFileError(f"cannot write {target}: directory {directory} does not exist")
    remove_stale_temporaries(target)
    try:
        fd, tmp_name = tempfile.mkstemp(
            prefix=f".{target.name}.{os.getpid()}.", suffix=".tmp", dir=directory
        )
    except OSError as err:
        raise CpmpFileError(
            f"cannot write {target}: {err.strerror or err}; choose a writable directory"
        ) from err
    os.close(fd)
    tmp = Path(tmp_name)
    os.chmod(tmp, 0o666 & ~_umask())
    try:
        yield tmp
        _fsync(tmp)
        os.replace(tmp, target)
        _fsync_directory(directory)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        raise


def _fsync(path: Path) -> None:
    """Flush ``path``'s data to disk, so the rename never publishes an empty file."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _fsync_directory(directory: Path) -> None:
    """Make the rename itself durable (where the platform allows directory fsync)."""
    with contextlib.suppress(OSError):
        fd = os.open(directory, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def remove_stale_temporaries(path: str | os.PathLike[str]) -> list[Path]:
    """Remove the temporary files that interrupted saves to ``path`` left behind (those whose
    writing process no longer exists); returns the removed paths."""
    target = Path(path)
    directory = target.parent if str(target.parent) else Path(".")
    removed = []
    prefix = f".{target.name}."
    for tmp in directory.glob(f"{glob.escape(prefix)}*.tmp"):
        pid_text = tmp.name[len(prefix) :].split(".", 1)[0]
        if not pid_text.isdigit() or _alive(int(pid_text)):
            continue
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
            removed.append(tmp)
    return removed


def _alive(pid: int) -> bool:
    """Whether a process ``pid`` exists on this machine."""
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _umask() -> int:
    """The process umask (mkstemp creates 0600 files; finished files get the usual mode)."""
    mask = os.umask(0)
    os.umask(mask)
    return mask


def atomic_write_text(path: str | os.PathLike[str], text: str) -> None:
    """Write ``text`` to ``path`` atomically (UTF-8)."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


def atomic_write_bytes(path: str | os.PathLike[str], data: bytes) -> None:
    """Write ``data`` to ``path`` atomically."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)


def to_builtin(obj: Any) -> Any:
    """Recursively convert numpy arrays/scalars, tuples and mappings to plain Python (JSON and
    ``torch.load(weights_only=True)`` safe); non-finite floats become ``None``."""
    if isinstance(obj, Mapping):
        return {str(k): to_builtin(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [to_builtin(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return to_builtin(obj.tolist())
    if isinstance(obj, np.generic):
        return to_builtin(obj.item())
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def load_checkpoint(
    path: str | os.PathLike[str], fmt: str, label: str, kind: str, remedy: str
) -> dict:
    """The payload dict of a checkpoint written by ``torch.save``, loaded with
    ``weights_only=True``; every failure is a :class:`CpmpFileError`.

    ``fmt``: the payload's ``"format"`` entry; ``label``: how messages name an unreadable file
    (``"a readable {label} checkpoint"``); ``kind``: how they name a payload of another format;
    ``remedy``: what to do instead (a missing or untrusted file). A file holding Python objects
    is refused as untrusted, never with torch's hint to switch the protection off. Version
    checks stay with the caller.
    """
    import pickle

    import torch

    path = Path(path)
    if not path.is_file():
        raise CpmpFileError(f"checkpoint {path} does not exist; {remedy}")
    try:
        payload = torch.load(path, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as err:
        if "global" not in str(err).lower():  # not a refused class: a damaged file
            raise CpmpFileError(
                f"{path} is not a readable {label} checkpoint (the file is damaged or of "
                "another kind)"
            ) from err
        raise CpmpFileError(
            f"{path} is not a trusted {label} checkpoint: it holds Python objects that a cpmp "
            f"checkpoint never contains, so it was not loaded; {remedy}"
        ) from err
    except Exception as err:
        raise CpmpFileError(f"{path} is not a readable {label} checkpoint: {err}") from err
    if not isinstance(payload, dict) or payload.get("format") != fmt:
        found = payload.get("format") if isinstance(payload, dict) else None
        raise CheckpointFormatError(f"{path} is not a {kind} checkpoint", found)
    return payload
