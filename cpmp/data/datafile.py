"""The HDF5 file format of demonstrations, read and written atomically.

:func:`save_demonstrations`, :func:`load_demonstrations` and :func:`list_splits`. Files
follow the robomimic layout (``/data/demo_<i>/{time,features,labels/<variable>}``,
``/mask/<split>``); ``docs/data_format.md`` documents it for hand-written recordings. The
record itself (:class:`~cpmp.data.Demonstration`, its validation) is
:mod:`cpmp.data.demonstration`.
"""

from __future__ import annotations

import json
import os
import re
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np

from cpmp.data.demonstration import Demonstration, mp_catalogue
from cpmp.errors import CpmpError, CpmpFileError, DataError
from cpmp.io import atomic_path

FORMAT_NAME = "cpmp-demonstrations"
FORMAT_VERSION = 1

PathLike = str | os.PathLike[str]

_DEMO_NAME = re.compile(r"demo_[A-Za-z0-9_.\-]+")
_SPLIT_NAME = re.compile(r"[A-Za-z0-9_.\-]+")


def save_demonstrations(
    path: PathLike,
    demos: Sequence[Demonstration],
    splits: Mapping[str, Sequence[int | str]] | None = None,
) -> None:
    """Write ``demos`` to an HDF5 file at ``path`` atomically.

    Group names are ``demo.name`` when set (it must look like ``demo_<letters/digits/_.->``),
    else ``demo_<i>`` with ``i`` the position in ``demos``. ``splits`` maps a split name to the
    demo indices or names in it, stored as ``/mask/<split>``. Everything is validated before
    writing; on any failure no file is left behind and an existing file is untouched.
    """
    demos = list(demos)
    if not demos:
        raise DataError("no demonstrations to save; pass at least one Demonstration")
    names = _group_names(demos)
    for demo in demos:
        demo.validate()
    _check_consistent(demos, names)
    masks = _resolve_splits(splits, names)
    catalogue = mp_catalogue(demos)
    sorted_mps = {v: np.array(mps, dtype=str) for v, mps in catalogue.items()}
    try:
        with atomic_path(path) as tmp, h5py.File(tmp, "w") as f:
            data = f.create_group("data")
            data.attrs["format"] = FORMAT_NAME
            data.attrs["format_version"] = FORMAT_VERSION
            data.attrs["feature_names"] = demos[0].feature_names
            data.attrs["variables"] = demos[0].variables
            data.attrs["mp_catalogue"] = json.dumps(catalogue)
            for name, demo in zip(names, demos, strict=True):
                group = data.create_group(name)
                group.attrs["name"] = name
                group.attrs["num_samples"] = demo.n_samples
                if demo.metadata:
                    group.attrs["metadata"] = json.dumps(demo.metadata)
                group.create_dataset("time", data=demo.time)
                group.create_dataset("features", data=demo.features)
                for variable, labels in demo.labels.items():
                    label_ids = np.searchsorted(sorted_mps[variable], labels).astype(np.int32)
                    group.create_dataset(f"labels/{variable}", data=label_ids)
            for split, members in masks.items():
                f.create_dataset(f"mask/{split}", data=np.array(members, dtype="S"))
    except CpmpError:
        raise
    except OSError as err:
        raise CpmpFileError(f"could not write demonstrations to {path}: {err}") from err


def load_demonstrations(path: PathLike, split: str | None = None) -> list[Demonstration]:
    """Read the demonstrations in ``path`` (all, or those in ``/mask/<split>``).

    Demonstrations come back in natural order of their group names (``demo_2`` before
    ``demo_10``); ``name`` is the group name.

    Raises:
        CpmpFileError: the file is missing, not HDF5, or not in the cpmp layout/version.
        DataError: a demonstration is malformed (label ids outside ``mp_catalogue``, NaN, ...)
            or ``split`` is not in the file (the message lists the available splits).
    """
    with _open(path) as (f, header):
        groups = _demo_groups(f, path)
        if split is not None:
            splits = _read_splits(f, path)
            if split not in splits:
                available = ", ".join(sorted(splits)) or "none"
                raise DataError(f"{path}: no split {split!r}; available splits: {available}")
            members = set(splits[split])
            missing = sorted(members.difference(groups), key=_natural_key)
            if missing:
                raise DataError(
                    f"{path}: mask/{split} lists {', '.join(missing)} which is not in /data; "
                    "fix the mask or add the demonstration"
                )
            groups = [g for g in groups if g in members]
        return [_read_demo(f[f"data/{g}"], g, header, path) for g in groups]


def list_splits(path: PathLike) -> dict[str, list[str]]:
    """Split name -> demo group names stored under ``/mask`` (empty dict if none)."""
    with _open(path) as (f, _):
        return _read_splits(f, path)


