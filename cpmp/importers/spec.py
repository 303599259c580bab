"""The mapping records of ``cpmp-import``.

They say which parts of a recording become features and which give the active movement
primitive (MP) of each control variable.

A mapping is written in YAML (or given as a dict) with a ``source`` key naming the importer
(``rosbag``, ``lerobot`` or ``mimicgen``) and that importer's options; :func:`load_mapping`
turns it into a :class:`RosbagSpec`, :class:`LeRobotSpec` or :class:`MimicGenSpec`. Every
record validates itself on construction and raises :class:`~cpmp.errors.ConfigError` naming
the entry and the fix; an unknown key is an error (a typo never silently drops a feature).
``docs/importing.md`` documents every key with a worked example per source.
"""

from __future__ import annotations

import dataclasses
import math
import os
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal, TypeVar

import yaml

from cpmp.errors import ConfigError, CpmpFileError

SOURCES = ("rosbag", "lerobot", "mimicgen")
"""The recording formats :func:`load_mapping` knows."""

ON_ERROR = ("raise", "skip")
"""What a demonstration that cannot be imported does: refuse the import, or be skipped."""

T = TypeVar("T")


# ----------------------------------------------------------------------------- small checks
def _text(value: object, what: str) -> str:
    if not isinstance(value, str) or not value.strip():
        raise ConfigError(f"{what} must be a non-empty string, got {value!r}")
    return value


def _optional_text(value: object, what: str) -> str | None:
    return None if value is None else _text(value, what)


def _texts(value: object, what: str) -> tuple[str, ...] | None:
    if value is None:
        return None
    if isinstance(value, str) or not isinstance(value, Sequence):
        raise ConfigError(f"{what} must be a list of strings, got {value!r}")
    items = tuple(_text(v, f"{what}[{i}]") for i, v in enumerate(value))
    if not items:
        raise ConfigError(f"{what} is an empty list; leave it out or give at least one entry")
    repeated = sorted({v for v in items if items.count(v) > 1})
    if repeated:
        raise ConfigError(f"{what} repeats {', '.join(repeated)}; give each entry once")
    return items


def _positive(value: object, what: str, *, allow_none: bool = False) -> float | None:
    if value is None and allow_none:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ConfigError(f"{what} must be a finite number, got {value!r}")
    if value <= 0:
        raise ConfigError(f"{what} must be > 0, got {value}")
    return float(value)


