"""ROS 2 bags as demonstrations, read with ``rosbags``.

rosbag2 with sqlite3 or MCAP storage; ``rosbags`` is pure Python (no ROS installation).

One bag is one demonstration. The mapping (:class:`~cpmp.importers.spec.RosbagSpec`) names the
topics and message fields that become features and, per control variable, a topic that gives
the active MP: a ``state`` topic names it in every message (``std_msgs/String``), an ``events``
topic marks each switch. Topics arrive at their own rates: each is sorted by stamp (repeated
stamps keep the last message received, reordering is reported), then resampled onto one clock
at ``rate`` Hz over the span every feature topic (and every state label topic) covers —
features by linear interpolation, labels by zero-order hold. Silent stretches longer than
``max_gap`` are reported (or refused with ``on_gap: error``).

Message definitions are taken from the bag itself (rosbag2 stores them since Humble); bags
without them are read with the ROS 2 Humble type store.
"""

from __future__ import annotations

import dataclasses
import os
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from rosbags.highlevel import AnyReader, AnyReaderError
from rosbags.interfaces import Connection
from rosbags.rosbag2 import ReaderError
from rosbags.serde import SerdeError
from rosbags.typesys import Stores, TypesysError, get_typestore

from cpmp.data import Demonstration
from cpmp.errors import CpmpError, CpmpFileError, DataError
from cpmp.importers.common import (
    FeatureBlock,
    ImportedDemo,
    ImportNote,
    check_unique_names,
    column_names,
    debounce,
    decode_labels,
    demo_name,
    pick_columns,
    stream_notes,
)
from cpmp.importers.resample import (
    CleanStream,
    clean_stream,
    interpolate_linear,
    uniform_clock,
    zero_order_hold,
)
from cpmp.importers.spec import RosbagSpec, TopicFeature, TopicLabel

FALLBACK_TYPESTORE = get_typestore(Stores.ROS2_HUMBLE)
"""Message types for bags that do not embed their definitions."""

_BAG_FILES = (".mcap", ".db3")
_READ_ERRORS = (
    AnyReaderError,
    ReaderError,
    SerdeError,
    TypesysError,
    OSError,
    ValueError,
    KeyError,
    IndexError,
)
"""What reading a damaged bag raises from inside rosbags and its storage plugins."""


@dataclass(frozen=True)
class _Message:
    """One received message: its stamp [s from the bag's start] and the deserialised object."""

    time: float
    msg: Any


def find_bags(inputs: str | os.PathLike[str] | Sequence[str | os.PathLike[str]]) -> list[Path]:
    """The bags in ``inputs``, in natural order of their names.

    A bag is a rosbag2 directory (with ``metadata.yaml``) or a single ``.mcap``/``.db3``
    file; a directory without ``metadata.yaml`` is searched one level down for bags.

    Raises:
        CpmpFileError: an input does not exist or holds no bag.
    """
    paths = [inputs] if isinstance(inputs, (str, os.PathLike)) else list(inputs)
    if not paths:
        raise CpmpFileError("no input given; pass a bag directory or a folder of bags")
    bags: list[Path] = []
    for raw in paths:
        path = Path(raw)
        if not path.exists():
            raise CpmpFileError(f"{path} does not exist; give a bag directory or a folder of bags")
        if _is_bag(path):
            bags.append(path)
            continue
        found = (
            sorted((p for p in path.iterdir() if _is_bag(p)), key=_natural_key)
            if path.is_dir()
            else []
        )
        if not found:
            raise CpmpFileError(
                f"{path} is not a ROS 2 bag and holds none: a bag is a directory with "
                "metadata.yaml (as ros2 bag record writes it) or a .mcap / .db3 file"
            )
        bags.extend(found)
    return bags


def read_rosbags(
    inputs: str | os.PathLike[str] | Sequence[str | os.PathLike[str]], spec: RosbagSpec
) -> list[ImportedDemo]:
    """Import every bag of ``inputs`` (see :func:`find_bags`) with ``spec``.

    Returns:
        One demonstration per bag, named ``demo_<bag name>``.

    Raises:
        CpmpFileError: a bag is missing or unreadable.
        DataError: a mapped topic is missing or empty, a field is missing or not numeric, a
            label topic does not name MPs, the topics do not overlap in time, a gap with
            ``on_gap: error``.
    """
    bags = find_bags(inputs)
    names = [demo_name(bag.stem if bag.is_file() else bag.name) for bag in bags]
    repeated = sorted({n for n in names if names.count(n) > 1})
    if repeated:
        raise CpmpFileError(f"two bags would both become {repeated[0]}; give bags distinct names")
    return [read_bag(bag, spec, name) for bag, name in zip(bags, names, strict=True)]


