"""Rerun recordings of episodes: write with :class:`EpisodeRecorder`, read back offline with
:func:`read_recording`.

``rerun`` is imported inside the functions and classes, so importing this module is cheap.

Layout of a recording (one ``.rrd`` file per episode). Time-series data sit on two timelines:
``time`` (a duration, seconds since the episode start) and ``tick`` (sequence, 0-based index of
the :meth:`EpisodeRecorder.log_tick` call).

=====================================  ===================================================
entity path                            content
=====================================  ===================================================
``world/<body>``                       ``Transform3D`` per tick: body pose in the world
``world/<body>/geom_<i>``              static ``Transform3D`` (geom pose in the body frame)
                                       and one of ``Boxes3D``/``Capsules3D``/
                                       ``Cylinders3D``/``Ellipsoids3D`` (sphere)
``features/<name>``                    ``Scalars``: one feature per entity
``progress/<variable>/<mp>/phi``       ``Scalars``: predicted progress φ of the node
``progress/<variable>/<mp>/entry``     ``Scalars``: 1 - φ
``progress/<variable>/<mp>/exit``      ``Scalars``: φ
``transition/<variable>/<target>``     ``Scalars``: transition probability to ``target``
``active/<variable>``                  ``TextLog`` ``"<variable>: <mp>"`` when the active MP
                                       changes
``active/<variable>/index``            ``Scalars`` per tick: index of the active MP in
                                       ``mp_names[variable]``
``events/transitions``                 ``TextLog`` ``"left_pos: approach -> grasp (p=0.71)"``
                                       plus the machine-readable ``cpmp.Transition`` record
``events/transitions/<variable>``      the same ``TextLog``, per control variable
``events/outcome``                     ``TextLog`` plus the ``cpmp.Outcome`` record
=====================================  ===================================================

Machine-readable encoding. Transitions and outcomes are logged, in the same row as their
``TextLog``, as ``rr.DynamicArchetype`` records whose columns read back as
``cpmp.Transition:{variable,source,target,probability}`` (strings, and a float64 probability)
and ``cpmp.Outcome:{outcome,reason}`` (strings); their time is the ``time`` timeline of the row.
The episode name is the recording name (``RecordingInfo:name`` property) and the recording
property ``cpmp`` holds ``episode``, ``feature_names``, ``mp_names`` and ``metadata`` (the last
three as JSON text; metadata values that JSON cannot encode are stored as ``str``).

Scalars and body poses are buffered and sent column-wise (``send_columns``) every
``flush_every`` ticks and on :meth:`EpisodeRecorder.close`: one ``rr.log`` call costs ~30 µs,
which at 100 entities per tick would cost more than the simulation itself. The file is written
beside the target under a temporary name and renamed onto it only by a successful
:meth:`EpisodeRecorder.close`, so a failed or aborted episode leaves no partial file.
"""

from __future__ import annotations

import json
import math
import uuid
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from cpmp.errors import ConfigError, CpmpError, CpmpFileError, DataError, UnknownMPError
from cpmp.io import atomic_path

if TYPE_CHECKING:
    import os

GEOM_TYPES = ("box", "capsule", "sphere", "cylinder")
"""Geom types :class:`EpisodeRecorder` can draw."""

_GEOM_MIN_SIZE = {"box": 3, "capsule": 2, "sphere": 1, "cylinder": 2}
_DEFAULT_RGBA = (0.6, 0.6, 0.6, 1.0)
_TRANSITION_ARCHETYPE = "cpmp.Transition"
_OUTCOME_ARCHETYPE = "cpmp.Outcome"
_NOTE_ARCHETYPE = "cpmp.Note"
_PROPERTY_NAME = "cpmp"

_ScalarBuffer = tuple[list[int], list[float], list[float]]
"""Per entity: ticks, times [s], values."""
_PoseBuffer = tuple[list[int], list[float], list[np.ndarray], list[np.ndarray]]
"""Per body: ticks, times [s], positions (3,), quaternions (4,) xyzw."""


class TransitionEvent(NamedTuple):
    """One MP transition: ``t`` [s], control ``variable``, ``source`` -> ``target`` MP;
    ``kind`` is ``switch`` (the switching rule fired) or ``recovery`` (a stall was resolved)."""

    t: float
    variable: str
    source: str
    target: str
    probability: float
    kind: str = "switch"


