"""Write an episode to a rerun ``.rrd`` file: :class:`EpisodeRecorder`.

The layout is in :mod:`cpmp.recordings`; paths, texts, panels and blueprint in
:mod:`~cpmp.recordings.layout`; buffered columns in :mod:`~cpmp.recordings.columns`.
"""

from __future__ import annotations

import bisect
import json
import math
import os
import uuid
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING

import numpy as np
import rerun as rr

from cpmp.config.sequencer import SequencerConfig
from cpmp.errors import ConfigError, CpmpError, DataError
from cpmp.io import atomic_path
from cpmp.recordings.columns import ColumnBuffer
from cpmp.recordings.layout import (
    EVENT_ORDER,
    MARK_SIZE,
    MARK_STYLES,
    MARKS_ENTITY,
    NOTE_ARCHETYPE,
    OUTCOME_ARCHETYPE,
    PROPERTY_NAME,
    START_ARCHETYPE,
    START_ENTITY,
    STATUS_ENTITY,
    THRESHOLD_COLOR,
    THRESHOLD_ENTITY,
    TRANSITION_ARCHETYPE,
    WARN_COLOR,
    HoldEnd,
    StartReference,
    VariableSeries,
    blueprint,
    check_feature_groups,
    check_mp,
    entity,
    event_lines,
    geom_archetypes,
    group_features,
    hold_text,
    outcome_text,
    parse_geoms,
    pose_rows,
    reference_distances,
    series_color,
    series_label,
    start_labels,
    start_map,
    start_markdown,
    start_text,
    status_markdown,
    transition_text,
)
from cpmp.records import JsonValue, PendingSwitch, StartDecision
from cpmp.sequencer.inputs import checked_time

if TYPE_CHECKING:
    import numpy.typing as npt
    import rerun.blueprint as rrb

    from cpmp.recordings.layout import ParsedGeom

ROW_STEP = 1e-6
"""Time [s] between the rows of one event in the events log (:meth:`EpisodeRecorder._log_event`),
and after the last row of an event at the same time: far below a control tick, so an event's
rows stay at its time to the viewer's precision."""


