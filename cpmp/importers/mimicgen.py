"""robomimic-style HDF5 files of the MimicGen family as demonstrations, read with h5py.

The family: MimicGen, DexMimicGen, Isaac Lab Mimic.

These files keep one group per demonstration, ``/data/demo_<i>``, with observations under
``obs/<key>`` (``(T, k)`` arrays), ``actions`` and, for data generation, ``datagen_info``: the
end-effector poses and, per subtask, a termination signal ``subtask_term_signals/<name>``
(``(T,)`` 0/1, switching to 1 once the subtask is done; MimicGen uses its first 0 -> 1
transition). MimicGen writes the signals under ``datagen_info/``, Isaac Lab Mimic under
``obs/datagen_info/``. Steps carry no time stamps: the mapping gives the control ``rate``.

Every effector is a control variable: its ``k``-th subtask is the MP the mapping names, from
the end of subtask ``k - 1`` to the first 0 -> 1 transition of subtask ``k``'s signal (the last
one to the end of the demonstration). A signal that chatters (turns 1, back to 0, then 1 again)
still ends its subtask at its first rise, as MimicGen does, and the import notes how much
earlier that is than where the signal settles. A control variable can instead read a per-step
label dataset. One demo group is one demonstration (same name).
"""

from __future__ import annotations

import functools
import os
import re
from pathlib import Path

import h5py
import numpy as np

from cpmp.data import Demonstration
from cpmp.errors import CpmpFileError, DataError
from cpmp.importers.common import (
    DemoReader,
    FeatureBlock,
    ImportedDemo,
    ImportNote,
    SkippedDemo,
    check_unique_names,
    column_names,
    debounce,
    decode_labels,
    derived_names,
    pick_columns,
    read_each,
    velocity,
    velocity_hint,
)
from cpmp.importers.spec import EffectorLabel, KeyFeature, MimicGenSpec

SIGNAL_GROUPS = ("datagen_info/subtask_term_signals", "obs/datagen_info/subtask_term_signals")
"""Where the termination signals are looked for when the mapping does not say (MimicGen,
then Isaac Lab Mimic)."""

_DEMO = re.compile(r"demo_[A-Za-z0-9_.\-]+")


def read_mimicgen(
    path: str | os.PathLike[str],
    spec: MimicGenSpec,
    *,
    skipped: list[SkippedDemo] | None = None,
) -> list[ImportedDemo]:
    """Import the demonstrations of a robomimic/MimicGen HDF5 file with ``spec``.

    Args:
        path: the HDF5 file.
        spec: the mapping.
        skipped: ``None``: a bad demo raises; a list: a bad demo is left out and recorded
            there (``on_error: skip``).

    Returns:
        One demonstration per ``/data/demo_<i>`` (natural order), stepped at ``spec.rate``.

    Raises:
        CpmpFileError: the file is missing, not HDF5 or has no ``/data`` group.
        DataError: a mapped key or signal is missing, not numeric, of another length than the
            demo, a signal never switches from 0 to 1, subtasks end out of order, a demo or
            mask asked for is not in the file.
    """
    path = Path(path)
    if not path.is_file():
        raise CpmpFileError(f"{path} does not exist; give the robomimic/MimicGen HDF5 file")
    try:
        f = h5py.File(path, "r")
    except OSError as err:
        raise CpmpFileError(f"cannot open {path} as HDF5: {err}") from None
    with f:
        if "data" not in f or not isinstance(f["data"], h5py.Group):
            raise CpmpFileError(
                f"{path} has no /data group; robomimic files keep demonstrations under "
                "/data/demo_<i>"
            )
        names = _demo_names(f, path, spec)
        readers = [
            DemoReader(n, f"{path}#{n}", functools.partial(_demo, f["data"][n], n, path, spec))
            for n in names
        ]
        return read_each(readers, skipped)


def _demo_names(f: h5py.File, path: Path, spec: MimicGenSpec) -> list[str]:
    present = sorted((k for k in f["data"] if _DEMO.fullmatch(k)), key=_natural_key)
    if not present:
        raise DataError(f"{path}: /data holds no demo_<i> groups")
    if spec.mask is not None:
        masks = sorted(f["mask"]) if "mask" in f else []
        if spec.mask not in masks:
            raise DataError(
                f"{path} has no mask/{spec.mask}; masks in the file: {', '.join(masks) or 'none'}"
            )
        wanted = [v.decode() if isinstance(v, bytes) else str(v) for v in f["mask"][spec.mask][()]]
    elif spec.demos is not None:
        wanted = list(spec.demos)
    else:
        return present
    missing = [n for n in wanted if n not in present]
    if missing:
        raise DataError(
            f"{path}: {missing[0]} is not in /data (present: {', '.join(present[:8])}"
            f"{', ...' if len(present) > 8 else ''})"
        )
    return sorted(wanted, key=_natural_key)