class NoteEvent(NamedTuple):
    """A sequencer note: ``t`` [s], ``kind`` (``hold``, ``recovery``, ``nonfinite``), the
    ``variable`` concerned (may be empty) and a readable ``text``."""

    t: float
    kind: str
    variable: str
    text: str


@dataclass
class RecordingSummary:
    """What :func:`read_recording` finds in an ``.rrd`` file.

    ``episodes``: episode names (recording name, else ``application_id/recording_id``), one per
    recording in the file. ``transitions``: in time order. ``outcome``/``reason``: of the last
    outcome logged, ``None`` if none. ``duration``: last time on the ``time`` timeline [s].
    ``n_ticks``: number of distinct ``tick`` values. ``entity_paths``: sorted, without the
    leading ``/`` and without recording properties. ``metadata``: the recorder's ``metadata``.
    """

    episodes: list[str]
    transitions: list[TransitionEvent]
    outcome: str | None
    reason: str | None
    duration: float
    n_ticks: int
    entity_paths: list[str]
    metadata: dict[str, Any] = field(default_factory=dict)
    notes: list[NoteEvent] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        """JSON-able dict of the fields, each transition and note as a dict with named fields."""
        data = asdict(self)
        data["transitions"] = [event._asdict() for event in self.transitions]
        data["notes"] = [note._asdict() for note in self.notes]
        return data


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


