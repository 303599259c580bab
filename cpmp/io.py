"""Atomic file writing and the checkpoint files of the sequencers.

A failed write never leaves a partial file behind. Checkpoints have one writer and one loader
that checks format, version and trust.
"""

from __future__ import annotations

import contextlib
import glob
import math
import os
import pickle
import tempfile
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import Any, NamedTuple, TypeVar

import numpy as np

from cpmp.errors import CheckpointFormatError, CpmpError, CpmpFileError

T = TypeVar("T")


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
    """Remove the temporary files that interrupted saves to ``path`` left behind.

    Those whose writing process no longer exists.

    Args:
        path: the file the saves were writing.

    Returns:
        The removed paths.
    """
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
    """Recursively convert numpy arrays/scalars, tuples and mappings to plain Python.

    The result is JSON and ``torch.load(weights_only=True)`` safe; non-finite floats become
    ``None``.
    """
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


def save_checkpoint(path: str | os.PathLike[str], payload: Mapping[str, Any]) -> Path:
    """Write a checkpoint ``payload`` atomically to ``path`` with ``torch.save``.

    Args:
        path: the file.
        payload: tensors and plain Python only, so that :func:`load_checkpoint` reads it with
            ``weights_only=True``.

    Returns:
        The path.
    """
    import torch  # lazy: cpmp.data and the importers write through this module without torch

    path = Path(path)
    with atomic_path(path) as tmp:
        torch.save(dict(payload), tmp)
    return path


REBUILD_ERRORS = (CpmpError, KeyError, TypeError, ValueError, RuntimeError, AttributeError)
"""What rebuilding a model from a readable payload raises on a damaged or incompatible one."""


class CheckpointSpec(NamedTuple):
    """What a checkpoint kind is and how messages speak of it.

    Attributes:
        fmt: the payload's ``"format"`` entry.
        versions: the payload versions this cpmp reads.
        name: how messages name the kind (``"not a readable {name} checkpoint"``).
        remedy: what to do instead of loading a missing, untrusted or damaged file.
    """

    fmt: str
    versions: tuple[int, ...]
    name: str
    remedy: str


def load_checkpoint(
    path: str | os.PathLike[str], spec: CheckpointSpec, rebuild: Callable[[dict[str, Any], int], T]
) -> T:
    """Read a checkpoint written by :func:`save_checkpoint` and rebuild its model.

    Every failure is a :class:`CpmpFileError`.

    The payload is loaded with ``torch.load(weights_only=True)``: a file holding Python objects
    is refused as untrusted, never with torch's hint to switch the protection off. Then its
    ``"format"`` entry must be ``spec.fmt`` (else :class:`CheckpointFormatError` carrying the
    format found) and its ``"version"`` one of ``spec.versions``; ``rebuild(payload, version)``
    builds the model, and what it raises (:data:`REBUILD_ERRORS`) is reported as a damaged
    checkpoint.

    Args:
        path: the checkpoint file.
        spec: the checkpoint kind expected.
        rebuild: ``(payload, version) -> model``.

    Returns:
        What ``rebuild`` returns.

    Raises:
        CpmpFileError: missing, unreadable, untrusted, of another version, or damaged.
        CheckpointFormatError: a readable checkpoint of another format.
    """
    payload = _load_payload(Path(path), spec)
    if not isinstance(payload, dict) or payload.get("format") != spec.fmt:
        found = payload.get("format") if isinstance(payload, dict) else None
        raise CheckpointFormatError(f"{path} is not a {spec.name} checkpoint", found)
    version = payload.get("version")
    if version not in spec.versions:
        known = " and ".join(str(v) for v in sorted(spec.versions))
        raise CpmpFileError(
            f"{path} has {spec.name} checkpoint version {version}; this cpmp reads "
            f"version{'s' if len(spec.versions) > 1 else ''} {known}"
        )
    try:
        return rebuild(payload, version)
    except REBUILD_ERRORS as err:
        raise CpmpFileError(
            f"{path} is a damaged {spec.name} checkpoint or one this cpmp cannot read "
            f"({type(err).__name__}: {err}); {spec.remedy}"
        ) from err


def _load_payload(path: Path, spec: CheckpointSpec) -> Any:
    """What ``torch.load(path, weights_only=True)`` returns.

    Raises:
        CpmpFileError: a missing, unreadable or untrusted file (see :func:`load_checkpoint`).
    """
    import torch  # lazy: cpmp.data and the importers write through this module without torch

    if not path.is_file():
        raise CpmpFileError(f"checkpoint {path} does not exist; {spec.remedy}")
    try:
        return torch.load(path, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as err:
        if "global" not in str(err).lower():  # not a refused class: a damaged file
            raise CpmpFileError(
                f"{path} is not a readable {spec.name} checkpoint (the file is damaged or of "
                "another kind)"
            ) from err
        raise CpmpFileError(
            f"{path} is not a trusted {spec.name} checkpoint: it holds Python objects that a cpmp "
            f"checkpoint never contains, so it was not loaded; {spec.remedy}"
        ) from err
    except Exception as err:
        raise CpmpFileError(f"{path} is not a readable {spec.name} checkpoint: {err}") from err