@dataclass
class _Hold:
    """A hold the recorder has seen noted and not yet logged (it is logged when it ends).

    Attributes:
        t: when it was first noted [s].
        tick: the tick it was first noted at (-1: before the first tick).
        held: the MP the switch to which is held back.
        text: the sequencer's first note of it.
        count: how many times it was noted.
    """

    t: float
    tick: int
    held: str
    text: str
    count: int = 1


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
        threshold: the switching rule's threshold (the sequencer config's ``threshold``),
            drawn as a line in every p(switch) plot (``threshold`` series, from the first tick
            to the last); ``None``: no line.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        feature_names: Sequence[str],
        mp_names: Mapping[str, Sequence[str]],
        episode: str = "episode",
        application_id: str = "cpmp",
        geoms: Sequence[Mapping[str, str | npt.ArrayLike]] | None = None,
        metadata: Mapping[str, JsonValue] | None = None,
        flush_every: int = 5000,
        feature_groups: Mapping[str, Sequence[str]] | None = None,
        threshold: float | None = SequencerConfig.threshold,
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
        if threshold is not None and not math.isfinite(threshold):
            raise ConfigError(f"threshold must be a finite number or None, got {threshold}")
        self.threshold = None if threshold is None else float(threshold)
        self.feature_groups = (
            group_features(self.feature_names)
            if feature_groups is None
            else check_feature_groups(feature_groups, self.feature_names)
        )
        self.episode = str(episode)
        self.flush_every = int(flush_every)
        parsed_geoms = parse_geoms(geoms or [])
        self._scene = bool(parsed_geoms)
        """Whether anything 3D was logged (geoms or body poses): else the layout has no scene."""

        self._rr = rr
        self._feature_paths = tuple(entity("features", name) for name in self.feature_names)
        self._mp_index = {
            var: {mp: i for i, mp in enumerate(mps)} for var, mps in self.mp_names.items()
        }
        self._active: dict[str, str] = {}
        self._last_transition = ""
        self._last_note = ""
        self._start_line = ""
        self._start_features: dict[str, float] = {}
        self._start_bounds: tuple[tuple[float, float], tuple[float, float]] | None = None
        self._cause: PendingSwitch | None = None
        """The outcome's cause (:meth:`log_outcome`): the blueprint opens on its variable."""
        self._holds: dict[str, _Hold] = {}
        self._events: set[str] = set()
        self._event_rows: dict[float, int] = {}  # event time -> rows of the events log there
        self._progress_mps: dict[str, set[str]] = {v: set() for v in self.mp_names}
        self._targets: dict[str, set[str]] = {v: set() for v in self.mp_names}
        self._last_p: dict[str, dict[str, float]] = {}
        self._marks: dict[str, set[str]] = {v: set() for v in self.mp_names}
        self._n_ticks = 0
        self._tick_times: list[float] = []
        """Every tick's time [s], in order (an event logged later at an earlier time)."""
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
            # The default blueprint is sent by close(), once the logged series are known.
            self._rec.save(self._tmp)
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
            place = {
                name: (group, m)
                for group, members in self.feature_groups.items()
                for m, name in enumerate(members)
            }
            for path, name in zip(self._feature_paths, self.feature_names, strict=True):
                group, m = place[name]
                self._columns.name_series(path, series_label(group, name), series_color(m))
            if self.threshold is not None:
                self._rec.log(
                    THRESHOLD_ENTITY,
                    rr.SeriesLines(
                        names=[f"threshold {self.threshold:g}"], colors=[THRESHOLD_COLOR]
                    ),
                    static=True,
                )
            for geom in parsed_geoms:
                self._log_geom(geom)
        except BaseException:
            self.abort()
            raise

    def _log_geom(self, geom: ParsedGeom) -> None:
        local, shape = geom_archetypes(geom)
        self._rec.log(entity("world", geom["body"], geom["name"]), local, shape, static=True)

    def _check_open(self) -> None:
        if self._closed:
            raise CpmpError(f"recorder for {self.path} is closed")

    def _set_event_time(self, t: float, tick: int | None = None) -> None:
        self._rec.reset_time()
        self._rec.set_time("time", duration=t)
        tick = self._n_ticks - 1 if tick is None else tick
        if tick >= 0:
            self._rec.set_time("tick", sequence=tick)

    def _log_event(
        self,
        path: str,
        t: float,
        text: str,
        level: str = "INFO",
        record: tuple[str, Mapping[str, str | float]] | None = None,
        tick: int | None = None,
        first: int | None = None,
    ) -> int:
        """Log one event at ``t`` [s] to ``path``: its rows of the events log and its record.

        The first row (``"  3.25 s  <text>"``) carries the machine-readable ``record`` (its
        archetype's name and components, to which ``t`` is added: the row may sit later); a long
        ``text`` continues on indented rows (:func:`event_lines`), each :data:`ROW_STEP` after
        the one above it: rows at one time stamp come back in no set order (rerun 0.41 showed
        an event's second row above its first, and two events of one time with their rows
        interleaved), one microsecond apart they sort as written. So an event logged at the
        time of one logged before starts after that one's rows: its ``first`` row is
        ``ROW_STEP · first`` after ``t`` (``None``: the next free row at ``t``; another entity
        with the same rows, e.g. a variable's own copy, passes the value returned). Warnings
        are drawn in :data:`WARN_COLOR`.

        Returns:
            ``first``: how many rows of the events log were at ``t`` before this event's.
        """
        if first is None:
            first = self._event_rows.get(t, 0)
        self._set_event_time(t, tick)
        color = WARN_COLOR if level == "WARN" else None
        rows = [
            # clear_unset: a row without a colour is drawn uncoloured (the viewer would carry
            # the entity's last colour over to it)
            self._rr.TextLog.from_fields(clear_unset=True, text=line, level=level, color=color)
            for line in event_lines(t, text)
        ]
        self._event_rows[t] = max(self._event_rows.get(t, 0), first + len(rows))
        for k, row in enumerate(rows, start=first):
            if k:
                self._rec.set_time("time", duration=t + k * ROW_STEP)
            extra: list[rr.DynamicArchetype] = []
            if record is not None and k == first:
                name, components = record
                archetype = self._rr.DynamicArchetype(name, components={**components, "t": t})
                extra.append(archetype)
            self._rec.log(path, row, *extra)
        return first

    def _log_status(self, t: float, outcome: str = "") -> None:
        """The ``status`` document at ``t`` [s] (event time already set)."""
        text = status_markdown(
            self.episode,
            t,
            self._active,
            list(self.mp_names),
            self._last_transition,
            outcome,
            self._last_note,
            self._start_line,
        )
        self._rec.log(STATUS_ENTITY, self._rr.TextDocument(text, media_type="text/markdown"))

    def log_tick(
        self,
        t: float,
        features: Sequence[float] | np.ndarray,
        progress: Mapping[str, Mapping[str, float]],
        active: Mapping[str, str],
        transition_probs: Mapping[str, Mapping[str, float]] | None = None,
        body_poses: Mapping[str, tuple[npt.ArrayLike, npt.ArrayLike]] | None = None,
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
        transitions = {v: dict(p) for v, p in (transition_probs or {}).items()}
        for variable, seen in self._targets.items():
            # A target logged before but not a successor now gets NaN: its line breaks
            # (rerun draws no line across a NaN) instead of sliding across the gap.
            if seen and variable not in transitions:
                transitions[variable] = {}
        for variable, targets in transitions.items():
            if not targets and not self._targets.get(variable):
                continue
            index = self._mp_index.get(variable, {})
            for target in targets:
                if target not in index:
                    check_mp(self.mp_names, variable, target)
            seen = self._targets[variable]
            names = [mp for mp in self.mp_names[variable] if mp in targets or mp in seen]
            row = np.array([targets.get(mp, math.nan) for mp in names], dtype=float)
            rows.append((self._columns.transition_paths(variable, tuple(names)), row))
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
        for variable, phis in progress.items():
            self._progress_mps[variable].update(phis)
        for variable, targets in transitions.items():
            self._targets[variable].update(targets)
            self._last_p[variable] = targets
        if tick == 0:
            self._start_features = dict(zip(self.feature_names, values.tolist(), strict=True))
            self._log_threshold(t, tick)
        changed = False
        for variable, mp in active.items():
            if self._active.get(variable) != mp:
                if not changed:
                    self._rec.reset_time()
                    self._rec.set_time("time", duration=t)
                    self._rec.set_time("tick", sequence=tick)
                changed = True
                self._active[variable] = mp
                first, *more = event_lines(t, f"{variable}: {mp}")
                path = entity("active", variable)
                self._rec.log(path, self._rr.TextLog(first), self._rr.StateChange(state=[mp]))
                for line in more:
                    self._rec.log(path, self._rr.TextLog(line))
        if changed:
            self._log_status(t)
        if poses is not None:
            self._scene = True
            bodies, positions, quats = poses
            self._columns.add_poses(bodies, tick, t, positions, quats)

        self._n_ticks += 1
        self._last_t = t
        self._tick_times.append(t)
        self._buffered_ticks += 1
        if self._buffered_ticks >= self.flush_every:
            self._flush_buffers()

    def _log_threshold(self, t: float, tick: int) -> None:
        """One point of the threshold line at ``t`` [s] (the first and the last tick's)."""
        if self.threshold is not None:
            self._set_event_time(t, tick)
            self._rec.log(THRESHOLD_ENTITY, self._rr.Scalars(self.threshold))

    def _log_mark(self, variable: str, kind: str, t: float, p: float | None) -> None:
        """Mark a ``kind`` event of ``variable`` at ``t`` [s] on its p plots, at height ``p``.

        No mark for a kind without a style (:data:`MARK_STYLES`) or a non-finite ``p``.
        """
        if kind not in MARK_STYLES or p is None or not math.isfinite(p):
            return
        path = entity(MARKS_ENTITY, variable, kind)
        if kind not in self._marks[variable]:
            self._marks[variable].add(kind)
            color, marker = MARK_STYLES[kind]
            points = self._rr.SeriesPoints(
                names=[kind], colors=[color], markers=[marker], marker_sizes=[MARK_SIZE]
            )
            self._rec.log(path, points, static=True)
        self._set_event_time(t)
        self._rec.log(path, self._rr.Scalars(float(p)))

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
        record = (
            TRANSITION_ARCHETYPE,
            {
                "variable": variable,
                "source": source,
                "target": target,
                "probability": probability,
                "kind": str(kind),
            },
        )
        if variable in self._holds:
            self._end_hold(variable, t, "switch", target)
        level = "WARN" if kind == "recovery" else "INFO"
        self._log_mark(variable, str(kind), t, probability)
        self._events.add("events/transitions")
        first = self._log_event("events/transitions", t, text, level, record)
        self._log_event(entity("events", "transitions", variable), t, text, level, first=first)
        self._last_transition = f"{text} at {t:.2f} s"
        self._set_event_time(t)
        self._log_status(t)

    def log_note(
        self, t: float, kind: str, variable: str, text: str, *, held: str | None = None
    ) -> None:
        """Record a sequencer note at ``t`` [s] about ``variable`` (may be empty).

        The note is a held transition, a stall recovery or a non-finite φ (``kind``), as
        readable ``text``. A ``hold`` note that names the MP it holds back (``held``) is one
        hold until ``variable`` switches: the sequencer notes it again each time its ``p``
        dips below the threshold and crosses it again, and the recording logs it once, at its
        first note, with how long it lasted and how many times it was noted
        (:func:`~cpmp.recordings.layout.hold_text`) — written when it ends (the switch,
        a hold to another MP, the outcome or :meth:`close`).

        Raises:
            UnknownMPError: ``held`` is given and not an MP of ``variable``.
        """
        self._check_open()
        t = checked_time(t)
        if kind == "hold" and held is not None:
            check_mp(self.mp_names, variable, held)
            current = self._holds.get(variable)
            if current is not None and current.held == held:
                current.count += 1
                return
            if current is not None:
                self._end_hold(variable, t, "hold", held)
            self._holds[variable] = _Hold(t, self._n_ticks - 1, held, str(text))
            # at the held target's p of the last tick, else on the threshold line
            p = self._last_p.get(variable, {}).get(held, self.threshold)
            self._log_mark(variable, "hold", t, p)
            self._events.add("events/notes")
        else:
            record = (
                NOTE_ARCHETYPE,
                {"kind": str(kind), "variable": str(variable), "text": str(text)},
            )
            level = "WARN" if kind in ("recovery", "nonfinite", "give_up") else "INFO"
            self._events.add("events/notes")
            self._log_event("events/notes", t, f"{kind}: {text}", level, record)
        self._last_note = f"{kind} at {t:.2f} s: {text}"
        self._set_event_time(t)
        self._log_status(t)

    def _end_hold(self, variable: str, end: float, ended_by: HoldEnd, then: str = "") -> None:
        """Log ``variable``'s open hold, at its first note, now that it ended at ``end`` [s].

        Its ``cpmp.Note`` record has the sequencer's first text and, besides, ``held`` (the
        MP held back), ``until`` [s], ``count`` (times noted), ``ended_by`` and ``then`` (what
        ended it, :func:`~cpmp.recordings.layout.hold_text`).
        """
        hold = self._holds.pop(variable)
        record = (
            NOTE_ARCHETYPE,
            {
                "kind": "hold",
                "variable": variable,
                "text": hold.text,
                "held": hold.held,
                "until": float(end),
                "count": hold.count,
                "ended_by": ended_by,
                "then": then,
            },
        )
        text = hold_text(hold.text, hold.t, end, ended_by, hold.count, variable, then)
        self._log_event("events/notes", hold.t, f"hold: {text}", "INFO", record, hold.tick)

    def _end_holds(self, end: float) -> None:
        """Log every open hold as lasting until the episode's end at ``end`` [s]."""
        for variable in list(self._holds):
            self._end_hold(variable, max(end, self._holds[variable].t), "end")

    def log_start(
        self,
        decision: StartDecision,
        references: Sequence[StartReference] = (),
        axes: Sequence[str] = (),
        *,
        correct: Mapping[str, str] | None = None,
        values: Mapping[str, float] | None = None,
    ) -> None:
        """Record how the initial MPs were chosen, at the decision's time.

        The decision (``events/start``: a line of the events log and the machine-readable
        ``cpmp.Start`` record) and the ``start`` document: the starts weighed with their
        scores (the ``correct`` one marked), this episode's start against the training starts
        ``references`` in ``axes``, and every feature at the start. With two ``axes``,
        ``start/boxes`` maps the training starts (coloured by their initial combination) and
        this episode's start (black) in those two, with tick values, axis titles and a colour
        key (:func:`~cpmp.recordings.layout.start_map`).

        Args:
            decision: the sequencer's start decision (``SequencerEpisode.start_decision``).
            references: the training demonstrations' starts.
            axes: what to compare the starts in: features, or keys of ``values`` (the unit in
                the name, e.g. ``box_width_m``); every reference's ``values`` holds each.
            correct: the initial MPs the demonstrator uses for this episode (some or all
                variables; ``None``: unknown).
            values: this episode's value of each axis that is not a feature.

        Raises:
            UnknownMPError: an MP of ``decision`` or ``correct`` is not in ``mp_names``.
            ConfigError: an axis is neither a feature nor in ``values``, or a reference lacks
                one.
        """
        self._check_open()
        t = checked_time(decision.t)
        for option in decision.options:
            for variable, mp in option.combination.items():
                check_mp(self.mp_names, variable, mp)
        for variable, mp in (correct or {}).items():
            check_mp(self.mp_names, variable, mp)
        values = {str(k): float(v) for k, v in (values or {}).items()}
        axes = [str(a) for a in axes]
        unknown = [a for a in axes if a not in self.feature_names and a not in values]
        missing = [r.name for r in references if any(a not in r.values for a in axes)]
        if unknown or missing:
            raise ConfigError(
                f"start axes must be features or given values, and in every reference: "
                f"unknown {unknown}, references without them {missing}"
            )
        record = (
            START_ARCHETYPE,
            {
                "rule": decision.rule,
                "chosen": json.dumps(decision.chosen, sort_keys=True),
                "options": json.dumps(
                    [{"combination": o.combination, "score": o.score} for o in decision.options]
                ),
                "correct": json.dumps(dict(correct or {}), sort_keys=True),
                "references": json.dumps(
                    [
                        {
                            "name": ref.name,
                            "combination": ref.combination,
                            "values": {a: ref.values[a] for a in axes if a in ref.values},
                            "distance": dist,
                        }
                        for ref, dist in reference_distances(
                            {**self._start_features, **values}, references, axes
                        )
                    ]
                ),
            },
        )
        self._start_line = start_text(decision)
        self._events.add("events/start")
        self._log_event("events/start", t, self._start_line, "INFO", record)
        self._set_event_time(t)
        mapped = len(axes) >= 2 and bool(references)
        document = start_markdown(
            decision,
            self._start_features,
            references,
            axes,
            correct=correct,
            values=values,
            colours=mapped,
        )
        self._rec.log(START_ENTITY, self._rr.TextDocument(document, media_type="text/markdown"))
        if mapped:
            here = {**self._start_features, **values}
            point = [here[a] for a in axes[:2]] if all(a in here for a in axes[:2]) else None
            combos = start_labels(decision, references)
            drawn = start_map(references, axes[:2], point, combos)
            for path, archetype in drawn.entities:
                self._rec.log(path, archetype)
            self._start_bounds = (drawn.x_range, drawn.y_range)
        self._log_status(t)

    def log_outcome(
        self,
        t: float,
        outcome: str,
        reason: str = "",
        *,
        success: bool | None = None,
        cause: PendingSwitch | None = None,
    ) -> None:
        """Record the episode's outcome (e.g. ``"complete"``) at ``t`` [s], with a reason.

        ``success=False`` logs it at level ``WARN`` (drawn in the viewer's warning colour),
        otherwise ``INFO``. The ``status`` document at ``t`` shows the outcome too. ``cause``:
        an incomplete episode's missing switch; its words end the outcome text (unless
        ``reason`` holds them already), its fields ride along in the outcome record
        (``cause``, JSON), and an event at the time its ``p`` was best (else at ``t``) names it.
        """
        self._check_open()
        t = checked_time(t)
        if not str(outcome):
            raise DataError("outcome must be a non-empty string")
        reason = str(reason)
        components = {"outcome": str(outcome), "reason": reason}
        level = "WARN" if success is False else "INFO"
        if cause is not None:
            self._cause = cause
            words = cause.describe()
            if words not in reason:
                reason = f"{reason}; {words}" if reason else words
            components = {**components, "reason": reason, "cause": json.dumps(cause.to_dict())}
            self._log_cause(t, cause, level)
        text = outcome_text(str(outcome), reason)
        record = (OUTCOME_ARCHETYPE, components)
        self._end_holds(t)
        self._events.add("events/outcome")
        self._log_event("events/outcome", t, text, level, record)
        self._set_event_time(t)
        self._log_status(t, outcome=text)

    def _log_cause(self, t: float, cause: PendingSwitch, level: str) -> None:
        """The event naming ``cause`` at the time its ``p`` was best (else at ``t`` [s])."""
        at = cause.best_t if math.isfinite(cause.best_t) and cause.best_t <= t else t
        tick = max(bisect.bisect_right(self._tick_times, at + 1e-9) - 1, 0)
        self._events.add("events/outcome")
        self._log_event("events/outcome", at, f"cause: {cause.describe()}", level, None, tick)

    def close(self) -> Path:
        """Flush, finish the file and move it onto ``path``; returns ``path``. Idempotent."""
        if self._closed:
            return self.path
        try:
            self._end_holds(self._last_t if math.isfinite(self._last_t) else 0.0)
            if self._n_ticks > 1:
                self._log_threshold(self._last_t, self._n_ticks - 1)
            self._flush_buffers()
            self._rec.send_blueprint(self._blueprint(), make_active=True, make_default=True)
            self._rec.flush()
            self._rec.disconnect()
        except BaseException:
            self.abort()
            raise
        self._closed = True
        self._atomic.__exit__(None, None, None)
        return self.path

    def _blueprint(self) -> rrb.Blueprint:
        """The default layout for what was logged (:func:`~cpmp.recordings.layout.blueprint`).

        An episode that ended at its first tick with a start decision logged (a wrong start)
        gets the start decision in the middle.
        """
        series = {
            v: VariableSeries(
                [mp for mp in mps if mp in self._progress_mps[v]],
                [mp for mp in mps if mp in self._targets[v]],
            )
            for v, mps in self.mp_names.items()
        }
        started = bool(self._start_line)
        return blueprint(
            self.feature_groups,
            series,
            start=started,
            start_focus=started and self._n_ticks <= 1,
            events=sorted(self._events, key=EVENT_ORDER.index),
            threshold=self.threshold is not None and self._n_ticks > 0,
            marks={v: [k for k in MARK_STYLES if k in kinds] for v, kinds in self._marks.items()},
            duration=self._last_t if self._n_ticks > 1 else None,
            start_bounds=self._start_bounds,
            scene=self._scene,
            focus=self._cause.variable if self._cause is not None else None,
            focus_time=self._focus_time(),
        )

    def _focus_time(self) -> tuple[float, float] | None:
        """The span [s] of the failed variable's pending switch.

        From the time of its best ``p`` (the last tick if it has none) to the last tick;
        ``None`` without a cause or a variable to focus on.
        """
        cause = self._cause
        if cause is None or not cause.variable or not math.isfinite(self._last_t):
            return None
        start = cause.best_t if math.isfinite(cause.best_t) else self._last_t
        return (min(start, self._last_t), self._last_t)

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