@dataclass(frozen=True)
class _Header:
    feature_names: list[str]
    variables: list[str]
    catalogue: dict[str, list[str]]


def _natural_key(name: str) -> list[int | str]:
    return [int(tok) if tok.isdigit() else tok for tok in re.split(r"(\d+)", name)]


def _group_names(demos: list[Demonstration]) -> list[str]:
    for demo in demos:
        if not isinstance(demo, Demonstration):
            raise DataError(f"expected Demonstration objects, got {type(demo).__name__}")
    names = [demo.name or f"demo_{i}" for i, demo in enumerate(demos)]
    seen: dict[str, int] = {}
    for i, name in enumerate(names):
        if not _DEMO_NAME.fullmatch(name):
            raise DataError(
                f"{name}: cannot be stored as an HDF5 group; rename it to demo_<something> "
                "using letters, digits, '_', '.' or '-' (or leave name=None for demo_<index>)"
            )
        if name in seen:
            raise DataError(
                f"{name}: demonstrations {seen[name]} and {i} share this name; "
                "give every demonstration a unique name"
            )
        seen[name] = i
    return names


def _check_consistent(demos: list[Demonstration], names: list[str]) -> None:
    ref = demos[0]
    for name, demo in zip(names[1:], demos[1:], strict=True):
        if demo.feature_names != ref.feature_names:
            raise DataError(
                f"{name}: feature_names {demo.feature_names} differ from {names[0]}'s "
                f"{ref.feature_names}; all demonstrations in a file must share the feature set"
            )
        if demo.variables != ref.variables:
            raise DataError(
                f"{name}: control variables {demo.variables} differ from {names[0]}'s "
                f"{ref.variables}; label the same variables in every demonstration"
            )


def _resolve_splits(
    splits: Mapping[str, Sequence[int | str]] | None, names: list[str]
) -> dict[str, list[str]]:
    if splits is None:
        return {}
    resolved: dict[str, list[str]] = {}
    for split, members in splits.items():
        if not isinstance(split, str) or not _SPLIT_NAME.fullmatch(split) or split == ".":
            raise DataError(
                f"split name {split!r} is invalid; use letters, digits, '_', '.' or '-'"
            )
        if isinstance(members, str | bytes):
            raise DataError(f"split {split!r} must be a list of demo indices or names")
        out: list[str] = []
        for member in members:
            if isinstance(member, int | np.integer) and not isinstance(member, bool):
                if not 0 <= member < len(names):
                    raise DataError(
                        f"split {split!r}: index {member} is out of range for "
                        f"{len(names)} demonstrations (use 0..{len(names) - 1})"
                    )
                out.append(names[int(member)])
            elif isinstance(member, str) and member in names:
                out.append(member)
            else:
                raise DataError(
                    f"split {split!r}: {member!r} is neither a demo index nor one of the demo "
                    f"names ({', '.join(names)})"
                )
        dupes = sorted({m for m in out if out.count(m) > 1})
        if dupes:
            raise DataError(f"split {split!r} lists {', '.join(dupes)} more than once")
        resolved[split] = out
    return resolved


@contextmanager
def _open(path: PathLike) -> Iterator[tuple[h5py.File, _Header]]:
    """Open ``path`` read-only and check the ``/data`` header."""
    p = Path(path)
    if not p.exists():
        raise CpmpFileError(f"{p}: no such file")
    if not p.is_file():
        raise CpmpFileError(f"{p}: is not a file")
    if not h5py.is_hdf5(p):
        raise CpmpFileError(f"{p}: is not an HDF5 file; expected a cpmp demonstrations file")
    try:
        with h5py.File(p, "r") as f:
            yield f, _read_header(f, p)
    except CpmpError:
        raise
    except (OSError, KeyError, TypeError, ValueError) as err:
        raise CpmpFileError(f"{p}: could not read demonstrations ({err})") from err


def _read_header(f: h5py.File, path: Path) -> _Header:
    data = f.get("data")
    if not isinstance(data, h5py.Group):
        raise CpmpFileError(f"{path}: has no /data group; not a cpmp demonstrations file")
    attrs = data.attrs
    fmt = _as_str(attrs.get("format"))
    if fmt != FORMAT_NAME:
        raise CpmpFileError(f"{path}: /data attribute format is {fmt!r}, expected {FORMAT_NAME!r}")
    version = attrs.get("format_version")
    if isinstance(version, np.generic):
        version = version.item()
    if version != FORMAT_VERSION:
        raise CpmpFileError(
            f"{path}: format_version {version!r} is not supported (this cpmp reads version "
            f"{FORMAT_VERSION}); upgrade cpmp or re-export the file"
        )
    for key in ("feature_names", "variables", "mp_catalogue"):
        if key not in attrs:
            raise CpmpFileError(f"{path}: /data is missing the {key!r} attribute")
    feature_names = _as_str_list(attrs["feature_names"], f"{path}: /data feature_names")
    variables = _as_str_list(attrs["variables"], f"{path}: /data variables")
    try:
        catalogue = json.loads(_as_str(attrs["mp_catalogue"]))
    except (TypeError, ValueError) as err:
        raise CpmpFileError(f"{path}: mp_catalogue is not valid JSON ({err})") from None
    if not isinstance(catalogue, dict) or sorted(catalogue) != sorted(variables):
        raise CpmpFileError(
            f"{path}: mp_catalogue must be a JSON object with one key per variable "
            f"{sorted(variables)}"
        )
    for variable, mps in catalogue.items():
        if not isinstance(mps, list) or not all(isinstance(m, str) and m for m in mps):
            raise CpmpFileError(
                f"{path}: mp_catalogue[{variable!r}] must be a list of non-empty MP names"
            )
    return _Header(feature_names, variables, catalogue)


