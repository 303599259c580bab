"""Write an episode to a rerun ``.rrd`` file: :class:`EpisodeRecorder` (layout in
:mod:`cpmp.experiment.recording`) and :func:`group_features`, the rule that puts features into
plot panels.

``rerun`` is imported inside the functions and classes, so importing this module is cheap.
"""

from __future__ import annotations

import json
import math
import re
import uuid
from collections.abc import Mapping, Sequence
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, Any

import numpy as np

from cpmp.errors import ConfigError, CpmpError, DataError, UnknownMPError
from cpmp.io import atomic_path
from cpmp.sequencer import checked_time

if TYPE_CHECKING:
    import os

GEOM_TYPES = ("box", "capsule", "sphere", "cylinder")
"""Geom types :class:`EpisodeRecorder` can draw."""

TOUCH_WORDS = ("contact", "contacts", "touch", "touching", "supported", "force", "collision")
"""A feature whose name has one of these words (between ``_``/``.``/``-``/``/``) goes into the
``touch`` panel (see :func:`group_features`)."""

MAX_SERIES_PER_PANEL = 8
"""Default largest number of features :func:`group_features` puts into one plot panel."""

TOUCH_GROUP = "touch"
OTHER_GROUP = "other"

_GEOM_MIN_SIZE = {"box": 3, "capsule": 2, "sphere": 1, "cylinder": 2}
_DEFAULT_RGBA = (0.6, 0.6, 0.6, 1.0)
_TOKEN = re.compile(r"[^._\-/\s]+")
_TRANSITION_ARCHETYPE = "cpmp.Transition"
_OUTCOME_ARCHETYPE = "cpmp.Outcome"
_NOTE_ARCHETYPE = "cpmp.Note"
_PROPERTY_NAME = "cpmp"
_STATUS_ENTITY = "status"

_RowBuffer = tuple[list[int], list[float], list[np.ndarray]]
"""Ticks, times [s] and one row (K,) of scalar values per tick for a tuple of K entity paths."""
"""Per entity: ticks, times [s], values."""
_PoseBuffer = tuple[list[int], list[float], list[np.ndarray], list[np.ndarray]]
"""Ticks, times [s], positions (B, 3) and xyzw quaternions (B, 4) per tick for B bodies."""
"""Per body: ticks, times [s], positions (3,), quaternions (4,) xyzw."""