def _non_negative(value: object, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ConfigError(f"{what} must be a finite number, got {value!r}")
    if value < 0:
        raise ConfigError(f"{what} must be >= 0, got {value}")
    return float(value)


def _integers(value: object, what: str) -> tuple[int, ...] | None:
    if value is None:
        return None
    if isinstance(value, str) or not isinstance(value, Sequence) or not value:
        raise ConfigError(f"{what} must be a non-empty list of integers, got {value!r}")
    for i, v in enumerate(value):
        if isinstance(v, bool) or not isinstance(v, int):
            raise ConfigError(f"{what}[{i}] must be an integer, got {v!r}")
    return tuple(int(v) for v in value)


def _choice(value: object, choices: Sequence[str], what: str) -> str:
    if value not in choices:
        raise ConfigError(f"{what} must be one of {', '.join(choices)}, got {value!r}")
    return str(value)


def _rename(value: object, what: str) -> dict[str, str]:
    if value is None:
        return {}
    if not isinstance(value, Mapping):
        raise ConfigError(f"{what} must be a mapping {{label in the recording: MP name}}")
    return {_text(str(k), f"{what} key"): _text(v, f"{what}[{k!r}]") for k, v in value.items()}


# ------------------------------------------------------------------------------- features
DERIVED = ("velocity",)
"""What a LeRobot or MimicGen feature entry can derive from its elements (``derive:``)."""


def _check_derive(value: object, where: str) -> None:
    if value is not None:
        _choice(value, DERIVED, f"{where}: derive")


@dataclass(frozen=True, kw_only=True)
class Selection:
    """Which elements of an array-valued source become feature columns, and their names.

    Attributes:
        index: element indices to keep, in this order (``None``: all elements).
        slice: ``(start, stop)`` elements ``start .. stop - 1`` (exclusive with ``index``).
        names: one feature name per kept element (default: ``<name>.<element>``).
        name: the prefix of the default names (default: derived from the source's path).
    """

    index: tuple[int, ...] | None = None
    slice: tuple[int, int] | None = None
    names: tuple[str, ...] | None = None
    name: str | None = None

    def _check_selection(self, where: str) -> None:
        object.__setattr__(self, "index", _integers(self.index, f"{where}: index"))
        if self.slice is not None:
            bounds = _integers(self.slice, f"{where}: slice")
            if bounds is None or len(bounds) != 2 or not 0 <= bounds[0] < bounds[1]:
                raise ConfigError(
                    f"{where}: slice must be [start, stop] with 0 <= start < stop, "
                    f"got {self.slice!r}"
                )
            object.__setattr__(self, "slice", (bounds[0], bounds[1]))
        if self.index is not None and self.slice is not None:
            raise ConfigError(f"{where}: give index or slice, not both")
        object.__setattr__(self, "names", _texts(self.names, f"{where}: names"))
        object.__setattr__(self, "name", _optional_text(self.name, f"{where}: name"))
        if self.names is not None:
            wanted = self.width
            if wanted is not None and wanted != len(self.names):
                raise ConfigError(
                    f"{where}: names has {len(self.names)} entries but {wanted} elements are "
                    "selected; give one name per selected element"
                )

    @property
    def width(self) -> int | None:
        """The number of selected elements where the selection fixes it, else ``None``."""
        if self.index is not None:
            return len(self.index)
        if self.slice is not None:
            return self.slice[1] - self.slice[0]
        return None


ROTATIONS = ("quat", "rotvec", "matrix6")
"""How a rotation becomes feature columns: ``quat`` the unit quaternion ``x, y, z, w``
(hemisphere-aligned, so continuous), ``rotvec`` the rotation vector (axis times angle
[rad]), ``matrix6`` the first two columns of the rotation matrix (Zhou et al.'s continuous
6-D representation)."""


@dataclass(frozen=True, kw_only=True)
class TfFrame:
    """An object's pose from the transform tree (``tf2_msgs/TFMessage`` on ``/tf``).

    Attributes:
        child: the frame whose pose is wanted (a transform's ``child_frame_id``), found in
            every message whatever its index among the message's transforms.
        parent: the frame to express it in; transforms along the tree are composed (box in
            world through world -> table -> box). ``None``: the child's own transform as
            published (its ``header.frame_id``).
        topic: the topic of the moving transforms.
        static_topic: the topic of the fixed ones (read when the bag has it).
    """

    child: str
    parent: str | None = None
    topic: str = "/tf"
    static_topic: str = "/tf_static"

    def __post_init__(self) -> None:
        where = "mapping feature tf"
        object.__setattr__(self, "child", _text(self.child, f"{where}: child").strip("/"))
        parent = _optional_text(self.parent, f"{where}: parent")
        object.__setattr__(self, "parent", None if parent is None else parent.strip("/"))
        _text(self.topic, f"{where}: topic")
        _text(self.static_topic, f"{where}: static_topic")
        if self.parent == self.child:
            raise ConfigError(f"{where}: parent and child are both {self.child!r}; give two frames")


@dataclass(frozen=True, kw_only=True)
class TopicFeature(Selection):
    """Features from one field of one ROS 2 topic's messages, or a pose from ``/tf``.

    Attributes:
        topic: the topic (``/joint_states``); not with ``tf``.
        field: dotted path into the message (``position``, ``pose.position``, ``data``; default
            ``data``); a number gives one column, a numeric array one per element, a message
            one per numeric field (``pose.position`` -> ``x, y, z``) in definition order.
        joints: for ``sensor_msgs/JointState``-like messages, pick elements by joint name.
            Each joint is its own series, sampled at the messages that hold it (several
            publishers on one topic, each with some of the joints).
        tf: instead of ``topic``: a frame's pose from the transform tree (elements
            ``translation.x, .y, .z`` then the rotation's).
        rotation: how every quaternion (``geometry_msgs/Quaternion``) of the feature becomes
            columns (:data:`ROTATIONS`); quaternions are always hemisphere-aligned and
            interpolated by slerp. ``index``/``slice`` pick among the converted elements.
    """

    topic: str | None = None
    field: str | None = None
    joints: tuple[str, ...] | None = None
    tf: TfFrame | None = None
    rotation: Literal["quat", "rotvec", "matrix6"] = "quat"

    def __post_init__(self) -> None:
        if self.tf is not None and not isinstance(self.tf, TfFrame):
            object.__setattr__(self, "tf", _build(TfFrame, self.tf, "mapping feature tf"))
        if (self.topic is None) == (self.tf is None):
            raise ConfigError(
                "mapping feature: give topic (a topic's message field) or tf: {child: <frame>, "
                "parent: <frame>} (a pose from /tf), exactly one"
            )
        _choice(self.rotation, ROTATIONS, "mapping feature: rotation")
        if self.tf is not None:
            where = f"mapping feature tf {self.tf.child!r}"
            if self.field is not None or self.joints is not None:
                raise ConfigError(
                    f"{where}: field and joints are for topic features; a tf feature's "
                    "elements are translation.x, .y, .z and the rotation's (pick with index or "
                    "slice)"
                )
            self._check_selection(where)
            return
        where = f"mapping feature on topic {self.topic!r}"
        _text(self.topic, "mapping feature: topic")
        object.__setattr__(self, "field", _text(self.field or "data", f"{where}: field"))
        object.__setattr__(self, "joints", _texts(self.joints, f"{where}: joints"))
        if self.joints is not None and (self.index is not None or self.slice is not None):
            raise ConfigError(f"{where}: give joints, index or slice, not several")
        self._check_selection(where)
        if (
            self.joints is not None
            and self.names is not None
            and len(self.names) != len(self.joints)
        ):
            raise ConfigError(f"{where}: names must have one entry per joint")

    @property
    def width(self) -> int | None:
        """The number of selected elements (joints and tf poses count too), else ``None``."""
        if self.joints is not None:
            return len(self.joints)
        if self.tf is not None and self.index is None and self.slice is None:
            return 3 + {"quat": 4, "rotvec": 3, "matrix6": 6}[self.rotation]
        return super().width

    @property
    def topics(self) -> tuple[str, ...]:
        """The topics the feature reads (``/tf`` and ``/tf_static`` for a tf feature)."""
        if self.tf is not None:
            return (self.tf.topic, self.tf.static_topic)
        assert self.topic is not None
        return (self.topic,)

    @property
    def default_prefix(self) -> str:
        """The prefix of default feature names.

        ``<topic without leading slash, / as .>.<field>`` (``joint_states.position``), or
        ``tf.<child>`` for a tf feature.
        """
        if self.tf is not None:
            return f"tf.{self.tf.child}"
        assert self.topic is not None
        return f"{self.topic.strip('/').replace('/', '.')}.{self.field}"


@dataclass(frozen=True, kw_only=True)
class ColumnFeature(Selection):
    """Features from one column of a LeRobot dataset's frames (``observation.state``).

    Attributes:
        column: the column; a number gives one feature, a fixed-length list one per element.
        derive: ``velocity``: the features are the time derivatives of the selected elements
            (central differences over each episode's frames, before any resampling), named
            ``<name>.<element>.vel`` unless ``names`` is given; ``None``: the values.
    """

    column: str
    derive: Literal["velocity"] | None = None

    def __post_init__(self) -> None:
        _text(self.column, "mapping feature: column")
        where = f"mapping feature column {self.column!r}"
        _check_derive(self.derive, where)
        self._check_selection(where)

    @property
    def default_prefix(self) -> str:
        """The column's name: the prefix of default feature names."""
        return self.column


@dataclass(frozen=True, kw_only=True)
class KeyFeature(Selection):
    """Features from one dataset of every robomimic/MimicGen demo group (``obs/object``).

    Attributes:
        key: path of the dataset inside ``/data/demo_<i>``, shape ``(T,)``, ``(T, k)`` or
            ``(T, a, b)`` (flattened row-major, e.g. a 4x4 pose matrix).
        derive: ``velocity``: the time derivatives of the selected elements (central
            differences over the demo's steps at the mapping's ``rate``), named
            ``<name>.<element>.vel`` unless ``names`` is given; ``None``: the values.
    """

    key: str
    derive: Literal["velocity"] | None = None

    def __post_init__(self) -> None:
        _text(self.key, "mapping feature: key")
        where = f"mapping feature key {self.key!r}"
        _check_derive(self.derive, where)
        self._check_selection(where)

    @property
    def default_prefix(self) -> str:
        """The key with ``.`` for ``/`` (``obs.robot0_eef_pos``)."""
        return self.key.strip("/").replace("/", ".")


# --------------------------------------------------------------------------------- labels
@dataclass(frozen=True, kw_only=True)
class LabelNames:
    """How recorded label values become MP names.

    Attributes:
        variable: the control variable these labels belong to.
        names: MP name of integer id ``i`` (``names[i]``), for integer-valued labels.
        rename: recorded label -> MP name (applied after ``names``), e.g. LeRobot subtask
            sentences to short MP names.
        mps: the allowed MP names (after renaming); another value is an error naming where it
            was recorded. ``None``: any name.
    """

    variable: str
    names: tuple[str, ...] | None = None
    rename: Mapping[str, str] = field(default_factory=dict)
    mps: tuple[str, ...] | None = None

    def _check_names(self, where: str) -> None:
        if "/" in _text(self.variable, f"{where}: variable") or self.variable == ".":
            raise ConfigError(f"{where}: control variable {self.variable!r} must not contain '/'")
        object.__setattr__(self, "names", _texts(self.names, f"{where}: names"))
        object.__setattr__(self, "rename", _rename(self.rename, f"{where}: rename"))
        object.__setattr__(self, "mps", _texts(self.mps, f"{where}: mps"))


@dataclass(frozen=True, kw_only=True)
class TopicLabel(LabelNames):
    """The active MP of one control variable from a ROS 2 topic.

    Attributes:
        topic: the topic.
        kind: ``state``: every message names the active MP (``std_msgs/String``), held until
            the next one (zero-order hold); ``events``: every message marks a switch.
        field: the message field holding the MP name (``state``; ``events`` without
            ``sequence``: the MP switched to).
        sequence: ``events`` only: the MPs in order, the first active from the start and one
            more per event (any message type, e.g. ``std_msgs/Empty``).
        initial: ``events`` without ``sequence``: the MP active before the first event.
    """

    topic: str
    kind: Literal["state", "events"] = "state"
    field: str = "data"
    sequence: tuple[str, ...] | None = None
    initial: str | None = None

    def __post_init__(self) -> None:
        where = f"mapping label {self.variable!r}"
        self._check_names(where)
        _text(self.topic, f"{where}: topic")
        _choice(self.kind, ("state", "events"), f"{where}: kind")
        _text(self.field, f"{where}: field")
        if self.sequence is not None:
            seq = self.sequence
            if isinstance(seq, str) or not isinstance(seq, Sequence) or len(seq) < 2:
                raise ConfigError(
                    f"{where}: sequence must list at least two MPs (the first active from the "
                    f"start, one more per event), got {seq!r}"
                )
            object.__setattr__(
                self,
                "sequence",
                tuple(_text(v, f"{where}: sequence[{i}]") for i, v in enumerate(seq)),
            )
        object.__setattr__(self, "initial", _optional_text(self.initial, f"{where}: initial"))
        if self.kind == "state" and (self.sequence is not None or self.initial is not None):
            raise ConfigError(
                f"{where}: sequence and initial are for kind: events; a state topic names the "
                "active MP in every message"
            )
        if self.kind == "events" and (self.sequence is None) == (self.initial is None):
            raise ConfigError(
                f"{where}: an events topic needs either sequence: [first MP, MP after event 1, "
                "...] or initial: <MP before the first event> with the MP switched to in "
                "the message's field"
            )


LANGUAGE_STYLES = ("subtask", "motion")
"""The ``language_persistent`` styles (lerobot >= 0.6) that can label a control variable."""

SARM_KINDS = ("sparse", "dense")
"""The SARM annotation sets in ``meta/episodes`` (``<kind>_subtask_names``, ...)."""


@dataclass(frozen=True, kw_only=True)
class ColumnLabel(LabelNames):
    """The active MP of one control variable of a LeRobot dataset.

    Exactly one of ``column``, ``language`` and ``sarm`` says where it is recorded.

    Attributes:
        column: a per-frame string column (MP names) or an integer column with ``names``;
            ``subtask_index`` (lerobot 0.4.4 - 0.5.x) takes its names from
            ``meta/subtasks.parquet`` unless ``names`` is given.
        language: a style of the ``language_persistent`` column (lerobot >= 0.6):
            ``subtask`` or ``motion``; each row of that style names the MP (its ``content``)
            active from its ``timestamp`` until the next row of the style.
        sarm: SARM's subtask annotations in ``meta/episodes`` (``sparse`` or ``dense``):
            ``<sarm>_subtask_names`` name the MPs, each active from its
            ``<sarm>_subtask_start_frames`` entry until the next one starts (the first from
            the episode's first frame).
    """

    column: str | None = None
    language: str | None = None
    sarm: str | None = None

    def __post_init__(self) -> None:
        where = f"mapping label {self.variable!r}"
        self._check_names(where)
        given = [k for k in ("column", "language", "sarm") if getattr(self, k) is not None]
        if len(given) != 1:
            raise ConfigError(
                f"{where}: give exactly one of column: <per-frame column>, language: "
                f"<{' | '.join(LANGUAGE_STYLES)}> (language_persistent, lerobot >= 0.6) or sarm: "
                f"<{' | '.join(SARM_KINDS)}> (SARM annotations in meta/episodes); got "
                f"{', '.join(given) or 'none'}"
            )
        if self.column is not None:
            _text(self.column, f"{where}: column")
        if self.language is not None:
            _choice(self.language, LANGUAGE_STYLES, f"{where}: language")
        if self.sarm is not None:
            _choice(self.sarm, SARM_KINDS, f"{where}: sarm")

    @property
    def source(self) -> str:
        """Where the labels are read, for messages (``column left_arm_mp``, ...)."""
        if self.language is not None:
            return f"language_persistent (style {self.language})"
        if self.sarm is not None:
            return f"SARM {self.sarm}_subtask_* annotations"
        return f"column {self.column}"


@dataclass(frozen=True)
class Subtask:
    """One subtask of an effector in a MimicGen-style file.

    Attributes:
        mp: the MP name this subtask becomes.
        signal: the termination signal (dataset under the signals group) whose first 0 -> 1
            transition ends this subtask; ``None`` for the effector's last subtask, which
            runs to the end of the demonstration.
    """

    mp: str
    signal: str | None = None

    def __post_init__(self) -> None:
        _text(self.mp, "mapping subtask: mp")
        _optional_text(self.signal, f"mapping subtask {self.mp!r}: signal")


@dataclass(frozen=True, kw_only=True)
class EffectorLabel(LabelNames):
    """The active MP of one control variable (an effector) in a robomimic/MimicGen file.

    Attributes:
        subtasks: the effector's subtasks in order; every one but the last names the
            termination signal that ends it.
        dataset: instead of subtasks, a per-step label dataset inside the demo group (strings,
            or integers with ``names``).
    """

    subtasks: tuple[Subtask, ...] | None = None
    dataset: str | None = None

    def __post_init__(self) -> None:
        where = f"mapping label {self.variable!r}"
        self._check_names(where)
        object.__setattr__(self, "dataset", _optional_text(self.dataset, f"{where}: dataset"))
        if (self.subtasks is None) == (self.dataset is None):
            raise ConfigError(
                f"{where}: give subtasks: [{{mp: ..., signal: ...}}, ...] (termination signals) "
                "or dataset: <per-step label dataset>, exactly one"
            )
        if self.subtasks is not None:
            tasks = self.subtasks
            if isinstance(tasks, str) or not isinstance(tasks, Sequence) or not tasks:
                raise ConfigError(f"{where}: subtasks must be a non-empty list")
            tasks = tuple(
                t if isinstance(t, Subtask) else _build(Subtask, t, f"{where}: subtasks[{i}]")
                for i, t in enumerate(tasks)
            )
            for i, task in enumerate(tasks[:-1]):
                if task.signal is None:
                    raise ConfigError(
                        f"{where}: subtask {i} ({task.mp!r}) has no signal; every subtask but "
                        "the last needs the termination signal that ends it"
                    )
            if tasks[-1].signal is not None:
                raise ConfigError(
                    f"{where}: the last subtask ({tasks[-1].mp!r}) runs to the end of the demo; "
                    f"remove its signal {tasks[-1].signal!r} (or add the subtask that follows)"
                )
            signals = [t.signal for t in tasks[:-1]]
            repeated = sorted({s for s in signals if signals.count(s) > 1})
            if repeated:
                raise ConfigError(
                    f"{where}: signal(s) {', '.join(map(str, repeated))} end two subtasks"
                )
            object.__setattr__(self, "subtasks", tasks)


# ---------------------------------------------------------------------------------- specs
@dataclass(frozen=True, kw_only=True)
class _SourceSpec:
    """Options every importer has.

    Attributes:
        min_activation: [s] label activations shorter than this are glitches: each is merged
            into the activation before it (the first into the one after) and reported.
            0 keeps every activation.
        on_gap: ``report`` gaps longer than ``max_gap`` in the summary, or make them an
            ``error``.
        on_error: ``raise``: a demonstration that cannot be imported refuses the whole import
            (nothing is written); ``skip``: it is left out and reported (the summary and
            ``<output>.skipped.json``), the others are imported. Errors that concern every
            demonstration (the mapping, a missing input) always refuse the import.
    """

    min_activation: float = 0.0
    on_gap: Literal["report", "error"] = "report"
    on_error: Literal["raise", "skip"] = "raise"

    def _check_common(
        self,
        features: Sequence[Selection],
        labels: Sequence[LabelNames],
        feature_kind: type[Selection],
        label_kind: type[LabelNames],
    ) -> None:
        object.__setattr__(
            self, "min_activation", _non_negative(self.min_activation, "min_activation")
        )
        _choice(self.on_gap, ("report", "error"), "on_gap")
        _choice(self.on_error, ON_ERROR, "on_error")
        if not features:
            raise ConfigError("the mapping has no features; map at least one source to features")
        if not labels:
            raise ConfigError("the mapping has no labels; map at least one control variable")
        variables = [label.variable for label in labels]
        repeated = sorted({v for v in variables if variables.count(v) > 1})
        if repeated:
            raise ConfigError(f"labels map control variable(s) {', '.join(repeated)} twice")
        object.__setattr__(self, "features", tuple(features))
        object.__setattr__(self, "labels", tuple(labels))
        explicit = [n for f in features if f.names for n in f.names]
        repeated = sorted({n for n in explicit if explicit.count(n) > 1})
        if repeated:
            raise ConfigError(
                f"feature name(s) {', '.join(repeated)} given twice; names must be unique"
            )
        for item in features:
            if not isinstance(item, feature_kind):
                raise ConfigError(
                    f"{type(self).__name__} features must be {feature_kind.__name__}, "
                    f"got {type(item).__name__}"
                )
        for item in labels:
            if not isinstance(item, label_kind):
                raise ConfigError(
                    f"{type(self).__name__} labels must be {label_kind.__name__}, "
                    f"got {type(item).__name__}"
                )


@dataclass(frozen=True, kw_only=True)
class RosbagSpec(_SourceSpec):
    """How to read ROS 2 bags (rosbag2, sqlite3 or MCAP storage): one bag is one demonstration.

    Attributes:
        features: topics and fields that become features.
        labels: one topic per control variable.
        rate: [Hz] the common clock every topic is resampled onto (linear interpolation for
            features, slerp for quaternions, zero-order hold for labels). It spans the time
            every feature series and every state label topic covers (a note names the topic
            that cut the recording short, and by how much).
        stamps: ``header``: a message's ``header.stamp`` where it has a header (the receive
            time where it has none); ``receive``: the time the bag recorded it.
        max_gap: [s] a topic silent for longer than this is reported (``on_gap``).
    """

    features: tuple[TopicFeature, ...]
    labels: tuple[TopicLabel, ...]
    rate: float
    stamps: Literal["header", "receive"] = "header"
    max_gap: float = 0.5

    def __post_init__(self) -> None:
        self._check_common(self.features, self.labels, TopicFeature, TopicLabel)
        object.__setattr__(self, "rate", _positive(self.rate, "rosbag mapping: rate [Hz]"))
        _choice(self.stamps, ("header", "receive"), "rosbag mapping: stamps")
        object.__setattr__(self, "max_gap", _positive(self.max_gap, "rosbag mapping: max_gap [s]"))


@dataclass(frozen=True, kw_only=True)
class LeRobotSpec(_SourceSpec):
    """How to read a LeRobot v3 dataset on disk: one episode is one demonstration.

    Attributes:
        features: columns that become features.
        labels: one label source per control variable: a per-frame column (or
            ``subtask_index``), a ``language_persistent`` style or SARM annotations.
        rate: [Hz] resample onto this clock; ``None`` keeps the recorded frames.
        episodes: episode indices to import (``None``: all).
        max_gap: [s] frames further apart are reported; ``None``: 1.5 frame periods.
    """

    features: tuple[ColumnFeature, ...]
    labels: tuple[ColumnLabel, ...]
    rate: float | None = None
    episodes: tuple[int, ...] | None = None
    max_gap: float | None = None

    def __post_init__(self) -> None:
        self._check_common(self.features, self.labels, ColumnFeature, ColumnLabel)
        object.__setattr__(
            self, "rate", _positive(self.rate, "lerobot mapping: rate [Hz]", allow_none=True)
        )
        object.__setattr__(self, "episodes", _integers(self.episodes, "lerobot mapping: episodes"))
        object.__setattr__(
            self,
            "max_gap",
            _positive(self.max_gap, "lerobot mapping: max_gap [s]", allow_none=True),
        )


@dataclass(frozen=True, kw_only=True)
class MimicGenSpec(_SourceSpec):
    """How to read a robomimic-style HDF5 file (MimicGen, DexMimicGen, Isaac Lab Mimic).

    One ``/data/demo_<i>`` group is one demonstration.

    Attributes:
        features: datasets inside each demo group that become features.
        labels: one effector (control variable) each.
        rate: [Hz] the control rate the steps were recorded at (robomimic files store no
            time; robosuite's default is 20 Hz).
        signals: the group of termination signals inside each demo; ``None`` looks in
            ``datagen_info/subtask_term_signals`` (MimicGen) then
            ``obs/datagen_info/subtask_term_signals`` (Isaac Lab Mimic).
        demos: demo group names to import (``None``: all).
        mask: import only the demos in the file's ``/mask/<mask>`` (e.g. ``train``).
    """

    features: tuple[KeyFeature, ...]
    labels: tuple[EffectorLabel, ...]
    rate: float
    signals: str | None = None
    demos: tuple[str, ...] | None = None
    mask: str | None = None

    def __post_init__(self) -> None:
        self._check_common(self.features, self.labels, KeyFeature, EffectorLabel)
        object.__setattr__(self, "rate", _positive(self.rate, "mimicgen mapping: rate [Hz]"))
        object.__setattr__(
            self, "signals", _optional_text(self.signals, "mimicgen mapping: signals")
        )
        object.__setattr__(self, "demos", _texts(self.demos, "mimicgen mapping: demos"))
        object.__setattr__(self, "mask", _optional_text(self.mask, "mimicgen mapping: mask"))
        if self.demos is not None and self.mask is not None:
            raise ConfigError("mimicgen mapping: give demos or mask, not both")


ImportSpec = RosbagSpec | LeRobotSpec | MimicGenSpec
"""A parsed mapping, one record per source."""


@dataclass(frozen=True)
class SplitSpec:
    """How imported demonstrations are split into ``mask/train`` and ``mask/test``.

    Attributes:
        test_fraction: fraction of demonstrations held out for testing, drawn at random with
            ``seed`` (rounded to the nearest count; at least one when > 0, and at least one
            demonstration always stays in train). 0: every demonstration trains.
        seed: seed of the draw (the same seed and inputs give the same split).
        test: names of the demonstrations to hold out instead of a random draw.
    """

    test_fraction: float = 0.0
    seed: int = 0
    test: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        fraction = _non_negative(self.test_fraction, "split: test_fraction")
        if fraction >= 1:
            raise ConfigError(
                f"split: test_fraction must be < 1 (some demonstrations must train), got {fraction}"
            )
        object.__setattr__(self, "test_fraction", fraction)
        if isinstance(self.seed, bool) or not isinstance(self.seed, int):
            raise ConfigError(f"split: seed must be an integer, got {self.seed!r}")
        test = None if self.test is None or len(self.test) == 0 else self.test
        object.__setattr__(self, "test", _texts(test, "split: test") or ())
        if self.test and self.test_fraction:
            raise ConfigError("split: give test (names) or test_fraction, not both")


# ------------------------------------------------------------------------------- loading
_FEATURES: dict[str, type] = {
    "rosbag": TopicFeature,
    "lerobot": ColumnFeature,
    "mimicgen": KeyFeature,
}
_LABELS: dict[str, type] = {"rosbag": TopicLabel, "lerobot": ColumnLabel, "mimicgen": EffectorLabel}
_SPECS: dict[str, type] = {"rosbag": RosbagSpec, "lerobot": LeRobotSpec, "mimicgen": MimicGenSpec}


def _build(cls: type[T], data: object, where: str, **extra: object) -> T:
    """``cls(**data, **extra)`` with unknown keys and wrong types as :class:`ConfigError`."""
    if not isinstance(data, Mapping):
        raise ConfigError(f"{where} must be a mapping of options, got {data!r}")
    known = [f.name for f in dataclasses.fields(cls) if f.init and f.name not in extra]  # type: ignore[arg-type]
    unknown = sorted(str(k) for k in data if k not in known)
    if unknown:
        raise ConfigError(
            f"{where}: unknown key(s) {', '.join(unknown)}; known keys: {', '.join(known)}"
        )
    values = {str(k): _plain(v) for k, v in data.items()}
    try:
        return cls(**values, **extra)
    except TypeError as err:
        raise ConfigError(f"{where}: {err}") from None


def _plain(value: object) -> object:
    """Lists (also OmegaConf ones) as tuples, mappings as dicts, recursively."""
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, Sequence) and not isinstance(value, str):
        return tuple(_plain(v) for v in value)
    return value


