"""Write an episode to a rerun ``.rrd`` file: :class:`EpisodeRecorder`.

The layout is in :mod:`cpmp.recordings`; paths, texts, panels and blueprint in
:mod:`~cpmp.recordings.layout`; buffered columns in :mod:`~cpmp.recordings.columns`.
"""

from __future__ import annotations

import json
import math
import os
import uuid
from collections.abc import Mapping, Sequence
from pathlib import Path
from types import TracebackType
from typing import Any

import numpy as np
import rerun as rr

from cpmp.errors import ConfigError, CpmpError, DataError
from cpmp.io import atomic_path
from cpmp.recordings.columns import ColumnBuffer
from cpmp.recordings.layout import (
    NOTE_ARCHETYPE,
    OUTCOME_ARCHETYPE,
    PROPERTY_NAME,
    STATUS_ENTITY,
    TRANSITION_ARCHETYPE,
    blueprint,
    check_feature_groups,
    check_mp,
    entity,
    geom_archetypes,
    group_features,
    outcome_text,
    parse_geom,
    pose_rows,
    status_markdown,
    transition_text,
)
from cpmp.sequencer.inputs import checked_time


class EpisodeRecorder:
    """Record one episode to a rerun ``.rrd`` file (layout: :mod:`cpmp.recordings`).

    Use as a context manager, or call :meth:`close` (keep the file) or :meth:`abort` (discard).

    Args:
        path: target ``.rrd`` file; its directory must exist. Written only by :meth:`close`.
        feature_names: names of the F features passed to :meth:`log_tick`, in order.
        mp_names: control variable -> names of its MPs (graph nodes).
        episode: episode name, shown in the viewer and returned by
            :func:`~cpmp.recordings.read_recording`.
        application_id: rerun application id (recordings with the same id share viewer
            blueprints).
        geoms: static visual geometry, dicts with ``body`` (str), ``type`` (one of
            :data:`~cpmp.recordings.GEOM_TYPES`), ``size`` (MuJoCo convention: box
            half-extents (3,) [m]; capsule/cylinder ``[radius, half-length]`` along the local z
            axis; sphere ``[radius]``; longer arrays, as MuJoCo's ``geom_size`` (3,), are
            fine), optional ``pos`` (3,) [m] and ``quat`` (4,) wxyz in the body frame, ``rgba``
            (4,) in [0, 1], ``name``.
        metadata: free-form JSON-able episode information, stored as a recording property.
        flush_every: send buffered per-tick data to the file every this many ticks (and on
            :meth:`close`). The default holds a 50 s episode at 100 Hz, so an episode that is
            discarded with :meth:`abort` (``record=failures`` keeps only failures) never pays
            for sending its columns.
        feature_groups: panel name -> feature names, one time-series panel each; features in
            no group go to ``other``. Default:
            :func:`~cpmp.recordings.group_features` of ``feature_names``.
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
            else check_feature_groups(feature_groups, self.feature_names)
        )
        self.episode = str(episode)
        self.flush_every = int(flush_every)
        parsed_geoms = [parse_geom(i, geom) for i, geom in enumerate(geoms or [])]

        self._rr = rr
        self._feature_paths = tuple(entity("features", name) for name in self.feature_names)
        self._mp_index = {
            var: {mp: i for i, mp in enumerate(mps)} for var, mps in self.mp_names.items()
        }
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
            self._columns = ColumnBuffer(self._rec, self.mp_names)
            self._rec.save(
                self._tmp, default_blueprint=blueprint(self.feature_groups, list(self.mp_names))
            )
            self._rec.send_recording_name(self.episode)
            self._rec.send_property(
                PROPERTY_NAME,
                rr.AnyValues(
                    episode=self.episode,
                    feature_names=json.dumps(self.feature_names),
                    feature_groups=json.dumps(self.feature_groups),
                    mp_names=json.dumps(self.mp_names),
                    metadata=json.dumps(dict(metadata or {}), default=str, sort_keys=True),
                ),
            )
            for path, name in zip(self._feature_paths, self.feature_names, strict=True):
                self._columns.name_series(path, name)
            for geom in parsed_geoms:
                self._log_geom(geom)
        except BaseException:
            self.abort()
            raise

    def _log_geom(self, geom: dict[str, Any]) -> None:
        local, shape = geom_archetypes(geom)
        self._rec.log(entity("world", geom["body"], geom["name"]), local, shape, static=True)

    def _check_open(self) -> None:
        if self._closed:
            raise CpmpError(f"recorder for {self.path} is closed")

    def _set_event_time(self, t: float) -> None:
        self._rec.reset_time()
        self._rec.set_time("time", duration=t)
        if self._n_ticks:
            self._rec.set_time("tick", sequence=self._n_ticks - 1)

    def _log_status(self, t: float, outcome: str = "") -> None:
        """The ``status`` document at ``t`` [s] (event time already set)."""
        text = status_markdown(
            self.episode, t, self._active, list(self.mp_names), self._last_transition, outcome
        )
        self._rec.log(STATUS_ENTITY, self._rr.TextDocument(text, media_type="text/markdown"))

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
                rows.append((self._columns.progress_paths(variable, tuple(phis)), row))
        for variable, targets in (transition_probs or {}).items():
            if targets:
                row = np.fromiter(targets.values(), dtype=float, count=len(targets))
                rows.append((self._columns.transition_paths(variable, tuple(targets)), row))
        if active:
            indices = np.empty(len(active))
            for i, (variable, mp) in enumerate(active.items()):
                index = self._mp_index.get(variable, {}).get(mp)
                if index is None:
                    check_mp(self.mp_names, variable, mp)
                indices[i] = index
            rows.append((self._columns.index_paths(tuple(active)), indices))
        poses = pose_rows(body_poses) if body_poses else None

        tick = self._n_ticks
        for paths, row in rows:
            self._columns.add_row(paths, tick, t, row)
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
                    entity("active", variable),
                    self._rr.TextLog(f"{variable}: {mp}"),
                    self._rr.StateChange(state=[mp]),
                )
        if changed:
            self._log_status(t)
        if poses is not None:
            bodies, positions, quats = poses
            self._columns.add_poses(bodies, tick, t, positions, quats)

        self._n_ticks += 1
        self._last_t = t
        self._buffered_ticks += 1
        if self._buffered_ticks >= self.flush_every:
            self._flush_buffers()

    def _flush_buffers(self) -> None:
        self._columns.send()
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
        """Record that ``variable`` switched from MP ``source`` to ``target`` at ``t`` [s].

        ``kind``: ``switch`` or ``recovery``.
        """
        self._check_open()
        t = checked_time(t)
        check_mp(self.mp_names, variable, source)
        check_mp(self.mp_names, variable, target)
        probability = float(probability)
        text = transition_text(variable, source, target, probability, str(kind))
        record = self._rr.DynamicArchetype(
            TRANSITION_ARCHETYPE,
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
        self._rec.log(entity("events", "transitions", variable), self._rr.TextLog(text))
        self._last_transition = f"{text} at {t:.2f} s"
        self._log_status(t)

    def log_note(self, t: float, kind: str, variable: str, text: str) -> None:
        """Record a sequencer note at ``t`` [s] about ``variable`` (may be empty).

        The note is a held transition, a stall recovery or a non-finite φ (``kind``), as
        readable ``text``.
        """
        self._check_open()
        t = checked_time(t)
        record = self._rr.DynamicArchetype(
            NOTE_ARCHETYPE,
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
            OUTCOME_ARCHETYPE, components={"outcome": str(outcome), "reason": str(reason)}
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


__all__ = ["EpisodeRecorder"]
