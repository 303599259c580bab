"""ROS 2 bags as demonstrations, read with ``rosbags``.

rosbag2 with sqlite3 or MCAP storage; ``rosbags`` is pure Python (no ROS installation).

One bag is one demonstration. The mapping (:class:`~cpmp.importers.spec.RosbagSpec`) names the
topics and message fields that become features and, per control variable, a topic that gives
the active MP: a ``state`` topic names it in every message (``std_msgs/String``), an ``events``
topic marks each switch. Topics arrive at their own rates: each is sorted by stamp (repeated
stamps keep the last message received, reordering is reported), then resampled onto one clock
at ``rate`` Hz over the span every feature series (and every state label topic) covers —
features by linear interpolation, quaternions by slerp after hemisphere alignment, labels by
zero-order hold; a note names the topic that limits the span and what it cut. Silent
stretches longer than ``max_gap`` are reported (or refused with ``on_gap: error``).

Recordings as robots make them: ``/joint_states`` shared by several publishers (each message
holds some of the joints: every joint is its own series), object poses on ``/tf`` and
``/tf_static`` (a frame picked by ``child_frame_id`` wherever it sits in the message, composed
through the tree to a chosen parent), and a bag folder that an interrupted ``ros2 bag record``
left without ``metadata.yaml`` (refused with the ``ros2 bag reindex`` command that repairs it).

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
    ROTATION_ELEMENTS,
    CleanStream,
    StreamReport,
    align_quaternions,
    clean_stream,
    interpolate_linear,
    interpolate_slerp,
    rotation_columns,
    uniform_clock,
    zero_order_hold,
)
from cpmp.importers.spec import RosbagSpec, TfFrame, TopicFeature, TopicLabel

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

_QUATERNION = "geometry_msgs/msg/Quaternion"


@dataclass(frozen=True)
class _Message:
    """One received message.

    Attributes:
        time: [s from the bag's start] its stamp (``spec.stamps``).
        received: [s from the bag's start] when the bag recorded it.
        msg: the deserialised message (a ``rosbags`` message dataclass of the topic's type,
            read through its fields).
    """

    time: float
    received: float
    msg: object


@dataclass(frozen=True)
class _Group:
    """Elements of a feature that are resampled together.

    Attributes:
        raw: the columns of the recorded values they come from.
        elements: the feature elements they give (a quaternion's after conversion).
        quaternion: ``raw`` is one quaternion ``x, y, z, w`` (slerped, then converted).
        base: a quaternion's path in the message (``pose.orientation``; empty for the field).
    """

    raw: tuple[int, ...]
    elements: tuple[str, ...]
    quaternion: bool = False
    base: str = ""


@dataclass(frozen=True)
class _Part:
    """Feature columns that share one series of stamps.

    Attributes:
        stream: the cleaned series, (m, w) values (quaternions hemisphere-aligned).
        positions: the feature elements it fills (indices into all the feature's elements).
        quaternion: ``stream`` holds one quaternion, slerped and converted to the mapping's
            rotation.
        moving: ``False`` for a constant (a static transform): it does not limit the clock.
    """

    stream: CleanStream
    positions: tuple[int, ...]
    quaternion: bool = False
    moving: bool = True


@dataclass(frozen=True)
class _Series:
    """One feature entry, read and cleaned, before resampling.

    Attributes:
        feature: the mapping's entry.
        parts: its series, each with its own stamps.
        width: how many elements the entry has (before ``index``/``slice``).
        picked: the elements kept.
        names: the kept elements' feature names.
        reports: what cleaning found, one per recorded series (for the notes).
        notes: what the reading repaired (quaternion sign flips).
    """

    feature: TopicFeature
    parts: tuple[_Part, ...]
    width: int
    picked: np.ndarray
    names: list[str]
    reports: tuple[StreamReport, ...]
    notes: tuple[ImportNote, ...]

    def on_clock(self, clock: np.ndarray) -> FeatureBlock:
        """The kept elements at every tick."""
        out = np.full((len(clock), self.width), np.nan)
        for part in self.parts:
            if part.quaternion:
                q = interpolate_slerp(part.stream.time, part.stream.values, clock)
                values = rotation_columns(q, self.feature.rotation)
            else:
                values = interpolate_linear(part.stream.time, part.stream.values, clock)
            out[:, list(part.positions)] = values
        return FeatureBlock(out[:, self.picked], self.names)


@dataclass(frozen=True)
class _Cover:
    """A series whose span limits the clock: what it is and its cleaned stream."""

    what: str
    stream: CleanStream


# ----------------------------------------------------------------------------- finding bags
def find_bags(inputs: str | os.PathLike[str] | Sequence[str | os.PathLike[str]]) -> list[Path]:
    """The bags in ``inputs``, in natural order of their names.

    A bag is a rosbag2 directory (with ``metadata.yaml``) or a single ``.mcap``/``.db3``
    file; a directory without ``metadata.yaml`` is searched one level down for bags. A bag
    folder that lost its ``metadata.yaml`` (an interrupted ``ros2 bag record``: a folder of
    ``.db3``/``.mcap`` files inside a folder of bags, or given itself with storage files
    named after it) is listed too: :func:`read_bag` refuses it, naming the repair.

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
        if _is_bag(path) or _is_interrupted(path, named=True):
            bags.append(path)
            continue
        found = (
            sorted(
                (p for p in path.iterdir() if _is_bag(p) or _is_interrupted(p, named=False)),
                key=_natural_key,
            )
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


def bag_demo_names(bags: Sequence[Path]) -> list[str]:
    """The demonstration name of every bag (:func:`~cpmp.importers.common.demo_name`).

    Raises:
        CpmpFileError: two bags would get the same name (both are named).
    """
    names = [demo_name(bag.stem if bag.is_file() else bag.name) for bag in bags]
    first: dict[str, Path] = {}
    for bag, name in zip(bags, names, strict=True):
        if name in first:
            raise CpmpFileError(
                f"bags {first[name]} and {bag} would both become {name}; rename one of them "
                "(demonstration names keep letters, digits, '_', '.' and '-')"
            )
        first[name] = bag
    return names


def read_rosbags(
    inputs: str | os.PathLike[str] | Sequence[str | os.PathLike[str]], spec: RosbagSpec
) -> list[ImportedDemo]:
    """Import every bag of ``inputs`` (see :func:`find_bags`) with ``spec``.

    Returns:
        One demonstration per bag, named ``demo_<bag name>``.

    Raises:
        CpmpFileError: a bag is missing or unreadable, or two bags would share a name.
        DataError: a bag is empty or was not closed (no ``metadata.yaml``), a mapped topic is
            missing or empty, a field, joint or frame is missing or not numeric, a label
            topic does not name MPs, the topics do not overlap in time, a gap with
            ``on_gap: error``.
    """
    bags = find_bags(inputs)
    names = bag_demo_names(bags)
    return [read_bag(bag, spec, name) for bag, name in zip(bags, names, strict=True)]


# ------------------------------------------------------------------------------- one bag
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
        bag and the clock's start in bag time, ``start_ns``), and notes on what was repaired
        (a ``window`` note says which topic limits the clock's span, and what it cut).

    Raises:
        CpmpFileError, DataError: as :func:`read_rosbags`.
    """
    bag = Path(path)
    name = name or demo_name(bag.stem if bag.is_file() else bag.name)
    if _is_interrupted(bag, named=False):
        raise DataError(_interrupted_message(name, bag))
    messages, start_ns = _read_messages(bag, spec, name)
    series = [_feature_series(f, messages, spec, name, start_ns) for f in spec.features]
    labels = [_label_stream(lab, messages[lab.topic], spec, name) for lab in spec.labels]
    features = [
        _Cover(f"feature {p.stream.report.stream}", p.stream)
        for s in series
        for p in s.parts
        if p.moving
    ]
    if not features:
        raise DataError(
            f"{name}: every mapped feature is constant (static transforms only); map at least "
            "one feature that is recorded over time"
        )
    covering = features + [
        _Cover(f"label {stream.report.stream}", stream)
        for lab, stream in zip(spec.labels, labels, strict=True)
        if lab.kind == "state"
    ]
    first = max(covering, key=lambda c: float(c.stream.time[0]))
    last = min(features, key=lambda c: float(c.stream.time[-1]))
    start, stop = float(first.stream.time[0]), float(last.stream.time[-1])
    clock = uniform_clock(start, stop, spec.rate)
    if len(clock) < 2:
        spans = ", ".join(
            f"{c.stream.report.stream} {c.stream.time[0]:.3f}..{c.stream.time[-1]:.3f} s"
            for c in covering
        )
        raise DataError(
            f"{name}: the mapped topics do not overlap for two ticks at {spec.rate} Hz "
            f"({spans}); check their stamps (stamps: receive uses the bag's receive times)"
        )
    notes: list[ImportNote] = []
    reported: set[str] = set()
    reports = [r for s in series for r in s.reports] + [s.report for s in labels]
    for report in reports:
        if report.stream not in reported:
            reported.add(report.stream)
            notes.extend(stream_notes(name, report, spec.on_gap, offset=start))
    notes.extend(note for s in series for note in s.notes)
    notes.append(_window_note(name, bag, spec, features, first, last, clock))
    blocks = [s.on_clock(clock) for s in series]
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


def _window_note(
    demo: str,
    bag: Path,
    spec: RosbagSpec,
    features: Sequence[_Cover],
    first: _Cover,
    last: _Cover,
    clock: np.ndarray,
) -> ImportNote:
    """The clock's span, the series that start it and end it, and what they cut.

    Cuts are measured against the feature data: from the first feature sample to the last.
    A cut shorter than one tick is not a loss and is not mentioned.
    """
    start, end = float(clock[0]), float(clock[-1])
    earliest = min(float(c.stream.time[0]) for c in features)
    latest = max(float(c.stream.time[-1]) for c in features)
    text = (
        f"clock {spec.rate:g} Hz from {start:.3f} s to {end:.3f} s of the bag ({len(clock)} "
        f"ticks): it starts when {first.what} starts and ends when {last.what} ends"
    )
    cuts = []
    tick = 1.0 / spec.rate
    if start - earliest > tick:
        cuts.append(
            f"{first.what} starts {start - earliest:.3f} s after the first feature data "
            f"({earliest:.3f} s), cutting the start"
        )
    if latest - end > tick:
        cuts.append(
            f"the last feature data ends {latest - end:.3f} s after {last.what} "
            f"({latest:.3f} s), cut from the end"
        )
    if cuts:
        text += (
            f"; {'; '.join(cuts)}: the recorded {latest - earliest:.3f} s become "
            f"{end - start:.3f} s"
        )
    return ImportNote(demo, "window", str(bag), text)


def _interrupted_message(name: str, bag: Path) -> str:
    mcap = any(p.suffix == ".mcap" for p in bag.iterdir())
    storage = "mcap" if mcap else "sqlite3"
    return (
        f"{name}: bag folder {bag} has no metadata.yaml: its recording was interrupted (ros2 "
        "bag record was stopped before it closed the bag) or the file was lost; rebuild it with "
        f"`ros2 bag reindex {bag} -s {storage}`, or remove the folder from the input"
    )


# ----------------------------------------------------------------------------- reading
def _read_messages(bag: Path, spec: RosbagSpec, name: str) -> tuple[dict[str, list[_Message]], int]:
    """Mapped topics' messages and the bag's start time [ns].

    Messages are in the order received; topics of a tf feature that the bag does not have
    are empty lists.
    """
    required = {lab.topic for lab in spec.labels}
    required |= {f.topic for f in spec.features if f.topic is not None}
    tf_topics = {t for f in spec.features if f.tf is not None for t in f.topics}
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
        if reader.message_count == 0:
            declared = f"{len(available)} topic(s) declared" if available else "no topics"
            raise DataError(
                f"{name}: bag {bag} is empty: it holds no messages ({declared}); re-record it "
                "or remove it from the input"
            )
        missing = sorted(required - set(available))
        for feature in spec.features:
            if feature.tf is not None and not set(feature.topics) & set(available):
                missing.append(feature.tf.topic)
        if missing:
            users = _topic_users(spec, missing[0])
            raise DataError(
                f"{name}: bag {bag} has no topic {missing[0]} (mapped to {users}); the bag "
                f"records {', '.join(sorted(available)) or 'no topics'}; fix the topic in the "
                "mapping or record it"
            )
        empty = sorted(t for t in required if available[t].msgcount == 0)
        if empty:
            raise DataError(
                f"{name}: topic {empty[0]} in bag {bag} has no messages (mapped to "
                f"{_topic_users(spec, empty[0])}); record it or remove it from the mapping"
            )
        wanted = required | tf_topics
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
            messages[connection.topic].append(
                _Message((when - start_ns) / 1e9, (received_ns - start_ns) / 1e9, msg)
            )
    except CpmpError:
        raise
    except _READ_ERRORS as err:
        raise CpmpFileError(f"cannot read {bag} as a ROS 2 bag: {err}") from None
    finally:
        reader.close()
    return messages, start_ns


def _topic_users(spec: RosbagSpec, topic: str) -> str:
    users = [f"feature {f.name or f.default_prefix}" for f in spec.features if topic in f.topics]
    users += [f"label {lab.variable}" for lab in spec.labels if lab.topic == topic]
    return ", ".join(users)


def _header_ns(msg: object) -> int | None:
    """``header.stamp`` [ns] where the message has one."""
    stamp = getattr(getattr(msg, "header", None), "stamp", None)
    if stamp is None or not hasattr(stamp, "sec"):
        return None
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


# ---------------------------------------------------------------------------- features
def _feature_series(
    feature: TopicFeature,
    messages: dict[str, list[_Message]],
    spec: RosbagSpec,
    demo: str,
    start_ns: int,
) -> _Series:
    """One feature entry's series, read and cleaned."""
    if feature.tf is not None:
        return _tf_series(feature, feature.tf, messages, spec, demo, start_ns)
    assert feature.topic is not None and feature.field is not None  # the spec checked
    if feature.joints is not None:
        return _joint_series(feature, messages[feature.topic], spec, demo)
    return _topic_series(feature, messages[feature.topic], spec, demo)


def _topic_series(
    feature: TopicFeature, messages: list[_Message], spec: RosbagSpec, demo: str
) -> _Series:
    """A field of every message: one series at the messages' stamps."""
    assert feature.topic is not None and feature.field is not None
    where = f"{demo}: topic {feature.topic} field {feature.field}"
    rows = []
    elements: list[str] | None = None
    quaternions: list[int] = []
    for message in messages:
        value = _resolve(message.msg, feature.field, where)
        row, row_elements, row_quaternions = _numeric(value, where)
        if elements is None:
            elements, quaternions = row_elements, row_quaternions
        elif row_elements != elements:
            raise DataError(
                f"{where} changes shape at {message.time:.3f} s ({len(row_elements)} "
                f"element(s) after {len(elements)}); features need the same elements in every "
                "message (pick them with index/slice/joints)"
            )
        rows.append(row)
    assert elements is not None  # topics without messages were refused when reading
    groups = _groups(elements, quaternions, feature.rotation)
    if feature.rotation != "quat" and not quaternions:
        raise DataError(
            f"{where} holds no quaternion ({_QUATERNION}), so rotation: {feature.rotation} has "
            "nothing to convert; map the orientation (e.g. field: pose.orientation) or drop "
            "rotation"
        )
    values = np.asarray(rows, dtype=np.float64)
    times = np.array([m.time for m in messages])
    return _grouped_series(
        feature, f"topic {feature.topic}", times, values, groups, spec, demo, where
    )


def _groups(elements: Sequence[str], quaternions: Sequence[int], rotation: str) -> list[_Group]:
    """Scalar elements one by one; each quaternion (start index) as one converted group."""
    groups = []
    starts = set(quaternions)
    i = 0
    while i < len(elements):
        if i in starts:
            base = elements[i][: -len("x")]  # "orientation.x" -> "orientation."
            converted = tuple(f"{base}{e}" for e in ROTATION_ELEMENTS[rotation])
            groups.append(
                _Group(tuple(range(i, i + 4)), converted, quaternion=True, base=base.rstrip("."))
            )
            i += 4
        else:
            groups.append(_Group((i,), (elements[i],)))
            i += 1
    return groups


def _grouped_series(
    feature: TopicFeature,
    stream_name: str,
    times: np.ndarray,
    values: np.ndarray,
    groups: Sequence[_Group],
    spec: RosbagSpec,
    demo: str,
    where: str,
    moving: bool = True,
    max_gap: float | None = -1.0,
) -> _Series:
    """Pick the feature's elements among ``groups``, check and clean what they need.

    ``max_gap``: as in :func:`clean_stream` (default: the mapping's for a moving series).
    """
    elements = [e for g in groups for e in g.elements]
    owner = [k for k, g in enumerate(groups) for _ in g.elements]
    picked = pick_columns(feature, len(elements), where)
    needed = sorted({owner[i] for i in picked})
    raw = sorted({c for k in needed for c in groups[k].raw})
    bad = np.argwhere(~np.isfinite(values[:, raw]))
    if bad.size:
        raise DataError(
            f"{where} is NaN/inf at {times[int(bad[0][0])]:.3f} s; drop or repair the message"
        )
    if max_gap is not None and max_gap < 0:
        max_gap = spec.max_gap if moving else None
    stream = clean_stream(stream_name, times, values, max_gap)
    position = np.cumsum([0] + [len(g.elements) for g in groups])
    parts: list[_Part] = []
    notes: list[ImportNote] = []
    linear = [k for k in needed if not groups[k].quaternion]
    if linear:
        cols = [c for k in linear for c in groups[k].raw]
        positions = tuple(int(position[k]) + j for k in linear for j in range(len(groups[k].raw)))
        part_stream = dataclasses.replace(stream, values=stream.values[:, cols])
        parts.append(_Part(part_stream, positions, moving=moving))
    for k in needed:
        group = groups[k]
        if not group.quaternion:
            continue
        label = f"{stream_name} {group.base}".rstrip()
        aligned = align_quaternions(stream.values[:, list(group.raw)], f"{demo}: {label}")
        if aligned.n_flips:
            notes.append(
                ImportNote(
                    demo,
                    "flip",
                    stream_name,
                    f"{label}: {aligned.n_flips} quaternion sign flip(s) (q -> -q, the same "
                    "rotation) aligned before interpolation",
                )
            )
        positions = tuple(range(int(position[k]), int(position[k + 1])))
        part_stream = dataclasses.replace(stream, values=aligned.values)
        parts.append(_Part(part_stream, positions, quaternion=True, moving=moving))
    names = column_names(feature, feature.default_prefix, elements, picked, where)
    reports = (stream.report,) if moving else ()
    return _Series(feature, tuple(parts), len(elements), picked, names, reports, tuple(notes))


def _joint_series(
    feature: TopicFeature, messages: list[_Message], spec: RosbagSpec, demo: str
) -> _Series:
    """Joints picked by name: each joint a series at the messages that hold it.

    Several publishers may share the topic (an arm's and a gripper's driver), each message
    holding some joints; joints that appear in the same messages share one series.
    """
    assert feature.topic is not None and feature.field is not None and feature.joints
    where = f"{demo}: topic {feature.topic} field {feature.field}"
    wanted = list(feature.joints)
    samples: dict[str, list[tuple[int, float]]] = {j: [] for j in wanted}
    seen: dict[str, None] = {}
    for k, message in enumerate(messages):
        names = getattr(message.msg, "name", None)
        if not isinstance(names, list):
            raise DataError(
                f"{where}: joints: needs a message with a name list (sensor_msgs/JointState)"
            )
        array = np.asarray(_resolve(message.msg, feature.field, where), dtype=np.float64)
        if array.ndim != 1:
            raise DataError(f"{where} is not a list of numbers; joints: picks from a list")
        seen.update(dict.fromkeys(names))
        if array.size == 0:
            continue  # this publisher does not fill the field (JointState allows it)
        if len(array) != len(names):
            raise DataError(
                f"{where} has {array.size} value(s) for {len(names)} joint name(s) at "
                f"{message.time:.3f} s; each joint needs its value"
            )
        for joint in wanted:
            if joint in names:
                samples[joint].append((k, float(array[names.index(joint)])))
    missing = [j for j in wanted if not samples[j]]
    if missing:
        known = ", ".join(seen) or "none"
        state = "has no value in" if missing[0] in seen else "is in no message of"
        raise DataError(
            f"{where}: joint {missing[0]!r} {state} the topic; the joints seen are {known}; "
            "fix joints: in the mapping"
        )
    by_messages: dict[tuple[int, ...], list[str]] = {}
    for joint in wanted:
        by_messages.setdefault(tuple(k for k, _ in samples[joint]), []).append(joint)
    parts: list[_Part] = []
    reports: list[StreamReport] = []
    for indices, joints in by_messages.items():
        stream_name = f"topic {feature.topic}"
        if len(by_messages) > 1:
            stream_name += f" ({', '.join(joints)})"
        values = np.array([[v for _, v in samples[j]] for j in joints]).T
        times = np.array([messages[k].time for k in indices])
        bad = np.argwhere(~np.isfinite(values))
        if bad.size:
            raise DataError(
                f"{where}: joint {joints[int(bad[0][1])]} is NaN/inf at "
                f"{times[int(bad[0][0])]:.3f} s; drop or repair the message"
            )
        stream = clean_stream(stream_name, times, values, spec.max_gap)
        parts.append(_Part(stream, tuple(wanted.index(j) for j in joints)))
        reports.append(stream.report)
    picked = np.arange(len(wanted))
    names = column_names(feature, feature.default_prefix, wanted, picked, where)
    return _Series(feature, tuple(parts), len(wanted), picked, names, tuple(reports), ())


def _resolve(msg: object, path: str, where: str) -> object:
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


def _numeric(value: object, where: str) -> tuple[list[float], list[str], list[int]]:
    """A number, numeric array or message as values, element names and quaternion starts.

    Element names: ``[""]`` for a number; indices for an array; field paths for a message.
    Quaternion starts: the index of ``x`` of every ``geometry_msgs/Quaternion`` inside.
    """
    if isinstance(value, (bool, int, float, np.integer, np.floating)):
        return [float(value)], [""], []
    if isinstance(value, (np.ndarray, list, tuple)):
        array = np.asarray(value)
        if array.ndim != 1 or array.dtype.kind not in "biuf":
            raise DataError(
                f"{where} is an array of {array.dtype} with shape {array.shape}; features need "
                "numbers"
            )
        return array.astype(np.float64).tolist(), [str(i) for i in range(len(array))], []
    if dataclasses.is_dataclass(value):
        values: list[float] = []
        names: list[str] = []
        quaternions: list[int] = []
        if getattr(value, "__msgtype__", None) == _QUATERNION:
            quaternions.append(0)
        _flatten(value, "", values, names, quaternions)
        if not values:
            raise DataError(f"{where} is a {value.__msgtype__} without numeric fields")
        return values, names, quaternions
    raise DataError(
        f"{where} is a {type(value).__name__}, not a number, numeric array or message of "
        "numbers; map a numeric field"
    )


def _flatten(
    msg: object, prefix: str, values: list[float], names: list[str], quaternions: list[int]
) -> None:
    """Append a message's numeric leaves (headers and strings skipped) in definition order.

    The start index of every ``geometry_msgs/Quaternion`` inside goes to ``quaternions``.
    """
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
            if getattr(value, "__msgtype__", None) == _QUATERNION:
                quaternions.append(len(values))
            _flatten(value, f"{path}.", values, names, quaternions)


# ---------------------------------------------------------------------------------- tf
_TF_ELEMENTS = (
    "translation.x",
    "translation.y",
    "translation.z",
    "rotation.x",
    "rotation.y",
    "rotation.z",
    "rotation.w",
)


@dataclass(frozen=True)
class _Edge:
    """One transform of the tree over time: ``frame`` in its parent.

    Attributes:
        frame: the child frame.
        parent: its parent frame.
        time: (m,) [s] stamps (one sample for a static transform).
        pose: (m, 7) translation then unit quaternion (hemisphere-aligned).
    """

    frame: str
    parent: str
    time: np.ndarray
    pose: np.ndarray

    def at(self, times: np.ndarray) -> np.ndarray:
        """(n, 7) the transform at ``times`` (linear translation, slerp rotation)."""
        if len(self.time) == 1:
            return np.repeat(self.pose, len(times), axis=0)
        translation = interpolate_linear(self.time, self.pose[:, :3], times)
        return np.hstack([translation, interpolate_slerp(self.time, self.pose[:, 3:], times)])


def _tf_series(
    feature: TopicFeature,
    tf: TfFrame,
    messages: dict[str, list[_Message]],
    spec: RosbagSpec,
    demo: str,
    start_ns: int,
) -> _Series:
    """The pose of ``tf.child`` in ``tf.parent``, composed along the tree of transforms.

    A transform is found by its ``child_frame_id`` wherever it sits in a message. The pose is
    sampled at the stamps of every moving transform on the path (the others interpolated
    there), over the time they all cover; a path of static transforms gives a constant.
    """
    where = f"{demo}: feature tf {tf.child!r}"
    topics = f"{tf.topic} and {tf.static_topic}"
    moving: dict[str, list[tuple[float, np.ndarray]]] = {}
    fixed: dict[str, np.ndarray] = {}
    parents: dict[str, dict[str, None]] = {}
    for topic, static in ((tf.topic, False), (tf.static_topic, True)):
        for message in messages.get(topic, []):
            transforms = getattr(message.msg, "transforms", None)
            if not isinstance(transforms, list):
                msgtype = getattr(message.msg, "__msgtype__", type(message.msg).__name__)
                raise DataError(
                    f"{where}: topic {topic} carries {msgtype}, not tf2_msgs/msg/TFMessage; "
                    "give tf: {topic: ...} the topic of the transforms"
                )
            for transform in transforms:
                child = str(transform.child_frame_id).strip("/")
                parent = str(transform.header.frame_id).strip("/")
                parents.setdefault(child, {})[parent] = None
                t, r = transform.transform.translation, transform.transform.rotation
                pose = np.array([t.x, t.y, t.z, r.x, r.y, r.z, r.w], dtype=np.float64)
                if static:
                    fixed[child] = pose  # the last one received holds
                    continue
                stamp = _header_ns(transform) if spec.stamps == "header" else None
                time = message.received if stamp is None else (stamp - start_ns) / 1e9
                moving.setdefault(child, []).append((time, pose))
    for child, options in parents.items():
        if len(options) > 1:
            raise DataError(
                f"{where}: frame {child!r} has several parents on {topics} "
                f"({', '.join(options)}); tf needs a tree, so fix the publishers or pick "
                "another frame"
            )
    parent_of = {child: next(iter(options)) for child, options in parents.items()}
    frames = sorted(set(parent_of) | set(parent_of.values()))
    if tf.child not in parent_of:
        raise DataError(
            f"{where}: no transform has child_frame_id {tf.child!r} on {topics}; the frames "
            f"there are {', '.join(frames) or 'none'}; fix tf.child in the mapping"
        )
    target = tf.parent or parent_of[tf.child]
    if target not in frames:
        raise DataError(
            f"{where}: no frame {target!r} on {topics} (frames: {', '.join(frames)}); fix "
            "tf.parent in the mapping"
        )
    child_chain, target_chain = _up(tf.child, parent_of, where), _up(target, parent_of, where)
    common = next((f for f in child_chain if f in target_chain), None)
    if common is None:
        raise DataError(
            f"{where}: frames {tf.child!r} and {target!r} are not connected on {topics} "
            f"({' -> '.join(reversed(child_chain))}; {' -> '.join(reversed(target_chain))}); "
            "pick a parent frame of the same tree"
        )
    down = child_chain[: child_chain.index(common)]  # edges from common down to the child
    up = target_chain[: target_chain.index(common)]  # edges from common down to the target
    edges: dict[str, _Edge] = {}
    reports: list[StreamReport] = []
    notes: list[ImportNote] = []
    for frame in [*down, *up]:
        name = f"{tf.topic} {parent_of[frame]} -> {frame}"
        if frame in moving:
            times = np.array([t for t, _ in moving[frame]])
            poses = np.array([p for _, p in moving[frame]])
            bad = np.argwhere(~np.isfinite(poses))
            if bad.size:
                raise DataError(
                    f"{where}: transform {parent_of[frame]} -> {frame} is NaN/inf at "
                    f"{times[int(bad[0][0])]:.3f} s; drop or repair the message"
                )
            stream = clean_stream(name, times, poses, spec.max_gap)
            reports.append(stream.report)
        else:
            stream = clean_stream(name, np.zeros(1), fixed[frame][None, :])
        aligned = align_quaternions(stream.values[:, 3:], f"{where}: {name}")
        if aligned.n_flips:
            notes.append(
                ImportNote(
                    demo,
                    "flip",
                    name,
                    f"{name}: {aligned.n_flips} quaternion sign flip(s) (q -> -q, the same "
                    "rotation) aligned before interpolation",
                )
            )
        pose = np.hstack([stream.values[:, :3], aligned.values])
        edges[frame] = _Edge(frame, parent_of[frame], stream.time, pose)
    dynamic = [e for e in edges.values() if e.frame in moving]
    if dynamic:
        first = max(float(e.time[0]) for e in dynamic)
        last = min(float(e.time[-1]) for e in dynamic)
        times = np.unique(np.concatenate([e.time for e in dynamic]))
        times = times[(times >= first) & (times <= last)]
        if not len(times):
            spans = ", ".join(
                f"{e.parent} -> {e.frame} {e.time[0]:.3f}..{e.time[-1]:.3f} s" for e in dynamic
            )
            raise DataError(
                f"{where}: the moving transforms from {target!r} to {tf.child!r} do not "
                f"overlap in time ({spans}); check their stamps"
            )
    else:
        times = np.zeros(1)
    pose = _compose(times, [edges[f] for f in down], [edges[f] for f in up])
    groups = [
        *(_Group((i,), (e,)) for i, e in enumerate(_TF_ELEMENTS[:3])),
        _Group(
            (3, 4, 5, 6),
            tuple(f"rotation.{e}" for e in ROTATION_ELEMENTS[feature.rotation]),
            quaternion=True,
            base="rotation",
        ),
    ]
    series = _grouped_series(
        feature,
        f"tf {tf.child} in {target}",
        times,
        pose,
        groups,
        spec,
        demo,
        where,
        moving=bool(dynamic),
        max_gap=None,
    )
    return dataclasses.replace(series, reports=tuple(reports), notes=tuple(notes) + series.notes)


def _up(frame: str, parent_of: dict[str, str], where: str) -> list[str]:
    """``frame``, its parent, its parent's parent, ... up to the root."""
    chain = [frame]
    while chain[-1] in parent_of:
        parent = parent_of[chain[-1]]
        if parent in chain:
            raise DataError(
                f"{where}: the transforms form a loop ({' -> '.join([*chain, parent])}); tf "
                "needs a tree, fix the publishers"
            )
        chain.append(parent)
    return chain


def _compose(times: np.ndarray, down: Sequence[_Edge], up: Sequence[_Edge]) -> np.ndarray:
    """(n, 7) the child in the target frame: ``inverse(common->target) * common->child``.

    ``down`` lists the edges from the child up to the common ancestor, ``up`` those from the
    target up to it.
    """

    def chain(edges: Sequence[_Edge]) -> np.ndarray:
        pose = np.tile([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0], (len(times), 1))
        for edge in reversed(edges):  # from the common ancestor down
            pose = _pose_product(pose, edge.at(times))
        return pose

    return _pose_product(_pose_inverse(chain(up)), chain(down))


def _quaternion_product(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(n, 4) Hamilton products ``a * b`` of ``x, y, z, w`` quaternions."""
    ax, ay, az, aw = a.T
    bx, by, bz, bw = b.T
    return np.column_stack(
        [
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        ]
    )


def _rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(n, 3) vectors ``v`` rotated by unit quaternions ``q``."""
    u, w = q[:, :3], q[:, 3:]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def _pose_product(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(n, 7) ``a * b``: pose ``b`` (in frame ``a``'s child) expressed in ``a``'s parent."""
    translation = a[:, :3] + _rotate(a[:, 3:], b[:, :3])
    return np.hstack([translation, _quaternion_product(a[:, 3:], b[:, 3:])])


def _pose_inverse(a: np.ndarray) -> np.ndarray:
    """(n, 7) the inverse transforms."""
    conjugate = a[:, 3:] * np.array([-1.0, -1.0, -1.0, 1.0])
    return np.hstack([-_rotate(conjugate, a[:, :3]), conjugate])


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


def _is_interrupted(path: Path, *, named: bool) -> bool:
    """A directory with rosbag2 storage files but no ``metadata.yaml``.

    With ``named``, every storage file must be named after the directory
    (``<dir>.db3``, ``<dir>_0.mcap``: what ``ros2 bag record`` and rosbags write), which
    tells an interrupted bag from a folder of single-file bags.
    """
    if not path.is_dir() or (path / "metadata.yaml").exists():
        return False
    files = [p for p in path.iterdir() if p.is_file() and p.suffix in _BAG_FILES]
    if not files:
        return False
    if not named:
        return True
    pattern = re.compile(rf"{re.escape(path.name)}(_\d+)?")
    return all(pattern.fullmatch(p.stem) for p in files)


def _natural_key(path: Path) -> list[int | str]:
    return [int(p) if p.isdigit() else p for p in re.split(r"(\d+)", path.name)]


__all__ = ["FALLBACK_TYPESTORE", "bag_demo_names", "find_bags", "read_bag", "read_rosbags"]
