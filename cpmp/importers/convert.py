"""Recordings in, cpmp demonstration file out.

:func:`read_recordings` reads without writing; :func:`import_recordings` reads, splits into
``mask/train`` / ``mask/test`` and writes atomically.

Nothing is written until every recording has been read and validated, and the file is
written atomically, so a failed import leaves no file behind (and an existing file at the
output path untouched).

``on_error="skip"`` (the mapping's ``on_error``, or the argument) reads every demonstration on
its own: one that raises a :class:`~cpmp.errors.CpmpError` is left out and reported
(:attr:`ImportResult.skipped`, and ``<output>.skipped.json`` beside the written file); the
import still fails when no demonstration is left.
"""

from __future__ import annotations

import dataclasses
import json
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from cpmp.data import Demonstration, save_demonstrations
from cpmp.errors import ConfigError, CpmpError, CpmpFileError, DataError
from cpmp.importers.common import ImportedDemo, ImportNote, SkippedDemo
from cpmp.importers.lerobot import read_lerobot
from cpmp.importers.mimicgen import read_mimicgen
from cpmp.importers.rosbag import bag_demo_names, find_bags, read_rosbags
from cpmp.importers.spec import (
    ON_ERROR,
    ImportSpec,
    LeRobotSpec,
    MimicGenSpec,
    RosbagSpec,
    SplitSpec,
    load_mapping,
)
from cpmp.io import atomic_write_text
from cpmp.records import JsonValue

PathLike = str | os.PathLike[str]
Inputs = PathLike | Sequence[PathLike]

SKIPPED_SUFFIX = ".skipped.json"
"""The report of an ``on_error: skip`` import sits at ``<output>`` + this suffix."""


@dataclass(frozen=True)
class ImportResult:
    """The outcome of an import.

    Attributes:
        source: ``rosbag``, ``lerobot`` or ``mimicgen``.
        inputs: the recordings given (paths as strings).
        imported: every demonstration with its notes and source, in file order.
        splits: split name -> demonstration names (``train`` always, ``test`` when held out).
        path: the written demonstration file (``None`` when nothing was written).
        skipped: the demonstrations an ``on_error: skip`` import left out, with the reason.
        on_error: ``raise`` or ``skip``: how the import treated a bad demonstration.
        skipped_path: the written ``<output>.skipped.json`` (``on_error: skip`` only).
    """

    source: str
    inputs: tuple[str, ...]
    imported: tuple[ImportedDemo, ...]
    splits: dict[str, list[str]] = field(default_factory=dict)
    path: Path | None = None
    skipped: tuple[SkippedDemo, ...] = ()
    on_error: str = "raise"
    skipped_path: Path | None = None

    @property
    def demos(self) -> list[Demonstration]:
        """The imported demonstrations."""
        return [item.demo for item in self.imported]

    @property
    def notes(self) -> list[ImportNote]:
        """Every note of every demonstration, in order."""
        return [note for item in self.imported for note in item.notes]


def source_of(spec: ImportSpec) -> str:
    """``rosbag``, ``lerobot`` or ``mimicgen`` for a parsed mapping."""
    if isinstance(spec, RosbagSpec):
        return "rosbag"
    if isinstance(spec, LeRobotSpec):
        return "lerobot"
    return "mimicgen"


def as_spec(mapping: ImportSpec | Mapping[str, object] | PathLike) -> ImportSpec:
    """A parsed mapping: itself, or loaded from a dict or YAML file (:func:`load_mapping`)."""
    if isinstance(mapping, (RosbagSpec, LeRobotSpec, MimicGenSpec)):
        return mapping
    return load_mapping(mapping)


def read_recordings(
    mapping: ImportSpec | Mapping[str, object] | PathLike,
    inputs: Inputs,
    *,
    on_error: str | None = None,
) -> ImportResult:
    """Read recordings as the mapping says, without writing anything.

    Args:
        mapping: the mapping (record, dict or YAML path).
        inputs: rosbag: bag directories/files or folders of bags; lerobot: the dataset's
            root folder; mimicgen: the HDF5 file.
        on_error: ``raise`` or ``skip`` a demonstration that cannot be imported; ``None``:
            the mapping's ``on_error`` (default ``raise``).

    Returns:
        The result with no ``path`` and every demonstration in ``train``.

    Raises:
        CpmpError: what the importer raises (:class:`~cpmp.errors.CpmpFileError` for
            unreadable recordings, :class:`~cpmp.errors.DataError` for data the mapping does
            not fit, :class:`~cpmp.errors.ConfigError` for an invalid mapping); with ``skip``,
            only errors that concern every demonstration, or a :class:`DataError` when every
            demonstration was skipped.
    """
    spec = as_spec(mapping)
    if on_error is not None:
        if on_error not in ON_ERROR:
            raise ConfigError(f"on_error must be one of {', '.join(ON_ERROR)}, got {on_error!r}")
        spec = dataclasses.replace(spec, on_error=on_error)
    paths = [inputs] if isinstance(inputs, (str, os.PathLike)) else list(inputs)
    if not paths:
        raise ConfigError("no input recordings given")
    skipped: list[SkippedDemo] | None = [] if spec.on_error == "skip" else None
    if isinstance(spec, RosbagSpec):
        imported = _read_bags(paths, spec, skipped)
    else:
        if len(paths) != 1:
            raise ConfigError(
                f"a {source_of(spec)} import reads one "
                f"{'dataset folder' if isinstance(spec, LeRobotSpec) else 'HDF5 file'}, got "
                f"{len(paths)} inputs; import them one at a time"
            )
        if isinstance(spec, LeRobotSpec):
            imported = read_lerobot(paths[0], spec, skipped=skipped)
        else:
            imported = read_mimicgen(paths[0], spec, skipped=skipped)
    if skipped and not imported:
        first = skipped[0]
        raise DataError(
            f"every demonstration failed to import ({len(skipped)} skipped, none left); the "
            f"first, {first.demo}: {first.reason}"
        )
    names = [item.demo.name for item in imported]
    return ImportResult(
        source=source_of(spec),
        inputs=tuple(str(p) for p in paths),
        imported=tuple(imported),
        splits={"train": [str(n) for n in names]},
        skipped=tuple(skipped or ()),
        on_error=spec.on_error,
    )