def group_features(
    names: Sequence[str],
    *,
    max_series: int = MAX_SERIES_PER_PANEL,
    touch_words: Sequence[str] = TOUCH_WORDS,
) -> dict[str, list[str]]:
    """Group feature names into plot panels, from the names alone.

    A name is split into words at ``_ . - /`` and white space. Names with a word in
    ``touch_words`` (case-insensitive) form the ``touch`` group; the others are grouped by
    their first word (``box_x``, ``box_z`` -> ``box``). A group of more than ``max_series``
    names is split by the next word, and named by the common prefix (``dist.left_rot.home``,
    ``dist.right_rot.home`` -> ``dist.left``, ``dist.right``); names that cannot be split
    further, or only into more than ``max_series`` parts, are cut into numbered parts
    (``arm_q 1``, ``arm_q 2``). Single-name groups are merged into
    ``other`` when there are several. Groups and their members keep the order of ``names``.
    """
    if max_series < 1:
        raise ConfigError(f"max_series must be >= 1, got {max_series}")
    if len(set(names)) != len(names):
        raise ConfigError(f"feature names must be unique, got {list(names)}")
    touch = {word.lower() for word in touch_words}
    tokens = {name: [m.span() for m in _TOKEN.finditer(name)] for name in names}
    touching = [n for n in names if any(n[a:b].lower() in touch for a, b in tokens[n])]
    rest = [n for n in names if n not in set(touching)]

    def words(name: str, depth: int) -> tuple[str, ...]:
        return tuple(name[a:b] for a, b in tokens[name][:depth])

    def prefix(name: str, depth: int) -> str:
        spans = tokens[name][:depth]
        return name[: spans[-1][1]] if spans else name

    def chunks(key: str, members: list[str]) -> dict[str, list[str]]:
        if len(members) <= max_series:
            return {key: members}
        starts = range(0, len(members), max_series)
        return {f"{key} {i + 1}": members[s : s + max_series] for i, s in enumerate(starts)}

    def split(key: str, members: list[str], depth: int) -> dict[str, list[str]]:
        if len(members) <= max_series:
            return {key: members}
        stay = [n for n in members if len(tokens[n]) <= depth]
        deeper: dict[tuple[str, ...], list[str]] = {}
        for name in members:
            if len(tokens[name]) > depth:
                deeper.setdefault(words(name, depth + 1), []).append(name)
        if not deeper or len(deeper) + bool(stay) > max_series:
            return chunks(key, members)
        if len(deeper) == 1 and not stay:
            (only,) = deeper.values()
            return split(prefix(only[0], depth + 1), only, depth + 1)
        out: dict[str, list[str]] = {}
        if stay:
            _merge(out, split(key, stay, depth))
        for sub in deeper.values():
            _merge(out, split(prefix(sub[0], depth + 1), sub, depth + 1))
        return out

    groups: dict[str, list[str]] = {}
    first: dict[str, list[str]] = {}
    for name in rest:
        first.setdefault(prefix(name, 1), []).append(name)
    for key, members in first.items():
        _merge(groups, split(key, members, 1))
    singles = [key for key, members in groups.items() if len(members) == 1]
    if len(singles) > 1:
        _merge(groups, chunks(OTHER_GROUP, [groups.pop(key)[0] for key in singles]))
    if touching:
        _merge(groups, chunks(TOUCH_GROUP, touching))
    order = {name: i for i, name in enumerate(names)}
    for members in groups.values():
        members.sort(key=order.__getitem__)
    return dict(sorted(groups.items(), key=lambda item: order[item[1][0]]))


def _merge(groups: dict[str, list[str]], more: Mapping[str, list[str]]) -> None:
    """Add ``more`` to ``groups`` in place; a name already used gets the members appended."""
    for key, members in more.items():
        groups.setdefault(key, []).extend(members)


def _check_feature_groups(
    groups: Mapping[str, Sequence[str]], names: Sequence[str]
) -> dict[str, list[str]]:
    """User-given groups, validated; features in no group are appended as ``other``."""
    out = {str(key): [str(n) for n in members] for key, members in groups.items()}
    seen: set[str] = set()
    for key, members in out.items():
        if not key or not members:
            raise ConfigError(f"feature_groups: group {key!r} needs a name and some features")
        unknown = [n for n in members if n not in names]
        if unknown:
            raise ConfigError(
                f"feature_groups[{key!r}] names unknown features {unknown}; known: {list(names)}"
            )
        twice = seen.intersection(members)
        if twice or len(set(members)) != len(members):
            raise ConfigError(f"feature_groups: features {sorted(twice)} are in several groups")
        seen.update(members)
    missing = [n for n in names if n not in seen]
    if missing:
        out.setdefault(OTHER_GROUP, []).extend(missing)
    return out


def transition_text(variable: str, source: str, target: str, probability: float, kind: str) -> str:
    """``"left_pos: approach -> grasp (p=0.71)"``, with ``" [recovery]"`` for a recovery."""
    text = f"{variable}: {source} -> {target} (p={probability:.2f})"
    return text if kind == "switch" else f"{text} [{kind}]"


def outcome_text(outcome: str, reason: str) -> str:
    """``"outcome: incomplete (deadlock)"``."""
    return f"outcome: {outcome}" + (f" ({reason})" if reason else "")


def _entity(*parts: str) -> str:
    import rerun as rr

    return "/".join(rr.escape_entity_path_part(part) for part in parts)


def _as_vector(value: Any, size: int, what: str, error: type[CpmpError]) -> np.ndarray:
    array = np.asarray(value, dtype=float)
    if array.shape != (size,):
        raise error(f"{what} must have shape ({size},), got {array.shape}")
    return array


