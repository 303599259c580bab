"""Atomic file writing and the checkpoint files of the sequencers.

A failed write never leaves a partial file behind. Checkpoints have one writer and one loader
that checks integrity (a SHA-256 of the payload stored in the file), format, version and trust.
"""

from __future__ import annotations

import contextlib
import glob
import hashlib
import logging
import math
import os
import pickle
import struct
import tempfile
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, NamedTuple, TypeAlias, TypeVar

import numpy as np

from cpmp.errors import CheckpointFormatError, CpmpError, CpmpFileError

if TYPE_CHECKING:
    import torch

T = TypeVar("T")

log = logging.getLogger(__name__)

CheckpointValue: TypeAlias = (
    "torch.Tensor | torch.dtype | str | int | float | bool"
    " | list[CheckpointValue] | tuple[CheckpointValue, ...] | dict[str, CheckpointValue] | None"
)
"""What a checkpoint payload holds: tensors, dtypes and plain Python, nested (nothing else
loads with ``weights_only=True``; :func:`payload_digest` refuses anything else)."""
CheckpointPayload: TypeAlias = "dict[str, CheckpointValue]"
"""A checkpoint's content: entry name -> value (``format``, ``version``, the model's parts)."""

CHECKSUM_KEY = "sha256"
"""The checkpoint entry holding :func:`payload_digest` of the rest of the payload."""


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
    if target.is_dir():
        raise CpmpFileError(
            f"cannot write {target}: it is a directory; give a file path inside it, such as "
            f"{target / 'model.pt'}"
        )
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


def to_builtin(obj: object) -> CheckpointValue:
    """Recursively convert numpy arrays/scalars, tuples and mappings to plain Python.

    The result is JSON and ``torch.load(weights_only=True)`` safe (a :data:`CheckpointValue`
    without tensors: ``cpmp.records.JsonValue``); non-finite floats become ``None``. Strings,
    ints, finite floats, bools and ``None`` are returned as they are (any other object too,
    unconverted: ``obj`` is to hold only the kinds above).
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
    return obj  # type: ignore[return-value]


def payload_digest(payload: Mapping[str, object]) -> str:
    """The SHA-256 (hex) of a checkpoint payload's content, independent of how it was pickled.

    Keys, their order, strings, numbers (floats bit-exact), ``None``, lists, tuples and every
    tensor's dtype, shape and bytes enter the digest, so any change of a value changes it; the
    :data:`CHECKSUM_KEY` entry itself does not.

    Args:
        payload: tensors and plain Python (what :func:`save_checkpoint` takes).

    Returns:
        64 hexadecimal digits.

    Raises:
        TypeError: the payload holds another kind of object (a checkpoint never does).
    """
    import torch  # lazy: cpmp.data and the importers write through this module without torch

    digest = hashlib.sha256()

    def feed(tag: bytes, data: bytes) -> None:
        digest.update(tag + struct.pack("<Q", len(data)) + data)

    inside: set[int] = set()  # the containers being walked (a damaged pickle can loop)

    def walk(obj: object, where: str) -> None:
        if isinstance(obj, Mapping | list | tuple):
            if id(obj) in inside:
                raise TypeError(
                    f"checkpoint payload holds itself at {where or '/'}; checkpoints hold no cycles"
                )
            inside.add(id(obj))
            try:
                walk_container(obj, where)
            finally:
                inside.discard(id(obj))
        elif isinstance(obj, str):
            feed(b"s", obj.encode("utf-8", "surrogatepass"))
        elif obj is None or isinstance(obj, bool):
            feed(b"b", repr(obj).encode())
        elif isinstance(obj, int):
            feed(b"i", str(obj).encode())
        elif isinstance(obj, float):
            feed(b"f", struct.pack("<d", obj))
        elif isinstance(obj, torch.Tensor):
            flat = obj.detach().to("cpu").contiguous().reshape(-1)
            feed(b"T", f"{flat.dtype} {tuple(obj.shape)}".encode())
            feed(b"B", flat.view(torch.uint8).numpy().tobytes() if flat.numel() else b"")
        elif isinstance(obj, torch.dtype):
            feed(b"D", str(obj).encode())
        else:
            raise TypeError(
                f"checkpoint payload holds a {type(obj).__name__} at {where or '/'}; checkpoints "
                "hold tensors and plain Python only"
            )

    def walk_container(
        obj: Mapping[object, object] | list[object] | tuple[object, ...], where: str
    ) -> None:
        if isinstance(obj, Mapping):
            feed(b"d", str(len(obj)).encode())
            for key, value in obj.items():
                walk(key, where)
                walk(value, f"{where}/{key}")
        else:
            feed(b"l" if isinstance(obj, list) else b"t", str(len(obj)).encode())
            for i, value in enumerate(obj):
                walk(value, f"{where}[{i}]")

    walk({k: v for k, v in payload.items() if k != CHECKSUM_KEY}, "")
    return digest.hexdigest()


def save_checkpoint(path: str | os.PathLike[str], payload: Mapping[str, CheckpointValue]) -> Path:
    """Write a checkpoint ``payload`` atomically to ``path`` with ``torch.save``.

    The file also holds the payload's SHA-256 (:func:`payload_digest`, under
    :data:`CHECKSUM_KEY`), which :func:`load_checkpoint` verifies.

    Args:
        path: the file.
        payload: tensors and plain Python only, so that :func:`load_checkpoint` reads it with
            ``weights_only=True``.

    Returns:
        The path.

    Raises:
        CpmpFileError: ``path`` is a directory or its directory is missing or not writable.
    """
    import torch  # lazy: cpmp.data and the importers write through this module without torch

    path = Path(path)
    content = {k: v for k, v in payload.items() if k != CHECKSUM_KEY}
    content[CHECKSUM_KEY] = payload_digest(content)
    with atomic_path(path) as tmp:
        torch.save(content, tmp)
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
    path: str | os.PathLike[str],
    spec: CheckpointSpec,
    rebuild: Callable[[CheckpointPayload, int], T],
) -> T:
    """Read a checkpoint written by :func:`save_checkpoint` and rebuild its model.

    Every failure is a :class:`CpmpFileError`.

    The payload is loaded with ``torch.load(weights_only=True)``: a file holding Python objects
    is refused as untrusted, never with torch's hint to switch the protection off; an empty,
    truncated or otherwise unreadable file is named so, with ``spec.remedy``. A payload with a
    checksum (:data:`CHECKSUM_KEY`) must match it, else the file is damaged; a payload without
    one (written before cpmp stored checksums) loads, with a logged warning that it was not
    verified. Then its ``"format"`` entry must be ``spec.fmt`` (else
    :class:`CheckpointFormatError` carrying the format found) and its ``"version"`` one of
    ``spec.versions`` (an older one is refused as a format too old, to be re-fitted: cpmp does
    not upgrade checkpoints); ``rebuild(payload, version)`` builds the model, and what it raises
    (:data:`REBUILD_ERRORS`) is reported as a damaged checkpoint.

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
    if isinstance(payload, dict):
        payload = _verified(payload, Path(path), spec)
    if not isinstance(payload, dict) or payload.get("format") != spec.fmt:
        found = payload.get("format") if isinstance(payload, dict) else None
        raise CheckpointFormatError(f"{path} is not a {spec.name} checkpoint", found)
    version = payload.get("version")
    if version not in spec.versions:
        known = " and ".join(str(v) for v in sorted(spec.versions))
        if (
            isinstance(version, int)
            and not isinstance(version, bool)
            and version < min(spec.versions)
        ):
            raise CpmpFileError(
                f"{path} is a {spec.name} checkpoint of version {version}, a format too old for "
                f"this cpmp (it reads version{'s' if len(spec.versions) > 1 else ''} {known}); "
                "re-fit the model and save it again"
            )
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