def _demo_groups(f: h5py.File, path: PathLike) -> list[str]:
    names = [k for k in f["data"] if k.startswith("demo_")]
    for name in names:
        if not isinstance(f["data"][name], h5py.Group):
            raise CpmpFileError(f"{path}: /data/{name} must be a group, not a dataset")
    return sorted(names, key=_natural_key)


def _read_splits(f: h5py.File, path: PathLike) -> dict[str, list[str]]:
    mask = f.get("mask")
    if mask is None:
        return {}
    splits: dict[str, list[str]] = {}
    for split in mask:
        dataset = mask[split]
        if not isinstance(dataset, h5py.Dataset) or dataset.ndim != 1:
            raise CpmpFileError(f"{path}: /mask/{split} must be a 1-D array of demo names")
        splits[split] = _as_str_list(dataset[()], f"{path}: /mask/{split}")
    return splits


def _read_demo(group: h5py.Group, name: str, header: _Header, path: PathLike) -> Demonstration:
    for key in ("time", "features", "labels"):
        if key not in group:
            raise CpmpFileError(f"{path}: /data/{name} has no {key!r} entry")
    stored = sorted(group["labels"])
    if stored != sorted(header.variables):
        raise CpmpFileError(
            f"{path}: /data/{name}/labels has {stored} but /data lists variables "
            f"{sorted(header.variables)}"
        )
    labels = {v: _decode_labels(group["labels"][v][()], name, v, header) for v in stored}
    metadata = None
    if "metadata" in group.attrs:
        try:
            metadata = json.loads(_as_str(group.attrs["metadata"]))
        except (TypeError, ValueError) as err:
            raise CpmpFileError(f"{path}: /data/{name} metadata is not JSON ({err})") from None
    demo = Demonstration(
        time=group["time"][()],
        features=group["features"][()],
        labels=labels,
        feature_names=header.feature_names,
        name=name,
        metadata=metadata,
    )
    num_samples = group.attrs.get("num_samples")
    if num_samples is not None and int(num_samples) != demo.n_samples:
        raise DataError(
            f"{name}: num_samples attribute is {int(num_samples)} but the demonstration has "
            f"{demo.n_samples} samples; fix the attribute"
        )
    return demo


def _decode_labels(ids: np.ndarray, name: str, variable: str, header: _Header) -> np.ndarray:
    mps = header.catalogue[variable]
    if ids.ndim != 1 or ids.dtype.kind not in "iu":
        raise DataError(
            f"{name}: labels/{variable} must be a 1-D integer array of MP ids, got "
            f"{ids.dtype} with shape {ids.shape}"
        )
    bad = np.flatnonzero((ids < 0) | (ids >= len(mps)))
    if bad.size:
        i = int(bad[0])
        raise DataError(
            f"{name}: labels/{variable} has MP id {int(ids[i])} at step {i} but "
            f"mp_catalogue[{variable!r}] has {len(mps)} MPs (ids 0..{len(mps) - 1}); "
            "add the MP to the catalogue or fix the id"
        )
    return np.array(mps, dtype=str)[ids]


def _as_str(value: object) -> str | None:
    """``value`` (an HDF5 attribute or item, of whatever type the file holds) as a string."""
    if isinstance(value, bytes | np.bytes_):
        return value.decode("utf-8")
    if isinstance(value, str):
        return str(value)
    if isinstance(value, np.ndarray) and value.shape == ():
        return _as_str(value.item())
    return None


def _as_str_list(value: object, what: str) -> list[str]:
    """``value`` (an HDF5 attribute, of whatever type the file holds) as a list of strings."""
    out = [_as_str(v) for v in np.atleast_1d(np.asarray(value)).tolist()]
    strings = [v for v in out if v is not None]
    if len(strings) != len(out):
        raise CpmpFileError(f"{what} must be a list of strings, got {value!r}")
    return strings


__all__ = [
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "list_splits",
    "load_demonstrations",
    "save_demonstrations",
]
