"""Rerun recordings of episodes: write them, read them back offline.

Write with :class:`EpisodeRecorder` (:mod:`~cpmp.recordings.writer`), read back offline with
:func:`read_recording` and :func:`read_views` (:mod:`~cpmp.recordings.reader`). Every name is
importable from here. The layout below (entity paths, record names, log texts, feature
panels, blueprint, 3D scene) is written down in :mod:`~cpmp.recordings.layout`, which both
sides use; the per-tick series are buffered by :mod:`~cpmp.recordings.columns`.

Layout of a recording (one ``.rrd`` file per episode). Time-series data sit on two timelines:
``time`` (a duration, seconds since the episode start) and ``tick`` (sequence, 0-based index of
the :meth:`EpisodeRecorder.log_tick` call).

=====================================  ===================================================
entity path                            content
=====================================  ===================================================
``world/<body>``                       ``Transform3D`` per tick: body pose in the world
                                       (a wrong start too: it has one tick, at t = 0)
``world/<body>/<geom>``                static ``Transform3D`` (geom pose in the body frame)
                                       and one of ``Boxes3D``/``Capsules3D``/
                                       ``Cylinders3D``/``Ellipsoids3D`` (sphere); ``<geom>``
                                       is the geom's ``name``, default ``geom_<i>``
``features/<name>``                    ``Scalars``: one feature per entity (static
                                       ``SeriesLines``: the feature name less its panel's,
                                       a colour of its own in the panel)
``progress/<variable>/<mp>/phi``       ``Scalars``: predicted progress φ of the node
``progress/<variable>/<mp>/entry``     ``Scalars``: 1 - φ
``progress/<variable>/<mp>/exit``      ``Scalars``: φ
``transition/<variable>/<target>``     ``Scalars``: transition probability to ``target``
                                       from the active MP; NaN while ``target`` is not a
                                       successor of the active MP (the line breaks)
``threshold``                          ``Scalars`` at the first and the last tick: the
                                       switching rule's threshold (static grey
                                       ``SeriesLines`` ``"threshold 0.65"``), drawn in
                                       every p(switch) plot
``marks/<variable>/<kind>``            ``Scalars`` at each switch, recovery (at its p) and
                                       hold (at the held target's p, at its first note)
                                       of ``variable`` (static ``SeriesPoints``: a marker
                                       and colour per kind), drawn in its p(switch) plots
``active/<variable>``                  ``TextLog`` ``"  0.44 s  <variable>: <mp>"`` and
                                       ``StateChange`` ``<mp>`` when the active MP changes
``active/<variable>/index``            ``Scalars`` per tick: index of the active MP in
                                       ``mp_names[variable]``
``status``                             ``TextDocument`` (markdown), logged when an active
                                       MP changes, at each transition and note, at the
                                       start decision and at the outcome: the active MP of
                                       every variable, the last transition, the last note
                                       in full, the start decision, the outcome
``start``                              ``TextDocument`` (markdown) at the start decision:
                                       the starts weighed with their scores, the episode's
                                       start against the training starts, the features
``start/boxes/training``, ``/episode`` ``Points2D``: the training starts (colour: their
                                       initial MPs) and this episode's start in two
                                       axes (:meth:`EpisodeRecorder.log_start`); beside
                                       them ``/axes``, ``/tick_values``, ``/axis_titles``,
                                       ``/key``, and the names on anchors of their own
``events/start``                       ``TextLog`` ``"  0.00 s  start (joint rule, ...)"``
                                       plus the machine-readable ``cpmp.Start`` record
``events/transitions``                 ``TextLog`` ``"  0.44 s  left_pos: approach -> grasp
                                       (p=0.71) [switch]"`` plus the machine-readable
                                       ``cpmp.Transition`` record
``events/transitions/<variable>``      the same ``TextLog``, per control variable
``events/notes``                       ``TextLog`` ``"  1.09 s  <kind>: <text>"`` plus
                                       ``cpmp.Note``; a hold once, at its first note, with
                                       how long it lasted and how often it was noted
                                       (``"...; held 0.63 s, until left_fingers switched
                                       to relax at 9.91 s (noted 3 times)"``)
``events/outcome``                     ``TextLog`` ``" 10.75 s  outcome: <outcome>
                                       (<reason>)"`` at the episode end (level ``WARN`` for
                                       a failure) plus the ``cpmp.Outcome`` record; an
                                       incomplete episode's cause also as ``"cause: <edge>
                                       never fired: ..."`` when its ``p`` was best
=====================================  ===================================================

An event's text longer than :data:`EVENT_WIDTH` characters continues on indented rows of
the same entity (:func:`event_lines`; rerun 0.41's text log shows one line per row), each a
microsecond after the one above it, and an event logged at the time of an earlier one starts
after that one's rows (rows of one time stamp show in no set order); the record is in the first
row. Warnings (level ``WARN``: recoveries, give-ups, non-finite
features, a failed outcome) are drawn in an orange of their own.

Blueprint (the viewer's default layout, sent when the recording is closed, for what it holds):
the 3D scene above the ``status`` document; a tab per feature group (:func:`group_features`:
box, each hand, goal distances, touch, ... from the feature names, at most 8 series each), a
plot as wide as the column; a tab per control variable with its φ (= exit), entry and transition
probabilities, an MP in one colour in all three and named by φ's legend only; above the feature
tabs, a grid of one small p(switch) plot per variable (every variable at once, without a click);
every p(switch) plot with the threshold line and the variable's event marks; the legends in the
plots' top-left corner, left of the curves (a plot with a legend starts its time axis before
t = 0); the active MPs as lanes of a state timeline; the events log (start, transitions, notes,
outcome) in a monospace font, each event starting with its time, and beside it in tabs the
``start`` document and the start map (the right column is the wider side one: the start's tables
fit it at 1440 px). Every view lists the entity paths it shows (rerun 0.41 matches no wildcard
in the middle of a path). An episode that ended at its first tick (a wrong start) puts the start
decision in the middle instead of the plots and the start map on the right. The blueprint and
selection panels start collapsed, the time panel as one row. :func:`read_views` lists the views.

Machine-readable encoding. Transitions and outcomes are logged, in the same row as their
``TextLog``, as ``rr.DynamicArchetype`` records whose columns read back as
``cpmp.Transition:{variable,source,target,probability,kind}`` (strings, and a float64
probability), ``cpmp.Note:{kind,variable,text}`` (a hold's also ``held``, ``until`` [s],
``count``, ``ended_by`` and ``then``), ``cpmp.Outcome:{outcome,reason,cause}`` (``cause``: the
:class:`~cpmp.records.PendingSwitch` as JSON, if any) and ``cpmp.Start:{rule,chosen,options}``
(strings; ``chosen`` and ``options`` as JSON), each with the event's time ``t`` [s] (float64;
its row's time on the ``time`` timeline may be a few microseconds later, after the rows of an
event logged before it at that time). The episode name is the recording name
(``RecordingInfo:name`` property) and the recording property ``cpmp`` holds ``episode``,
``feature_names``, ``feature_groups``, ``mp_names`` and ``metadata`` (all but the first as JSON
text; metadata values that JSON cannot encode are stored as ``str``).

Scalars and body poses are buffered and sent column-wise (``send_columns``) every
``flush_every`` ticks (default 5000) and on :meth:`EpisodeRecorder.close`, one row per tick and
tuple of entities: one ``rr.log`` call per entity and tick would cost more than the simulation
itself (see docs/benchmarks.md), and an aborted episode sends nothing. The file is written
beside the target under a temporary name and renamed onto it only by a successful
:meth:`EpisodeRecorder.close`, so a failed or aborted episode leaves no partial file.
"""

from __future__ import annotations

# ruff: noqa: E402
# The extra is checked before the imports that need it.
from cpmp.errors import require as _require

_require("rerun", "rerun", "cpmp.recordings (rerun .rrd files)")

from cpmp.recordings.layout import (
    EVENT_WIDTH,
    GEOM_TYPES,
    MAX_SERIES_PER_PANEL,
    TOUCH_WORDS,
    StartReference,
    event_lines,
    group_features,
    outcome_text,
    transition_text,
)
from cpmp.recordings.reader import (
    RecordingSummary,
    SequencerNote,
    TransitionEvent,
    ViewInfo,
    format_summary,
    read_recording,
    read_views,
)
from cpmp.recordings.writer import EpisodeRecorder

__all__ = [
    "EVENT_WIDTH",
    "GEOM_TYPES",
    "MAX_SERIES_PER_PANEL",
    "TOUCH_WORDS",
    "EpisodeRecorder",
    "RecordingSummary",
    "SequencerNote",
    "StartReference",
    "TransitionEvent",
    "ViewInfo",
    "event_lines",
    "format_summary",
    "group_features",
    "outcome_text",
    "read_recording",
    "read_views",
    "transition_text",
]