def _demo(group: h5py.Group, name: str, path: Path, spec: MimicGenSpec) -> ImportedDemo:
    blocks = [_feature(group, feature, name, path) for feature in spec.features]
    n = len(blocks[0].values)
    for feature, block in zip(spec.features, blocks, strict=True):
        if len(block.values) != n:
            raise DataError(
                f"{name}: {feature.key} has {len(block.values)} steps but "
                f"{spec.features[0].key} has {n}; every mapped dataset needs one row per step"
            )
    if n < 2:
        raise DataError(f"{name} has {n} step(s); cpmp needs at least 2")
    time = np.arange(n) / spec.rate
    blocks = [
        FeatureBlock(velocity(time, b.values, f"{name}: {feature.key}"), b.names)
        if feature.derive == "velocity"
        else b
        for feature, b in zip(spec.features, blocks, strict=True)
    ]
    notes: list[ImportNote] = []
    labels: dict[str, np.ndarray] = {}
    for label in spec.labels:
        if label.subtasks is not None:
            values = _subtask_labels(group, label, name, n, spec, time, notes)
        else:
            values = _dataset_labels(group, label, name, n)
            values, glitches = debounce(name, label.variable, time, values, spec.min_activation)
            notes.extend(glitches)
        labels[label.variable] = values
    demo = Demonstration(
        time=time,
        features=np.hstack([b.values for b in blocks]),
        labels=labels,
        feature_names=check_unique_names(blocks, name),
        name=name,
        metadata={"source": "mimicgen", "file": str(path), "rate_hz": spec.rate},
    )
    return ImportedDemo(demo, tuple(notes), f"{path}#{name}")


def _dataset(group: h5py.Group, key: str, demo: str, what: str) -> h5py.Dataset:
    if key not in group or not isinstance(group[key], h5py.Dataset):
        parent = key.rsplit("/", 1)[0] if "/" in key else ""
        holder = group[parent] if parent and parent in group else group
        keys = sorted(holder.keys()) if isinstance(holder, h5py.Group) else []
        place = f"{parent}/" if parent and parent in group else ""
        hint = ""
        if what == "dataset":
            positions = [place + k for k in keys if "pos" in k and "vel" not in k]
            hint = velocity_hint(key, positions[0] if positions else "<position key>", "key")
        raise DataError(
            f"{demo} has no {what} {key}; {place or 'the demo group'} holds "
            f"{', '.join(place + k for k in keys) or 'nothing'}; fix the key in the mapping"
            f"{hint}"
        )
    return group[key]


def _feature(group: h5py.Group, feature: KeyFeature, demo: str, path: Path) -> FeatureBlock:
    dataset = _dataset(group, feature.key, demo, "dataset")
    where = f"{demo}: {feature.key}"
    if dataset.dtype.kind not in "biuf":
        raise DataError(f"{where} has dtype {dataset.dtype}; features need numbers")
    shape = dataset.shape
    if len(shape) >= 4 or (len(shape) == 3 and dataset.dtype == np.uint8):
        raise DataError(
            f"{where} has shape {shape} ({dataset.dtype}), which looks like images; cpmp's "
            "features are low-dimensional: map obs keys such as robot0_eef_pos"
        )
    if len(shape) == 0:
        raise DataError(f"{where} is a scalar; features need one row per step")
    values = np.asarray(dataset[()], dtype=np.float64)
    if values.ndim == 1:
        values, elements = values[:, None], [""]
    elif values.ndim == 2:
        elements = [str(i) for i in range(values.shape[1])]
    else:  # (T, a, b), e.g. a 4x4 pose: row-major
        a, b = values.shape[1:]
        values = values.reshape(len(values), a * b)
        elements = [f"{i}.{j}" for i in range(a) for j in range(b)]
    bad = np.argwhere(~np.isfinite(values))
    if bad.size:
        raise DataError(
            f"{where} is NaN/inf at step {int(bad[0][0])} (element {int(bad[0][1])}) in {path}; "
            "repair the demo or leave it out (demos:, mask: or on_error: skip)"
        )
    picked = pick_columns(feature, values.shape[1], where)
    names = column_names(feature, feature.default_prefix, elements, picked, where)
    return FeatureBlock(
        values[:, picked], derived_names(names, feature.derive, feature.names is not None)
    )