class EpisodeRecorder:
    """Record one episode to a rerun ``.rrd`` file (see the module docstring for the layout).

    Parameters
    ----------
    path:
        Target ``.rrd`` file; its directory must exist. Written only by :meth:`close`.
    feature_names:
        Names of the F features passed to :meth:`log_tick`, in order.
    mp_names:
        Control variable -> names of its MPs (graph nodes).
    episode:
        Episode name, shown in the viewer and returned by :func:`read_recording`.
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
        Send buffered per-tick data to the file every this many ticks.

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
        flush_every: int = 500,
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
        self.episode = str(episode)
        self.flush_every = int(flush_every)
        parsed_geoms = [_parse_geom(i, geom) for i, geom in enumerate(geoms or [])]

        self._rr = rr
        self._feature_paths = [_entity("features", name) for name in self.feature_names]
        self._scalars: dict[str, _ScalarBuffer] = {}
        self._poses: dict[str, _PoseBuffer] = {}
        self._named_series: set[str] = set()
        self._active: dict[str, str] = {}
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
                    mp_names=json.dumps(self.mp_names),
                    metadata=json.dumps(dict(metadata or {}), default=str, sort_keys=True),
                ),
            )
            for geom in parsed_geoms:
                self._log_geom(geom)
        except BaseException:
            self.abort()
            raise

    def _blueprint(self, rrb: Any) -> Any:
        unit = rrb.ScalarAxis(range=(0.0, 1.0))
        progress_views = [
            rrb.TimeSeriesView(origin=_entity("progress", var), name=f"progress {var}", axis_y=unit)
            for var in self.mp_names
        ] or [rrb.TimeSeriesView(origin="progress", name="progress", axis_y=unit)]
        return rrb.Blueprint(
            rrb.Horizontal(
                rrb.Spatial3DView(origin="world", name="scene"),
                rrb.Vertical(
                    rrb.TimeSeriesView(origin="features", name="features"),
                    rrb.Tabs(*progress_views, name="progress"),
                    rrb.TimeSeriesView(
                        origin="transition", name="transition probabilities", axis_y=unit
                    ),
                ),
                rrb.Vertical(
                    rrb.TextLogView(
                        origin="events",
                        contents=["+ events/transitions", "+ events/outcome"],
                        name="events",
                    ),
                    rrb.TextLogView(origin="active", name="active MPs"),
                ),
                column_shares=[2, 2, 1],
            ),
            collapse_panels=False,
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

    @staticmethod
    def _check_time(t: float) -> float:
        t = float(t)
        if not math.isfinite(t):
            raise DataError(f"time t must be finite, got {t}")
        return t

    def _buffer_scalar(self, path: str, tick: int, t: float, value: float) -> None:
        ticks, times, values = self._scalars.setdefault(path, ([], [], []))
        ticks.append(tick)
        times.append(t)
        values.append(float(value))

    def _name_series(self, path: str, name: str) -> None:
        if path not in self._named_series:
            self._named_series.add(path)
            self._rec.log(path, self._rr.SeriesLines(names=[name]), static=True)

    def _set_event_time(self, t: float) -> None:
        self._rec.reset_time()
        self._rec.set_time("time", duration=t)
        if self._n_ticks:
            self._rec.set_time("tick", sequence=self._n_ticks - 1)

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
        t = self._check_time(t)
        if t < self._last_t:
            raise DataError(f"tick times must be non-decreasing: got t={t} after {self._last_t}")
        values = np.asarray(features, dtype=float)
        if values.shape != (len(self.feature_names),):
            raise DataError(
                f"features must have shape ({len(self.feature_names)},) to match "
                f"feature_names, got {values.shape}"
            )
        for variable, phis in progress.items():
            for mp in phis:
                self._check_mp(variable, mp)
        for variable, mp in active.items():
            self._check_mp(variable, mp)
        for variable, targets in (transition_probs or {}).items():
            for target in targets:
                self._check_mp(variable, target)
        poses = {
            str(body): (
                _as_vector(pos, 3, f"position of body {body!r}", DataError),
                _as_vector(quat, 4, f"quaternion (wxyz) of body {body!r}", DataError),
            )
            for body, (pos, quat) in (body_poses or {}).items()
        }

        tick = self._n_ticks
        for path, value in zip(self._feature_paths, values, strict=True):
            self._buffer_scalar(path, tick, t, value)
        for variable, phis in progress.items():
            for mp, phi in phis.items():
                phi = float(phi)
                for part, value in (("phi", phi), ("entry", 1.0 - phi), ("exit", phi)):
                    path = _entity("progress", variable, mp, part)
                    self._name_series(path, f"{mp} {part}")
                    self._buffer_scalar(path, tick, t, value)
        for variable, targets in (transition_probs or {}).items():
            for target, probability in targets.items():
                self._buffer_scalar(_entity("transition", variable, target), tick, t, probability)
        for variable, mp in active.items():
            index_path = _entity("active", variable, "index")
            self._buffer_scalar(index_path, tick, t, self.mp_names[variable].index(mp))
            if self._active.get(variable) != mp:
                self._active[variable] = mp
                self._rec.reset_time()
                self._rec.set_time("time", duration=t)
                self._rec.set_time("tick", sequence=tick)
                self._rec.log(_entity("active", variable), self._rr.TextLog(f"{variable}: {mp}"))
        for body, (pos, quat) in poses.items():
            ticks, times, positions, quats = self._poses.setdefault(body, ([], [], [], []))
            ticks.append(tick)
            times.append(t)
            positions.append(pos)
            quats.append(_wxyz_to_xyzw(quat))

        self._n_ticks += 1
        self._last_t = t
        self._buffered_ticks += 1
        if self._buffered_ticks >= self.flush_every:
            self._flush_buffers()

    def _flush_buffers(self) -> None:
        rr = self._rr
        for path, (ticks, times, values) in self._scalars.items():
            if ticks:
                self._rec.send_columns(
                    path,
                    indexes=[
                        rr.TimeColumn("time", duration=np.asarray(times)),
                        rr.TimeColumn("tick", sequence=np.asarray(ticks)),
                    ],
                    columns=rr.Scalars.columns(scalars=np.asarray(values)),
                )
                for column in (ticks, times, values):
                    column.clear()
        for body, (ticks, times, positions, quats) in self._poses.items():
            if ticks:
                self._rec.send_columns(
                    _entity("world", body),
                    indexes=[
                        rr.TimeColumn("time", duration=np.asarray(times)),
                        rr.TimeColumn("tick", sequence=np.asarray(ticks)),
                    ],
                    columns=rr.Transform3D.columns(
                        translation=np.stack(positions), quaternion=np.stack(quats)
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
        t = self._check_time(t)
        self._check_mp(variable, source)
        self._check_mp(variable, target)
        probability = float(probability)
        text = f"{variable}: {source} -> {target} (p={probability:.2f})"
        if kind != "switch":
            text += f" [{kind}]"
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

    def log_note(self, t: float, kind: str, variable: str, text: str) -> None:
        """Record a sequencer note at ``t`` [s]: a held transition, a stall recovery or a
        non-finite φ (``kind``), about ``variable`` (may be empty), as readable ``text``."""
        self._check_open()
        t = self._check_time(t)
        record = self._rr.DynamicArchetype(
            _NOTE_ARCHETYPE,
            components={"kind": str(kind), "variable": str(variable), "text": str(text)},
        )
        level = "WARN" if kind in ("recovery", "nonfinite") else "INFO"
        self._set_event_time(t)
        self._rec.log("events/notes", self._rr.TextLog(f"{kind}: {text}", level=level), record)

    def log_outcome(self, t: float, outcome: str, reason: str = "") -> None:
        """Record the episode's outcome (e.g. ``"success"``) at ``t`` [s], with a reason."""
        self._check_open()
        t = self._check_time(t)
        if not str(outcome):
            raise DataError("outcome must be a non-empty string")
        text = f"outcome: {outcome}" + (f" ({reason})" if reason else "")
        record = self._rr.DynamicArchetype(
            _OUTCOME_ARCHETYPE, components={"outcome": str(outcome), "reason": str(reason)}
        )
        self._set_event_time(t)
        self._rec.log("events/outcome", self._rr.TextLog(text, level="INFO"), record)

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