def read_bag(
    path: str | os.PathLike[str], spec: RosbagSpec, name: str | None = None
) -> ImportedDemo:
    """Import one bag as one demonstration.

    Args:
        path: the bag (directory with ``metadata.yaml``, or a ``.mcap``/``.db3`` file).
        spec: the mapping.
        name: the demonstration's name (default ``demo_<bag name>``).

    Returns:
        The demonstration on a clock of ``spec.rate`` Hz starting at 0 s (``metadata``: the
        bag and the clock's start in bag time, ``start_ns``), and notes on what was repaired.

    Raises:
        CpmpFileError, DataError: as :func:`read_rosbags`.
    """
    bag = Path(path)
    name = name or demo_name(bag.stem if bag.is_file() else bag.name)
    messages, start_ns = _read_messages(bag, spec, name)
    notes: list[ImportNote] = []
    features = [_feature_stream(f, messages[f.topic], spec, name) for f in spec.features]
    labels = [_label_stream(lab, messages[lab.topic], spec, name) for lab in spec.labels]
    covering = [s for s, _ in features] + [
        stream for lab, stream in zip(spec.labels, labels, strict=True) if lab.kind == "state"
    ]
    start = max(float(s.time[0]) for s in covering)
    stop = min(float(s.time[-1]) for s, _ in features)
    clock = uniform_clock(start, stop, spec.rate)
    if len(clock) < 2:
        spans = ", ".join(
            f"{s.report.stream} {s.time[0]:.3f}..{s.time[-1]:.3f} s" for s in covering
        )
        raise DataError(
            f"{name}: the mapped topics do not overlap for two ticks at {spec.rate} Hz "
            f"({spans}); check their stamps (stamps: receive uses the bag's receive times)"
        )
    reported: set[str] = set()
    for stream in [*covering, *labels]:
        if stream.report.stream not in reported:
            reported.add(stream.report.stream)
            notes.extend(stream_notes(name, stream.report, spec.on_gap, offset=start))
    notes.append(
        ImportNote(
            name,
            "window",
            str(bag),
            f"clock {spec.rate:g} Hz from {start:.3f} s to {clock[-1]:.3f} s of the bag "
            f"({len(clock)} ticks; the span every feature topic covers)",
        )
    )
    blocks = [
        FeatureBlock(interpolate_linear(stream.time, stream.values, clock), block_names)
        for stream, block_names in features
    ]
    feature_names = check_unique_names(blocks, name)
    label_arrays: dict[str, np.ndarray] = {}
    for lab, stream in zip(spec.labels, labels, strict=True):
        values = _label_on_clock(lab, stream, clock, name)
        values, glitches = debounce(name, lab.variable, clock - start, values, spec.min_activation)
        label_arrays[lab.variable] = values
        notes.extend(glitches)
    demo = Demonstration(
        time=clock - start,
        features=np.hstack([b.values for b in blocks]),
        labels=label_arrays,
        feature_names=feature_names,
        name=name,
        metadata={
            "source": "rosbag",
            "bag": str(bag),
            "rate_hz": spec.rate,
            "start_ns": int(start_ns + round(start * 1e9)),
        },
    )
    return ImportedDemo(demo, tuple(notes), str(bag))


# ----------------------------------------------------------------------------- reading
def _read_messages(bag: Path, spec: RosbagSpec, name: str) -> tuple[dict[str, list[_Message]], int]:
    """Mapped topics' messages and the bag's start time [ns].

    Messages are (stamp, object) in the order received.
    """
    wanted = {f.topic for f in spec.features} | {lab.topic for lab in spec.labels}
    try:
        reader = AnyReader([bag], default_typestore=FALLBACK_TYPESTORE)
        reader.open()
    except _READ_ERRORS as err:
        raise CpmpFileError(
            f"cannot read {bag} as a ROS 2 bag ({err}); give a rosbag2 directory with "
            "metadata.yaml, or its .mcap / .db3 file"
        ) from None
    try:
        available = reader.topics
        missing = sorted(wanted - set(available))
        if missing:
            users = _topic_users(spec, missing[0])
            raise DataError(
                f"{name}: bag {bag} has no topic {missing[0]} (mapped to {users}); the bag "
                f"records {', '.join(sorted(available)) or 'no topics'}; fix the topic in the "
                "mapping or record it"
            )
        empty = sorted(t for t in wanted if available[t].msgcount == 0)
        if empty:
            raise DataError(
                f"{name}: topic {empty[0]} in bag {bag} has no messages (mapped to "
                f"{_topic_users(spec, empty[0])}); record it or remove it from the mapping"
            )
        connections: list[Connection] = [c for c in reader.connections if c.topic in wanted]
        start_ns = int(reader.start_time)
        messages: dict[str, list[_Message]] = {t: [] for t in wanted}
        for connection, received_ns, raw in reader.messages(connections=connections):
            try:
                msg = reader.deserialize(raw, connection.msgtype)
            except _READ_ERRORS as err:
                raise CpmpFileError(
                    f"{name}: cannot decode a {connection.msgtype} message on {connection.topic} "
                    f"in {bag} ({err}); the bag may be damaged"
                ) from None
            stamp_ns = _header_ns(msg) if spec.stamps == "header" else None
            when = received_ns if stamp_ns is None else stamp_ns
            messages[connection.topic].append(_Message((when - start_ns) / 1e9, msg))
    except CpmpError:
        raise
    except _READ_ERRORS as err:
        raise CpmpFileError(f"cannot read {bag} as a ROS 2 bag: {err}") from None
    finally:
        reader.close()
    return messages, start_ns