def _signal_group(group: h5py.Group, spec: MimicGenSpec, demo: str) -> h5py.Group:
    candidates = (spec.signals,) if spec.signals is not None else SIGNAL_GROUPS
    for key in candidates:
        if key in group and isinstance(group[key], h5py.Group):
            return group[key]
    raise DataError(
        f"{demo} has no subtask termination signals (looked in {', '.join(candidates)}); "
        "set signals: to the group that holds them, or label the variable with dataset:"
    )


def _subtask_labels(
    group: h5py.Group,
    label: EffectorLabel,
    demo: str,
    n: int,
    spec: MimicGenSpec,
    time: np.ndarray,
    notes: list[ImportNote],
) -> np.ndarray:
    """(n,) MP names of one effector from its subtasks' termination signals.

    A chattering signal (more than one 0 -> 1 step) adds a note to ``notes``.
    """
    assert label.subtasks is not None
    signals = _signal_group(group, spec, demo)
    out = np.empty(n, dtype=object)
    start = 0
    for task in label.subtasks[:-1]:
        assert task.signal is not None  # the spec checked: all but the last have one
        if task.signal not in signals:
            raise DataError(
                f"{demo}: no termination signal {task.signal} for {label.variable}'s subtask "
                f"{task.mp!r} in {signals.name.split('/', 3)[-1]} (signals: "
                f"{', '.join(sorted(signals)) or 'none'}); fix the signal name in the mapping"
            )
        signal = signals[task.signal]
        if not isinstance(signal, h5py.Dataset) or signal.size != n:
            shape = signal.shape if isinstance(signal, h5py.Dataset) else "a group"
            raise DataError(
                f"{demo}: signal {task.signal} has shape {shape}; expected ({n},), one flag "
                "per step"
            )
        done = np.asarray(signal[()]).reshape(-1) > 0.5
        rises = np.flatnonzero(done[1:] & ~done[:-1]) + 1
        if not rises.size:
            state = "is 1 from the first step" if done.all() else "never becomes 1"
            raise DataError(
                f"{demo}: signal {task.signal} {state}, so {label.variable}'s subtask "
                f"{task.mp!r} has no end; MimicGen needs a 0 -> 1 transition; fix the signal "
                "or leave the demo out (demos: / mask:)"
            )
        end = int(rises[0])
        if rises.size > 1 or not done[end:].all():
            settled = int(rises[-1]) if done[rises[-1] :].all() else None
            note = _chatter_note(demo, label.variable, task.mp, task.signal, time, end, settled)
            notes.append(note)
        if end <= start:
            raise DataError(
                f"{demo}: {label.variable}'s subtask {task.mp!r} ends at step {end} "
                f"({time[end]:.3f} s), not after the previous subtask's end (step {start}); "
                "list the subtasks in the order they happen"
            )
        out[start:end] = task.mp
        start = end
    out[start:] = label.subtasks[-1].mp
    return decode_labels(label, out.astype(str), f"{demo}: {label.variable} subtasks")


def _chatter_note(
    demo: str,
    variable: str,
    mp: str,
    signal: str,
    time: np.ndarray,
    first: int,
    settled: int | None,
) -> ImportNote:
    """The note on a chattering termination signal: how early its first rise is."""
    if settled is None:
        where = "and does not stay 1 to the end"
    else:
        where = (
            f"and stays 1 only from step {settled} ({time[settled]:.3f} s); the switch is "
            f"{time[settled] - time[first]:.3f} s earlier than there"
        )
    return ImportNote(
        demo,
        "chatter",
        variable,
        f"{variable}: signal {signal} chatters: {mp!r} ends at its first 0 -> 1 step "
        f"{first} ({time[first]:.3f} s), as MimicGen does, {where}",
    )


def _dataset_labels(group: h5py.Group, label: EffectorLabel, demo: str, n: int) -> np.ndarray:
    assert label.dataset is not None
    dataset = _dataset(group, label.dataset, demo, "label dataset")
    raw = np.asarray(dataset[()])
    if raw.ndim == 2 and raw.shape[1] == 1:
        raw = raw[:, 0]
    if raw.ndim != 1 or len(raw) != n:
        raise DataError(
            f"{demo}: label dataset {label.dataset} has shape {dataset.shape}; expected ({n},), "
            "one label per step"
        )
    return decode_labels(label, raw, f"{demo}: label dataset {label.dataset}")


def _natural_key(name: str) -> list[int | str]:
    return [int(p) if p.isdigit() else p for p in re.split(r"(\d+)", name)]


__all__ = ["SIGNAL_GROUPS", "read_mimicgen"]