def _verified(payload: CheckpointPayload, path: Path, spec: CheckpointSpec) -> CheckpointPayload:
    """``payload`` without its checksum entry, once the checksum matched.

    Args:
        payload: what ``torch.load`` read from ``path``.
        path: the file (for messages).
        spec: the checkpoint kind expected (for messages).

    Returns:
        The payload less :data:`CHECKSUM_KEY`.

    Raises:
        CpmpFileError: the stored checksum does not match the content.
        CheckpointFormatError: it does not match and the format entry is not ``spec.fmt``
            (``damaged`` set: another loader may know the format and name the damage).
    """
    stored = payload.get(CHECKSUM_KEY)
    if stored is None:
        if payload.get("format") == spec.fmt:
            log.warning(
                "%s has no checksum (written before cpmp stored one): loaded without an "
                "integrity check; save it again to add one",
                path,
            )
        return payload
    try:
        actual = payload_digest(payload)
    except TypeError as err:
        actual = f"none ({err})"
    if stored != actual and payload.get("format") != spec.fmt:
        raise CheckpointFormatError(
            f"{path} is not a {spec.name} checkpoint (its format entry is "
            f"{payload.get('format')!r}) and its content does not match the SHA-256 stored in "
            "it: a damaged file",
            payload.get("format"),
            damaged=True,
        )
    if stored != actual:
        raise CpmpFileError(
            f"{path} is a damaged {spec.name} checkpoint: its content does not match the "
            f"SHA-256 stored in it (the file changed after it was written, e.g. a bad copy or "
            f"disk); copy it again from its source, or {spec.remedy}"
        )
    return {k: v for k, v in payload.items() if k != CHECKSUM_KEY}


def _load_payload(path: Path, spec: CheckpointSpec) -> CheckpointValue:
    """What ``torch.load(path, weights_only=True)`` returns.

    A payload dict, or any other value the file holds (:func:`load_checkpoint` refuses that as
    another format).

    Raises:
        CpmpFileError: a missing, unreadable or untrusted file (see :func:`load_checkpoint`).
    """
    import torch  # lazy: cpmp.data and the importers write through this module without torch

    if path.is_dir():
        raise CpmpFileError(f"checkpoint {path} is a directory; give the checkpoint file in it")
    if not path.is_file():
        raise CpmpFileError(f"checkpoint {path} does not exist; {spec.remedy}")
    size = path.stat().st_size
    if size == 0:
        raise CpmpFileError(
            f"{path} is empty (0 bytes), not a {spec.name} checkpoint: a save or copy did not "
            f"finish; {spec.remedy}"
        )
    try:
        return torch.load(path, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as err:
        if "global" not in str(err).lower():  # not a refused class: a damaged file
            raise CpmpFileError(
                f"{path} is not a readable {spec.name} checkpoint (the file is damaged or of "
                f"another kind); {spec.remedy}"
            ) from err
        raise CpmpFileError(
            f"{path} is not a trusted {spec.name} checkpoint: it holds Python objects that a cpmp "
            f"checkpoint never contains, so it was not loaded; {spec.remedy}"
        ) from err
    except Exception as err:
        reason = str(err) or type(err).__name__
        raise CpmpFileError(
            f"{path} is not a readable {spec.name} checkpoint: the file is truncated or damaged "
            f"({size} bytes; torch.load: {reason}); copy it again from its source, or "
            f"{spec.remedy}"
        ) from err