def _read_bags(
    paths: list[PathLike], spec: RosbagSpec, skipped: list[SkippedDemo] | None
) -> list[ImportedDemo]:
    """Every bag of ``paths``; with ``skipped``, one bag at a time, a bad one recorded there."""
    if skipped is None:
        return read_rosbags(paths, spec)
    imported: list[ImportedDemo] = []
    bags = find_bags(paths)
    for bag, demo in zip(bags, bag_demo_names(bags), strict=True):
        try:
            imported.extend(read_rosbags([bag], spec))
        except CpmpError as err:
            reason = " ".join(str(err).split())
            skipped.append(SkippedDemo(demo, str(bag), type(err).__name__, reason))
    return imported


def make_splits(names: Sequence[str], split: SplitSpec) -> dict[str, list[str]]:
    """Split demonstration names into ``{"train": [...], "test": [...]}``.

    ``test`` is there only when something is held out; names keep the order given.

    Raises:
        ConfigError: a test name is not among ``names``, or holding out would leave nothing
            to train on.
    """
    names = list(names)
    if split.test:
        unknown = [n for n in split.test if n not in names]
        if unknown:
            raise ConfigError(
                f"split: test names {unknown[0]!r}, which is not an imported demonstration "
                f"({', '.join(names)})"
            )
        test = set(split.test)
    elif split.test_fraction > 0:
        if len(names) < 2:
            raise ConfigError(
                f"split: test_fraction {split.test_fraction} needs at least 2 demonstrations, "
                f"got {len(names)}; import more or set test_fraction to 0"
            )
        n_test = min(max(round(split.test_fraction * len(names)), 1), len(names) - 1)
        rng = np.random.default_rng(split.seed)
        test = {names[i] for i in rng.choice(len(names), size=n_test, replace=False)}
    else:
        test = set()
    train = [n for n in names if n not in test]
    if not train:
        raise ConfigError(
            "split: every demonstration is held out for testing; keep one to train on"
        )
    splits = {"train": train}
    if test:
        splits["test"] = [n for n in names if n in test]
    return splits


def import_recordings(
    mapping: ImportSpec | Mapping[str, object] | PathLike,
    inputs: Inputs,
    output: PathLike,
    split: SplitSpec | None = None,
    *,
    on_error: str | None = None,
) -> ImportResult:
    """Read recordings as the mapping says and write them as one cpmp demonstration file.

    Args:
        mapping: the mapping (record, dict or YAML path; ``docs/importing.md``).
        inputs: the recordings (see :func:`read_recordings`).
        output: the HDF5 file to write (``docs/data_format.md``); its folder must exist.
        split: which demonstrations go to ``mask/test`` (default: none; all in ``mask/train``).
        on_error: ``raise`` (all or nothing) or ``skip`` bad demonstrations; ``None``: the
            mapping's ``on_error``. With ``skip``, ``<output>.skipped.json`` lists every
            skipped demonstration and why (an empty list when none was), written atomically
            after the output.

    Returns:
        The result with ``path`` (and with ``skip``, ``skipped_path``) set.

    Raises:
        CpmpError: as :func:`read_recordings`, or the output cannot be written; then no file
            is left at ``output`` (an existing one is untouched).
    """
    split = split or SplitSpec()
    output = Path(output)
    folder = output.parent if str(output.parent) else Path(".")
    if not folder.is_dir():
        raise CpmpFileError(
            f"cannot write {output}: folder {folder} does not exist; create it first"
        )
    result = read_recordings(mapping, inputs, on_error=on_error)
    names = [str(item.demo.name) for item in result.imported]
    splits = make_splits(names, split)
    save_demonstrations(output, result.demos, splits=splits)
    report = None
    if result.on_error == "skip":
        report = skipped_report_path(output)
        atomic_write_text(report, json.dumps(skipped_report(result, output), indent=2) + "\n")
    return dataclasses.replace(result, splits=splits, path=output, skipped_path=report)


def skipped_report_path(output: PathLike) -> Path:
    """``<output>.skipped.json``: where an ``on_error: skip`` import reports what it skipped."""
    output = Path(output)
    return output.with_name(output.name + SKIPPED_SUFFIX)


def skipped_report(result: ImportResult, output: PathLike) -> dict[str, JsonValue]:
    """The JSON report of an ``on_error: skip`` import.

    Keys: ``output``, ``source``, ``inputs``, ``imported`` (names), ``skipped`` (one
    ``{demo, source, error, reason}`` per skipped demonstration).
    """
    return {
        "output": str(output),
        "source": result.source,
        "inputs": list(result.inputs),
        "imported": [str(item.demo.name) for item in result.imported],
        "skipped": [item.to_dict() for item in result.skipped],
    }


__all__ = [
    "SKIPPED_SUFFIX",
    "ImportResult",
    "as_spec",
    "import_recordings",
    "make_splits",
    "read_recordings",
    "skipped_report",
    "skipped_report_path",
    "source_of",
]