def _first(cell: Any) -> Any:
    """A component cell reads back as a list (one batch); return its first value or None."""
    if isinstance(cell, list):
        return cell[0] if cell else None
    return cell


def _times_seconds(batch: Any) -> list[float] | None:
    if "time" not in batch.schema.names:
        return None
    column = batch.column("time")
    raw = column.cast("int64").to_pylist()
    scale = 1e-9 if str(column.type).startswith(("duration", "timestamp")) else 1.0
    return [math.nan if value is None else value * scale for value in raw]


def read_recording(path: str | os.PathLike[str]) -> RecordingSummary:
    """Read an ``.rrd`` file back offline and summarise it (see :class:`RecordingSummary`).

    Raises :class:`~cpmp.errors.CpmpFileError` if ``path`` is missing or not a rerun recording.
    """
    from rerun.chunk import RrdReader
    from rerun.error_utils import RerunWarning

    file = Path(path)
    if not file.exists():
        raise CpmpFileError(f"recording {file} does not exist")
    if not file.is_file():
        raise CpmpFileError(f"recording {file} is not a file")
    try:
        with warnings.catch_warnings():
            # A truncated file warns about its missing footer before failing: the error says it.
            warnings.simplefilter("ignore", RerunWarning)
            reader = RrdReader(file)
            stores = reader.recordings()
            batches = [
                (index, store, chunk.entity_path, chunk.to_record_batch())
                for index, store in enumerate(stores)
                for chunk in reader.stream(store=store)
            ]
    except (RuntimeError, ValueError, OSError) as err:
        raise CpmpFileError(f"cannot read {file} as a rerun recording (.rrd): {err}") from err
    if not stores:
        raise CpmpFileError(f"{file} contains no rerun recording")

    names: dict[int, str] = {}
    metadata: dict[str, Any] = {}
    ticks: dict[int, set[int]] = {index: set() for index in range(len(stores))}
    entity_paths: set[str] = set()
    transitions: list[TransitionEvent] = []
    notes: list[NoteEvent] = []
    outcomes: list[tuple[float, int, str, str]] = []
    duration = 0.0
    for index, _store, entity_path, batch in batches:
        columns = batch.schema.names
        entity = entity_path.lstrip("/")
        if entity.startswith("__properties"):
            if "RecordingInfo:name" in columns:
                names[index] = str(_first(batch.column("RecordingInfo:name")[0].as_py()))
            if entity == f"__properties/{_PROPERTY_NAME}" and "metadata" in columns:
                metadata = json.loads(_first(batch.column("metadata")[0].as_py()) or "{}")
            continue
        entity_paths.add(entity)
        times = _times_seconds(batch)
        if times:
            finite = [t for t in times if math.isfinite(t)]
            duration = max([duration, *finite])
        if "tick" in columns:
            ticks[index].update(v for v in batch.column("tick").to_pylist() if v is not None)
        if times is None:
            continue
        if f"{_TRANSITION_ARCHETYPE}:variable" in columns:
            fields = {
                name: batch.column(f"{_TRANSITION_ARCHETYPE}:{name}").to_pylist()
                for name in ("variable", "source", "target", "probability")
            }
            kind_column = f"{_TRANSITION_ARCHETYPE}:kind"
            kinds = (
                batch.column(kind_column).to_pylist()
                if kind_column in columns
                else [None] * len(times)
            )
            for row, t in enumerate(times):
                if _first(fields["variable"][row]) is None:
                    continue
                transitions.append(
                    TransitionEvent(
                        t=t,
                        variable=str(_first(fields["variable"][row])),
                        source=str(_first(fields["source"][row])),
                        target=str(_first(fields["target"][row])),
                        probability=float(_first(fields["probability"][row])),
                        kind=str(_first(kinds[row]) or "switch"),
                    )
                )
        if f"{_NOTE_ARCHETYPE}:kind" in columns:
            cells = {
                name: batch.column(f"{_NOTE_ARCHETYPE}:{name}").to_pylist()
                for name in ("kind", "variable", "text")
            }
            for row, t in enumerate(times):
                if _first(cells["kind"][row]) is not None:
                    notes.append(
                        NoteEvent(
                            t,
                            str(_first(cells["kind"][row])),
                            str(_first(cells["variable"][row]) or ""),
                            str(_first(cells["text"][row]) or ""),
                        )
                    )
        if f"{_OUTCOME_ARCHETYPE}:outcome" in columns:
            outcome_column = batch.column(f"{_OUTCOME_ARCHETYPE}:outcome").to_pylist()
            reason_column = (
                batch.column(f"{_OUTCOME_ARCHETYPE}:reason").to_pylist()
                if f"{_OUTCOME_ARCHETYPE}:reason" in columns
                else [None] * len(times)
            )
            for row, t in enumerate(times):
                outcome = _first(outcome_column[row])
                if outcome is not None:
                    reason = _first(reason_column[row])
                    outcomes.append((t, len(outcomes), str(outcome), str(reason or "")))

    transitions.sort(key=lambda event: event.t)
    notes.sort(key=lambda note: note.t)
    last_outcome = max(outcomes, default=None)
    episodes = [
        names.get(index, f"{store.application_id}/{store.recording_id}")
        for index, store in enumerate(stores)
    ]
    return RecordingSummary(
        episodes=episodes,
        transitions=transitions,
        outcome=last_outcome[2] if last_outcome else None,
        reason=last_outcome[3] if last_outcome else None,
        duration=duration,
        n_ticks=sum(len(values) for values in ticks.values()),
        entity_paths=sorted(entity_paths),
        metadata=metadata,
        notes=notes,
    )


def format_summary(summary: RecordingSummary) -> str:
    """Human-readable multi-line text of a :class:`RecordingSummary`."""
    lines = [
        f"episode: {', '.join(summary.episodes)}",
        f"ticks: {summary.n_ticks}, duration: {summary.duration:.3f} s",
        f"transitions ({len(summary.transitions)}):",
    ]
    lines += [
        f"  t={event.t:8.3f} s  {event.variable}: {event.source} -> {event.target} "
        f"(p={event.probability:.2f})" + ("" if event.kind == "switch" else f" [{event.kind}]")
        for event in summary.transitions
    ]
    if summary.notes:
        lines.append(f"notes ({len(summary.notes)}):")
        lines += [f"  t={n.t:8.3f} s  {n.kind}: {n.text}" for n in summary.notes]
    if summary.outcome is None:
        lines.append("outcome: none recorded")
    else:
        reason = f" ({summary.reason})" if summary.reason else ""
        lines.append(f"outcome: {summary.outcome}{reason}")
    return "\n".join(lines)


__all__ = [
    "GEOM_TYPES",
    "EpisodeRecorder",
    "NoteEvent",
    "RecordingSummary",
    "TransitionEvent",
    "format_summary",
    "read_recording",
]