def _topic_users(spec: RosbagSpec, topic: str) -> str:
    users = [f"feature {f.name or f.default_prefix}" for f in spec.features if f.topic == topic]
    users += [f"label {lab.variable}" for lab in spec.labels if lab.topic == topic]
    return ", ".join(users)


def _header_ns(msg: Any) -> int | None:
    """``header.stamp`` [ns] where the message has one."""
    stamp = getattr(getattr(msg, "header", None), "stamp", None)
    if stamp is None or not hasattr(stamp, "sec"):
        return None
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


# ---------------------------------------------------------------------------- features
def _feature_stream(
    feature: TopicFeature, messages: list[_Message], spec: RosbagSpec, demo: str
) -> tuple[CleanStream, list[str]]:
    """The feature's columns per message, cleaned, and their names."""
    where = f"topic {feature.topic} field {feature.field}"
    rows = []
    elements: list[str] | None = None
    for message in messages:
        value = _resolve(message.msg, feature.field, f"{demo}: {where}")
        if feature.joints is not None:
            row, row_elements = _by_joint(message.msg, value, feature.joints, f"{demo}: {where}")
        else:
            row, row_elements = _numeric(value, f"{demo}: {where}")
        if elements is None:
            elements = row_elements
        elif row_elements != elements:
            raise DataError(
                f"{demo}: {where} changes shape at {message.time:.3f} s ({len(row_elements)} "
                f"element(s) after {len(elements)}); features need the same elements in every "
                "message (pick them with index/slice/joints)"
            )
        rows.append(row)
    assert elements is not None  # topics without messages were refused when reading
    picked = (
        np.arange(len(elements))
        if feature.joints is not None
        else pick_columns(feature, len(elements), f"{demo}: {where}")
    )
    values = np.asarray(rows, dtype=np.float64)[:, picked]
    bad = np.argwhere(~np.isfinite(values))
    if bad.size:
        i = int(bad[0][0])
        raise DataError(
            f"{demo}: {where} is NaN/inf at {messages[i].time:.3f} s; drop or repair the message"
        )
    times = np.array([m.time for m in messages])
    stream = clean_stream(f"topic {feature.topic}", times, values, spec.max_gap)
    names = column_names(feature, feature.default_prefix, elements, picked, f"{demo}: {where}")
    return stream, names


def _resolve(msg: Any, path: str, where: str) -> Any:
    """The value at dotted ``path`` inside a message."""
    value = msg
    for part in path.split("."):
        if not dataclasses.is_dataclass(value):
            raise DataError(f"{where}: {part!r} is inside a {type(value).__name__}, not a message")
        fields = [f.name for f in dataclasses.fields(value)]
        if part not in fields:
            msgtype = getattr(value, "__msgtype__", type(value).__name__)
            raise DataError(
                f"{where}: {msgtype} has no field {part!r}; its fields are {', '.join(fields)}"
            )
        value = getattr(value, part)
    return value


def _numeric(value: Any, where: str) -> tuple[list[float], list[str]]:
    """A number, numeric array or message as values and element names.

    Element names: ``[""]`` for a number; indices for an array; field paths for a message.
    """
    if isinstance(value, (bool, int, float, np.integer, np.floating)):
        return [float(value)], [""]
    if isinstance(value, (np.ndarray, list, tuple)):
        array = np.asarray(value)
        if array.ndim != 1 or array.dtype.kind not in "biuf":
            raise DataError(
                f"{where} is an array of {array.dtype} with shape {array.shape}; features need "
                "numbers"
            )
        return array.astype(np.float64).tolist(), [str(i) for i in range(len(array))]
    if dataclasses.is_dataclass(value):
        values: list[float] = []
        names: list[str] = []
        _flatten(value, "", values, names)
        if not values:
            raise DataError(f"{where} is a {value.__msgtype__} without numeric fields")
        return values, names
    raise DataError(
        f"{where} is a {type(value).__name__}, not a number, numeric array or message of "
        "numbers; map a numeric field"
    )