def parse_mapping(data: Mapping[str, object], where: str = "mapping") -> ImportSpec:
    """Build the spec of ``data`` (a mapping as :func:`load_mapping` reads it from YAML).

    Args:
        data: ``{"source": "rosbag" | "lerobot" | "mimicgen", "features": [...], "labels":
            {variable: {...}}, ...}``.
        where: how messages name ``data`` (its file).

    Raises:
        ConfigError: an unknown source or key, a missing or invalid value.
    """
    if not isinstance(data, Mapping):
        raise ConfigError(f"{where} must be a mapping with a source key, got {type(data).__name__}")
    source = data.get("source")
    if source not in SOURCES:
        raise ConfigError(f"{where}: source must be one of {', '.join(SOURCES)}, got {source!r}")
    options = {str(k): v for k, v in data.items() if k != "source"}
    features = options.pop("features", None)
    labels = options.pop("labels", None)
    if isinstance(features, str) or not isinstance(features, Sequence) or not features:
        raise ConfigError(f"{where}: features must be a non-empty list of feature entries")
    if not isinstance(labels, Mapping) or not labels:
        raise ConfigError(f"{where}: labels must map each control variable to its label source")
    parsed_features = tuple(
        _build(_FEATURES[source], f, f"{where}: features[{i}]") for i, f in enumerate(features)
    )
    parsed_labels = tuple(
        _build(_LABELS[source], spec, f"{where}: labels.{variable}", variable=str(variable))
        for variable, spec in labels.items()
    )
    return _build(_SPECS[source], options, where, features=parsed_features, labels=parsed_labels)