def _wxyz_to_xyzw(quat_wxyz: np.ndarray) -> np.ndarray:
    return quat_wxyz[[1, 2, 3, 0]]


def _pose_rows(
    body_poses: Mapping[str, tuple[Any, Any]],
) -> tuple[tuple[str, ...], np.ndarray, np.ndarray]:
    """Body names, positions (B, 3) [m] and xyzw quaternions (B, 4) of wxyz ``body_poses``;
    a malformed pose raises :class:`DataError` naming its body."""
    bodies = tuple(str(body) for body in body_poses)
    try:
        positions = np.array([pos for pos, _ in body_poses.values()], dtype=float)
        quats = np.array([quat for _, quat in body_poses.values()], dtype=float)
    except (TypeError, ValueError):
        positions = quats = np.empty(0)
    if positions.shape != (len(bodies), 3) or quats.shape != (len(bodies), 4):
        for body, (pos, quat) in body_poses.items():
            _as_vector(pos, 3, f"position of body {body!r}", DataError)
            _as_vector(quat, 4, f"quaternion (wxyz) of body {body!r}", DataError)
        raise DataError("body_poses must map each body to (position (3,), quaternion (4,))")
    return bodies, positions, quats[:, [1, 2, 3, 0]]


class EpisodeRecorder:
    """Record one episode to a rerun ``.rrd`` file (layout: :mod:`cpmp.experiment.recording`).

    Parameters
    ----------
    path:
        Target ``.rrd`` file; its directory must exist. Written only by :meth:`close`.
    feature_names:
        Names of the F features passed to :meth:`log_tick`, in order.
    mp_names:
        Control variable -> names of its MPs (graph nodes).
    episode:
        Episode name, shown in the viewer and returned by
        :func:`~cpmp.experiment.recording.read_recording`.
    application_id:
        Rerun application id (recordings with the same id share viewer blueprints).
    geoms:
        Static visual geometry, dicts with ``body`` (str), ``type`` (one of
        :data:`GEOM_TYPES`), ``size`` (MuJoCo convention: box half-extents (3,) [m];
        capsule/cylinder ``[radius, half-length]`` along the local z axis; sphere ``[radius]``;
        longer arrays, as MuJoCo's ``geom_size`` (3,), are fine), optional ``pos`` (3,) [m] and
        ``quat`` (4,) wxyz in the body frame, ``rgba`` (4,) in [0, 1], ``name``.
    metadata:
        Free-form JSON-able episode information, stored as a recording property.
    flush_every:
        Send buffered per-tick data to the file every this many ticks (and on :meth:`close`).
        The default holds a 50 s episode at 100 Hz (a few MB), so an episode that is
        discarded with :meth:`abort` (``record=failures`` keeps only failures) never pays for
        sending its columns.
    feature_groups:
        Panel name -> feature names, one time-series panel each; features in no group go to
        ``other``. Default: :func:`group_features` of ``feature_names``.

    Use as a context manager, or call :meth:`close` (keep the file) or :meth:`abort` (discard).
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        feature_names: Sequence[str],
        mp_names: Mapping[str, Sequence[str]],
        episode: str = "episode",
        application_id: str = "cpmp",
        geoms: Sequence[Mapping[str, Any]] | None = None,
        metadata: Mapping[str, Any] | None = None,
        flush_every: int = 5000,
        feature_groups: Mapping[str, Sequence[str]] | None = None,
    ) -> None:
        import rerun as rr
        import rerun.blueprint as rrb

        self.path = Path(path)
        self.feature_names = [str(name) for name in feature_names]
        if len(set(self.feature_names)) != len(self.feature_names):
            raise ConfigError(f"feature_names contains duplicates: {self.feature_names}")
        self.mp_names = {str(var): [str(mp) for mp in mps] for var, mps in mp_names.items()}
        for variable, mps in self.mp_names.items():
            if not mps or len(set(mps)) != len(mps):
                raise ConfigError(
                    f"mp_names[{variable!r}] must be a non-empty list of unique names, got {mps}"
                )
        if flush_every < 1:
            raise ConfigError(f"flush_every must be >= 1, got {flush_every}")
        self.feature_groups = (
            group_features(self.feature_names)
            if feature_groups is None
            else _check_feature_groups(feature_groups, self.feature_names)
        )
        self.episode = str(episode)
        self.flush_every = int(flush_every)
        parsed_geoms = [_parse_geom(i, geom) for i, geom in enumerate(geoms or [])]

        self._rr = rr
        self._feature_paths = tuple(_entity("features", name) for name in self.feature_names)
        self._mp_index = {
            var: {mp: i for i, mp in enumerate(mps)} for var, mps in self.mp_names.items()
        }
        # Per-tick values are buffered as rows, one buffer per tuple of entity paths; the paths
        # of a (kind, variable, MP names) layout are made, checked and named once.
        self._rows: dict[tuple[str, ...], _RowBuffer] = {}
        self._poses: dict[tuple[str, ...], _PoseBuffer] = {}
        self._layouts: dict[tuple[Any, ...], tuple[str, ...]] = {}
        self._named_series: set[str] = set()
        self._active: dict[str, str] = {}
        self._last_transition = ""
        self._n_ticks = 0
        self._buffered_ticks = 0
        self._last_t = -math.inf
        self._closed = False

        self._atomic = atomic_path(self.path)
        self._tmp = self._atomic.__enter__()
        try:
            # Without an explicit id, rerun reuses one id per process: every episode recorded in
            # a process would then merge into one recording when the files are opened together.
            self._rec = rr.RecordingStream(application_id, recording_id=str(uuid.uuid4()))
            self._rec.save(self._tmp, default_blueprint=self._blueprint(rrb))
            self._rec.send_recording_name(self.episode)
            self._rec.send_property(
                _PROPERTY_NAME,
                rr.AnyValues(
                    episode=self.episode,
                    feature_names=json.dumps(self.feature_names),
                    feature_groups=json.dumps(self.feature_groups),
                    mp_names=json.dumps(self.mp_names),
                    metadata=json.dumps(dict(metadata or {}), default=str, sort_keys=True),
                ),
            )
            for path, name in zip(self._feature_paths, self.feature_names, strict=True):
                self._name_series(path, name)
            for geom in parsed_geoms:
                self._log_geom(geom)
        except BaseException:
            self.abort()
            raise

    def _blueprint(self, rrb: Any) -> Any:
        """Scene and status | feature panels and per-variable probabilities | active MPs and
        events. Every plot has few series (rerun's legend sits in its bottom-right corner)."""
        unit = rrb.ScalarAxis(range=(0.0, 1.0))
        feature_views = [
            rrb.TimeSeriesView(
                origin="features",
                contents=[f"+ {_entity('features', name)}" for name in members],
                name=group,
            )
            for group, members in self.feature_groups.items()
        ] or [rrb.TimeSeriesView(origin="features", name="features")]
        variable_tabs = [
            rrb.Grid(
                rrb.TimeSeriesView(
                    origin=_entity("progress", var),
                    contents="+ $origin/*/phi",
                    name=f"{var}: progress φ (= exit)",
                    axis_y=unit,
                ),
                rrb.TimeSeriesView(
                    origin=_entity("progress", var),
                    contents="+ $origin/*/entry",
                    name=f"{var}: entry 1 - φ",
                    axis_y=unit,
                ),
                rrb.TimeSeriesView(
                    origin=_entity("transition", var),
                    name=f"{var}: transition probabilities",
                    axis_y=unit,
                ),
                name=var,
            )
            for var in self.mp_names
        ]
        body_first = rrb.TextLogColumns(
            timeline_columns=[rrb.encodings.TimelineColumn("time")],
            text_log_columns=[
                rrb.encodings.TextLogColumn("body"),
                rrb.encodings.TextLogColumn("loglevel"),
                rrb.encodings.TextLogColumn("entitypath", visible=False),
            ],
        )
        middle = [rrb.Grid(*feature_views, name="features")]
        if variable_tabs:
            middle.append(rrb.Tabs(*variable_tabs, name="probabilities"))
        return rrb.Blueprint(
            rrb.Horizontal(
                rrb.Vertical(
                    rrb.Spatial3DView(origin="world", name="scene"),
                    rrb.TextDocumentView(origin=_STATUS_ENTITY, name="status"),
                    row_shares=[3, 2],
                ),
                rrb.Vertical(*middle, row_shares=[3, 2][: len(middle)]),
                rrb.Vertical(
                    rrb.StateTimelineView(origin="active", name="active MPs"),
                    rrb.Tabs(
                        rrb.TextLogView(
                            origin="events",
                            contents=[
                                "+ events/transitions",
                                "+ events/notes",
                                "+ events/outcome",
                            ],
                            name="events",
                            columns=body_first,
                        ),
                        rrb.TextLogView(origin="active", name="active MP log", columns=body_first),
                    ),
                    row_shares=[2, 3],
                ),
                column_shares=[2, 3, 2],
            ),
            # Room for the views; the full time panel stays: its rows mark every event.
            rrb.BlueprintPanel(state="collapsed"),
            rrb.SelectionPanel(state="collapsed"),
            rrb.TimePanel(state="expanded"),
        )

    def _log_geom(self, geom: dict[str, Any]) -> None:
        rr = self._rr
        path = _entity("world", geom["body"], geom["name"])
        size, color = geom["size"], geom["rgba"]
        kind = geom["type"]
        if kind == "box":
            shape = rr.Boxes3D(half_sizes=[size[:3]], colors=[color], fill_mode="solid")
        elif kind == "sphere":
            shape = rr.Ellipsoids3D(half_sizes=[[size[0]] * 3], colors=[color], fill_mode="solid")
        elif kind == "cylinder":
            shape = rr.Cylinders3D(
                lengths=[2 * size[1]], radii=[size[0]], colors=[color], fill_mode="solid"
            )
        else:
            # rerun capsules run from z = 0 to z = length; MuJoCo's are centred on the geom frame.
            shape = rr.Capsules3D(
                lengths=[2 * size[1]],
                radii=[size[0]],
                translations=[[0.0, 0.0, -size[1]]],
                colors=[color],
                fill_mode="solid",
            )
        local = rr.Transform3D(translation=geom["pos"], quaternion=_wxyz_to_xyzw(geom["quat"]))
        self._rec.log(path, local, shape, static=True)

    def _check_open(self) -> None:
        if self._closed:
            raise CpmpError(f"recorder for {self.path} is closed")

    def _check_mp(self, variable: str, mp: str | None = None) -> None:
        if variable not in self.mp_names:
            raise UnknownMPError(
                f"unknown control variable {variable!r}; known: {sorted(self.mp_names)}"
            )
        if mp is not None and mp not in self.mp_names[variable]:
            raise UnknownMPError(
                f"unknown MP {mp!r} for variable {variable!r}; known: {self.mp_names[variable]}"
            )

    def _buffer_row(self, paths: tuple[str, ...], tick: int, t: float, row: np.ndarray) -> None:
        ticks, times, rows = self._rows.setdefault(paths, ([], [], []))
        ticks.append(tick)
        times.append(t)
        rows.append(row)

    def _progress_paths(self, variable: str, mps: tuple[str, ...]) -> tuple[str, ...]:
        """``phi``, ``entry``, ``exit`` paths of each MP in ``mps`` (MP-major), checked, named."""
        key = ("progress", variable, mps)
        paths = self._layouts.get(key)
        if paths is None:
            for mp in mps:
                self._check_mp(variable, mp)
            series = [(mp, part) for mp in mps for part in ("phi", "entry", "exit")]
            paths = tuple(_entity("progress", variable, mp, part) for mp, part in series)
            for path, (mp, part) in zip(paths, series, strict=True):
                self._name_series(path, f"{mp} {part}")
            self._layouts[key] = paths
        return paths

    def _transition_paths(self, variable: str, targets: tuple[str, ...]) -> tuple[str, ...]:
        key = ("transition", variable, targets)
        paths = self._layouts.get(key)
        if paths is None:
            for target in targets:
                self._check_mp(variable, target)
            paths = tuple(_entity("transition", variable, target) for target in targets)
            for path, target in zip(paths, targets, strict=True):
                self._name_series(path, f"to {target}")
            self._layouts[key] = paths
        return paths

    def _index_paths(self, variables: tuple[str, ...]) -> tuple[str, ...]:
        key = ("active", variables)
        paths = self._layouts.get(key)
        if paths is None:
            for variable in variables:
                self._check_mp(variable)
            paths = tuple(_entity("active", variable, "index") for variable in variables)
            self._layouts[key] = paths
        return paths

    def _name_series(self, path: str, name: str) -> None:
        if path not in self._named_series:
            self._named_series.add(path)
            self._rec.log(path, self._rr.SeriesLines(names=[name]), static=True)

    def _set_event_time(self, t: float) -> None:
        self._rec.reset_time()
        self._rec.set_time("time", duration=t)
        if self._n_ticks:
            self._rec.set_time("tick", sequence=self._n_ticks - 1)

    def _log_status(self, t: float, outcome: str = "") -> None:
        """The ``status`` document at ``t`` [s] (event time already set): active MPs, last
        transition, outcome, as markdown."""
        lines = [f"**{self.episode}** · t = {t:.2f} s", "", "| variable | active MP |", "|---|---|"]
        lines += [f"| {var} | {self._active.get(var, '-')} |" for var in self.mp_names]
        if self._last_transition:
            lines += ["", f"last transition: {self._last_transition}"]
        if outcome:
            lines += ["", f"**{outcome}**"]
        document = self._rr.TextDocument("\n".join(lines), media_type="text/markdown")
        self._rec.log(_STATUS_ENTITY, document)

    def log_tick(
        self,
        t: float,
        features: Sequence[float] | np.ndarray,
        progress: Mapping[str, Mapping[str, float]],
        active: Mapping[str, str],
        transition_probs: Mapping[str, Mapping[str, float]] | None = None,
        body_poses: Mapping[str, tuple[Any, Any]] | None = None,
    ) -> None:
        """Record one control tick.

        ``t`` [s], non-decreasing; ``features`` (F,) in ``feature_names`` order (non-finite
        values are recorded as they are); ``progress[variable][mp]`` = predicted φ;
        ``active[variable]`` = active MP; ``transition_probs[variable][target]`` = probability
        of switching to ``target``; ``body_poses[body]`` = (position (3,) [m], quaternion (4,)
        wxyz) in the world frame. Everything is validated before anything is recorded.
        """
        self._check_open()
        t = checked_time(t)
        if t < self._last_t:
            raise DataError(f"tick times must be non-decreasing: got t={t} after {self._last_t}")
        values = np.array(features, dtype=float)  # a copy: the caller may reuse its array
        if values.shape != (len(self.feature_names),):
            raise DataError(
                f"features must have shape ({len(self.feature_names)},) to match "
                f"feature_names, got {values.shape}"
            )
        rows: list[tuple[tuple[str, ...], np.ndarray]] = [(self._feature_paths, values)]
        for variable, phis in progress.items():
            if phis:
                phi = np.fromiter(phis.values(), dtype=float, count=len(phis))
                row = np.empty(3 * phi.size)
                row[0::3], row[1::3], row[2::3] = phi, 1.0 - phi, phi
                rows.append((self._progress_paths(variable, tuple(phis)), row))
        for variable, targets in (transition_probs or {}).items():
            if targets:
                row = np.fromiter(targets.values(), dtype=float, count=len(targets))
                rows.append((self._transition_paths(variable, tuple(targets)), row))
        if active:
            indices = np.empty(len(active))
            for i, (variable, mp) in enumerate(active.items()):
                index = self._mp_index.get(variable, {}).get(mp)
                if index is None:
                    self._check_mp(variable, mp)
                indices[i] = index
            rows.append((self._index_paths(tuple(active)), indices))
        poses = _pose_rows(body_poses) if body_poses else None

        tick = self._n_ticks
        for paths, row in rows:
            self._buffer_row(paths, tick, t, row)
        changed = False
        for variable, mp in active.items():
            if self._active.get(variable) != mp:
                if not changed:
                    self._rec.reset_time()
                    self._rec.set_time("time", duration=t)
                    self._rec.set_time("tick", sequence=tick)
                changed = True
                self._active[variable] = mp
                self._rec.log(
                    _entity("active", variable),
                    self._rr.TextLog(f"{variable}: {mp}"),
                    self._rr.StateChange(state=[mp]),
                )
        if changed:
            self._log_status(t)
        if poses is not None:
            bodies, positions, quats = poses
            ticks, times, position_rows, quat_rows = self._poses.setdefault(
                bodies, ([], [], [], [])
            )
            ticks.append(tick)
            times.append(t)
            position_rows.append(positions)
            quat_rows.append(quats)

        self._n_ticks += 1
        self._last_t = t
        self._buffered_ticks += 1
        if self._buffered_ticks >= self.flush_every:
            self._flush_buffers()

    def _flush_buffers(self) -> None:
        rr = self._rr

        def indexes(ticks: list[int], times: list[float]) -> list[Any]:
            return [
                rr.TimeColumn("time", duration=np.asarray(times)),
                rr.TimeColumn("tick", sequence=np.asarray(ticks)),
            ]

        for paths, (ticks, times, rows) in self._rows.items():
            if ticks:
                table = np.asarray(rows, dtype=float)  # (T, K)
                for j, path in enumerate(paths):
                    self._rec.send_columns(
                        path,
                        indexes=indexes(ticks, times),
                        columns=rr.Scalars.columns(scalars=table[:, j]),
                    )
                for column in (ticks, times, rows):
                    column.clear()
        for bodies, (ticks, times, positions, quats) in self._poses.items():
            if ticks:
                translation, rotation = np.stack(positions), np.stack(quats)  # (T, B, 3|4)
                for j, body in enumerate(bodies):
                    self._rec.send_columns(
                        _entity("world", body),
                        indexes=indexes(ticks, times),
                        columns=rr.Transform3D.columns(
                            translation=translation[:, j], quaternion=rotation[:, j]
                        ),
                    )
                for column in (ticks, times, positions, quats):
                    column.clear()
        self._buffered_ticks = 0

    def log_transition(
        self,
        t: float,
        variable: str,
        source: str,
        target: str,
        probability: float,
        kind: str = "switch",
    ) -> None:
        """Record that ``variable`` switched from MP ``source`` to ``target`` at ``t`` [s]
        (``kind``: ``switch`` or ``recovery``)."""
        self._check_open()
        t = checked_time(t)
        self._check_mp(variable, source)
        self._check_mp(variable, target)
        probability = float(probability)
        text = transition_text(variable, source, target, probability, str(kind))
        record = self._rr.DynamicArchetype(
            _TRANSITION_ARCHETYPE,
            components={
                "variable": variable,
                "source": source,
                "target": target,
                "probability": probability,
                "kind": str(kind),
            },
        )
        self._set_event_time(t)
        self._rec.log("events/transitions", self._rr.TextLog(text, level="INFO"), record)
        self._rec.log(_entity("events", "transitions", variable), self._rr.TextLog(text))
        self._last_transition = f"{text} at {t:.2f} s"
        self._log_status(t)

    def log_note(self, t: float, kind: str, variable: str, text: str) -> None:
        """Record a sequencer note at ``t`` [s]: a held transition, a stall recovery or a
        non-finite φ (``kind``), about ``variable`` (may be empty), as readable ``text``."""
        self._check_open()
        t = checked_time(t)
        record = self._rr.DynamicArchetype(
            _NOTE_ARCHETYPE,
            components={"kind": str(kind), "variable": str(variable), "text": str(text)},
        )
        level = "WARN" if kind in ("recovery", "nonfinite") else "INFO"
        self._set_event_time(t)
        self._rec.log("events/notes", self._rr.TextLog(f"{kind}: {text}", level=level), record)

    def log_outcome(
        self, t: float, outcome: str, reason: str = "", *, success: bool | None = None
    ) -> None:
        """Record the episode's outcome (e.g. ``"complete"``) at ``t`` [s], with a reason.

        ``success=False`` logs it at level ``WARN`` (drawn in the viewer's warning colour),
        otherwise ``INFO``. The ``status`` document at ``t`` shows the outcome too.
        """
        self._check_open()
        t = checked_time(t)
        if not str(outcome):
            raise DataError("outcome must be a non-empty string")
        text = outcome_text(str(outcome), str(reason))
        record = self._rr.DynamicArchetype(
            _OUTCOME_ARCHETYPE, components={"outcome": str(outcome), "reason": str(reason)}
        )
        level = "WARN" if success is False else "INFO"
        self._set_event_time(t)
        self._rec.log("events/outcome", self._rr.TextLog(text, level=level), record)
        self._log_status(t, outcome=text)

    def close(self) -> Path:
        """Flush, finish the file and move it onto ``path``; returns ``path``. Idempotent."""
        if self._closed:
            return self.path
        try:
            self._flush_buffers()
            self._rec.flush()
            self._rec.disconnect()
        except BaseException:
            self.abort()
            raise
        self._closed = True
        self._atomic.__exit__(None, None, None)
        return self.path

    def abort(self) -> None:
        """Discard the recording: nothing is written at ``path``. Idempotent."""
        if self._closed:
            return
        self._closed = True
        rec = getattr(self, "_rec", None)
        if rec is not None:
            rec.disconnect()
        error = CpmpError(f"recording of {self.path} aborted")
        self._atomic.__exit__(type(error), error, None)

    def __enter__(self) -> EpisodeRecorder:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()


def _parse_geom(index: int, geom: Mapping[str, Any]) -> dict[str, Any]:
    where = f"geoms[{index}]"
    kind = geom.get("type")
    if kind not in GEOM_TYPES:
        raise ConfigError(f"{where}: type must be one of {GEOM_TYPES}, got {kind!r}")
    if "body" not in geom:
        raise ConfigError(f"{where}: missing 'body'")
    size = np.asarray(geom.get("size", ()), dtype=float).ravel()
    if size.size < _GEOM_MIN_SIZE[kind] or not np.all(np.isfinite(size)):
        raise ConfigError(
            f"{where}: a {kind} needs at least {_GEOM_MIN_SIZE[kind]} finite size values, "
            f"got {size.tolist()}"
        )
    pos = _as_vector(geom.get("pos", (0.0, 0.0, 0.0)), 3, f"{where} pos", ConfigError)
    quat = _as_vector(geom.get("quat", (1.0, 0.0, 0.0, 0.0)), 4, f"{where} quat", ConfigError)
    rgba = _as_vector(geom.get("rgba", _DEFAULT_RGBA), 4, f"{where} rgba", ConfigError)
    return {
        "body": str(geom["body"]),
        "name": str(geom.get("name", f"geom_{index}")),
        "type": kind,
        "size": size.tolist(),
        "pos": pos,
        "quat": quat,
        "rgba": np.round(np.clip(rgba, 0.0, 1.0) * 255).astype(np.uint8),
    }


__all__ = [
    "GEOM_TYPES",
    "MAX_SERIES_PER_PANEL",
    "TOUCH_WORDS",
    "EpisodeRecorder",
    "group_features",
    "outcome_text",
    "transition_text",
]