def _flatten(msg: Any, prefix: str, values: list[float], names: list[str]) -> None:
    """Append a message's numeric leaves (headers and strings skipped) in definition order."""
    for f in dataclasses.fields(msg):
        value = getattr(msg, f.name)
        path = f"{prefix}{f.name}"
        if f.name == "header":
            continue
        if isinstance(value, (bool, int, float, np.integer, np.floating)):
            values.append(float(value))
            names.append(path)
        elif isinstance(value, np.ndarray) and value.ndim == 1 and value.dtype.kind in "biuf":
            values.extend(value.astype(np.float64).tolist())
            names.extend(f"{path}.{i}" for i in range(len(value)))
        elif dataclasses.is_dataclass(value):
            _flatten(value, f"{path}.", values, names)


def _by_joint(
    msg: Any, value: Any, joints: Sequence[str], where: str
) -> tuple[list[float], list[str]]:
    """The elements of ``value`` belonging to ``joints``, looked up in ``msg.name``."""
    names = getattr(msg, "name", None)
    if not isinstance(names, list):
        raise DataError(
            f"{where}: joints: needs a message with a name list (sensor_msgs/JointState)"
        )
    array = np.asarray(value, dtype=np.float64)
    if array.ndim != 1 or len(array) != len(names):
        raise DataError(f"{where} has {array.size} value(s) for {len(names)} joint name(s)")
    missing = [j for j in joints if j not in names]
    if missing:
        raise DataError(
            f"{where}: no joint {missing[0]!r} in the message; its joints are {', '.join(names)}"
        )
    return [float(array[names.index(j)]) for j in joints], list(joints)


# ------------------------------------------------------------------------------ labels
def _label_stream(
    label: TopicLabel, messages: list[_Message], spec: RosbagSpec, demo: str
) -> CleanStream:
    """The label topic's values (MP names, ids, or nothing for sequence events), cleaned."""
    where = f"{demo}: label topic {label.topic}"
    if label.kind == "events" and label.sequence is not None:
        values = np.zeros(len(messages), dtype=np.int64)
    else:
        raw = [_resolve(m.msg, label.field, f"{where} field {label.field}") for m in messages]
        for m, value in zip(messages, raw, strict=True):
            if isinstance(value, bool) or not isinstance(value, (str, int, np.integer)):
                raise DataError(
                    f"{where} field {label.field} is a {type(value).__name__} at {m.time:.3f} s, "
                    "not an MP name; publish the MP's name (std_msgs/String) or an integer id "
                    "with names: in the mapping"
                )
        values = np.asarray(raw)
        if values.dtype.kind not in "Uiu":
            raise DataError(f"{where} mixes MP names and numbers; publish one kind")
    max_gap = spec.max_gap if label.kind == "state" else None
    return clean_stream(
        f"topic {label.topic}", np.array([m.time for m in messages]), values, max_gap
    )


def _label_on_clock(
    label: TopicLabel, stream: CleanStream, clock: np.ndarray, demo: str
) -> np.ndarray:
    """The variable's MP at every tick."""
    where = f"{demo}: label topic {label.topic}"
    if label.kind == "state":
        return decode_labels(label, zero_order_hold(stream.time, stream.values, clock), where)
    if label.sequence is not None:
        if len(stream.time) != len(label.sequence) - 1:
            raise DataError(
                f"{where} has {len(stream.time)} switch event(s) but the mapping's sequence "
                f"for {label.variable!r} lists {len(label.sequence) - 1} switch(es) "
                f"({' -> '.join(label.sequence)}); fix the sequence or the recording"
            )
        return decode_labels(
            label, _switches(clock, stream.time, label.sequence[0], label.sequence[1:]), where
        )
    assert label.initial is not None  # the spec checked: sequence or initial
    targets = decode_labels(label, stream.values, where)
    first = label.rename.get(label.initial, label.initial)
    # targets are decoded (renamed) already; the check of the whole only adds the initial MP
    return decode_labels(
        dataclasses.replace(label, rename={}), _switches(clock, stream.time, first, targets), where
    )


def _switches(
    clock: np.ndarray, times: np.ndarray, first: str, targets: Sequence[str]
) -> np.ndarray:
    """Labels from switch events, (m,) str.

    ``first`` until the first event time, then each event's target from its time on (an
    event between ticks takes effect at the next tick).
    """
    out = np.full(len(clock), first, dtype=object)
    for when, target in zip(times, targets, strict=True):
        out[clock >= when] = target
    return out.astype(str)


def _is_bag(path: Path) -> bool:
    if path.is_dir():
        return (path / "metadata.yaml").is_file()
    return path.is_file() and path.suffix in _BAG_FILES


def _natural_key(path: Path) -> list[int | str]:
    return [int(p) if p.isdigit() else p for p in re.split(r"(\d+)", path.name)]


__all__ = ["FALLBACK_TYPESTORE", "find_bags", "read_bag", "read_rosbags"]