def load_mapping(mapping: str | os.PathLike[str] | Mapping[str, object]) -> ImportSpec:
    """Read a mapping from a YAML file (or take it as a dict) and validate it.

    Raises:
        CpmpFileError: the file is missing or not YAML.
        ConfigError: the mapping is invalid (see :func:`parse_mapping`).
    """
    if isinstance(mapping, Mapping):
        return parse_mapping(mapping)
    path = Path(mapping)
    if not path.is_file():
        raise CpmpFileError(f"mapping file {path} does not exist; give the YAML mapping's path")
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as err:
        raise CpmpFileError(f"cannot read mapping file {path}: {err}") from err
    except yaml.YAMLError as err:
        raise ConfigError(f"mapping file {path} is not valid YAML: {_one_line(str(err))}") from None
    return parse_mapping(data, where=str(path))


def _one_line(text: str) -> str:
    return re.sub(r"\s+", " ", text).strip()


__all__ = [
    "DERIVED",
    "LANGUAGE_STYLES",
    "ON_ERROR",
    "SARM_KINDS",
    "SOURCES",
    "ColumnFeature",
    "ColumnLabel",
    "EffectorLabel",
    "ImportSpec",
    "KeyFeature",
    "LabelNames",
    "LeRobotSpec",
    "MimicGenSpec",
    "RosbagSpec",
    "Selection",
    "SplitSpec",
    "Subtask",
    "TfFrame",
    "TopicFeature",
    "TopicLabel",
    "load_mapping",
    "parse_mapping",
]
