"""What a recording must show to explain the sequencer's decisions, one test per defect seen in
rerun 0.41's viewer (#22): the blueprint names the logged entities, transition lines break
where their source MP is inactive, every series of a panel has its own colour, the start
decision is recorded with its scores, a hold is noted once, the events log carries its times."""

from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from rerun.chunk import RrdReader

from cpmp.experiment.reproduction import EpisodeLogger, start_references
from cpmp.recordings import EpisodeRecorder, StartReference, read_recording, read_views
from cpmp.recordings.layout import blueprint_paths, series_label
from cpmp.records import SequencerNote, StartDecision, StartOption, TickInfo, TransitionEvent
from cpmp.worlds.two_point import make_demonstrations

MP_NAMES = {"a": ["a_go", "a_wait", "a_back"], "b": ["b_go", "b_back"]}
FEATURES = ["box_width", "box_depth", "left_x", "left_y"]
DT = 0.1


def _column(path: Path, entity: str, column: str) -> list:
    """Values of one component column of one entity, in time order."""
    rows = []
    for chunk in RrdReader(path).stream():
        if chunk.entity_path != f"/{entity}":
            continue
        batch = chunk.to_record_batch()
        if column in batch.schema.names:
            times = batch.column("time").to_pylist() if "time" in batch.schema.names else None
            values = batch.column(column).to_pylist()
            rows += zip(times or [0] * len(values), values, strict=True)
    return [value for _, value in sorted(rows, key=lambda row: row[0])]


def _episode(path: Path, ticks: int = 6, start: bool = True) -> Path:
    """``a`` runs a_go (successor a_wait) for 2 ticks, a_wait (successor a_back) for 2, then
    a_go again: the probability to a_wait is logged, absent, logged."""
    decision = StartDecision(
        0.0,
        "joint",
        [
            StartOption({"a": "a_go", "b": "b_go"}, -0.2),
            StartOption({"a": "a_wait", "b": "b_go"}, -1.5),
        ],
        {"a": "a_go", "b": "b_go"},
    )
    references = [
        StartReference("demo_0", {"a": "a_go", "b": "b_go"}, dict.fromkeys(FEATURES, 0.2)),
        StartReference("demo_1", {"a": "a_wait", "b": "b_go"}, dict.fromkeys(FEATURES, 0.6)),
    ]
    with EpisodeRecorder(path, feature_names=FEATURES, mp_names=MP_NAMES) as recorder:
        for tick in range(ticks):
            t = tick * DT
            a = ["a_go", "a_go", "a_wait", "a_wait", "a_go", "a_go"][tick]
            successor = {"a_go": "a_wait", "a_wait": "a_back"}[a]
            recorder.log_tick(
                t,
                [0.3, 0.3, tick, -tick],
                {"a": {mp: 0.1 * tick for mp in MP_NAMES["a"]}, "b": {"b_go": 0.5}},
                {"a": a, "b": "b_go"},
                {"a": {successor: 0.05 * tick}, "b": {"b_back": 0.2}},
            )
            if tick == 0 and start:
                recorder.log_start(decision, references, ["box_width", "box_depth"])
        recorder.log_outcome(ticks * DT, "complete", "done")
    return path


def test_every_view_names_logged_entities_and_every_phi_is_in_a_view(tmp_path):
    """rerun 0.41 matches no ``$origin/*/phi``: the views list the paths themselves, each one
    logged, and every φ, entry and transition series logged is in a view."""
    path = _episode(tmp_path / "e.rrd")
    views = read_views(path)
    logged = set(read_recording(path).entity_paths)
    named = blueprint_paths(views)
    # a wildcard may end a query ($origin/**); one in the middle matched nothing in rerun 0.41
    assert not [line for v in views for line in v.contents if "*" in line.rsplit("/", 1)[0]]
    assert set(named) <= logged, set(named) - logged
    for quantity in ("phi", "entry"):
        wanted = {p for p in logged if p.startswith("progress/") and p.endswith(f"/{quantity}")}
        assert wanted and wanted <= set(named)
    transitions = {p for p in logged if p.startswith("transition/")}
    assert transitions == {"transition/a/a_wait", "transition/a/a_back", "transition/b/b_back"}
    assert transitions <= set(named)
    (phi_a,) = [v for v in views if v.name == "φ (exit)" and v.origin == "progress/a"]
    assert phi_a.contents == [f"+ progress/a/{mp}/phi" for mp in MP_NAMES["a"]]


def test_a_transition_line_breaks_while_its_source_is_inactive(tmp_path):
    """``to a_wait`` is logged while a_go runs, NaN while a_wait runs, logged again after: the
    viewer draws no line across a NaN, so the plot does not slide across the gap."""
    path = _episode(tmp_path / "e.rrd")
    values = [v[0] for v in _column(path, "transition/a/a_wait", "Scalars:scalars")]
    assert values[:2] == pytest.approx([0.0, 0.05])
    assert [math.isnan(v) for v in values] == [False, False, True, True, False, False]
    back = [v[0] for v in _column(path, "transition/a/a_back", "Scalars:scalars")]
    assert [math.isnan(v) for v in back] == [False, False, True, True]  # from its first tick


def test_series_of_a_panel_have_distinct_colours_shared_across_panels(tmp_path):
    path = _episode(tmp_path / "e.rrd")
    phi = {
        mp: _column(path, f"progress/a/{mp}/phi", "SeriesLines:colors")[0][0]
        for mp in MP_NAMES["a"]
    }
    assert len(set(phi.values())) == 3
    for mp, colour in phi.items():  # the same MP, the same colour, in every panel
        assert _column(path, f"progress/a/{mp}/entry", "SeriesLines:colors")[0][0] == colour
    assert _column(path, "transition/a/a_wait", "SeriesLines:colors")[0][0] == phi["a_wait"]
    features = [_column(path, f"features/{n}", "SeriesLines:colors")[0][0] for n in FEATURES]
    groups = read_recording(path).feature_groups
    for members in groups.values():
        colours = [features[FEATURES.index(n)] for n in members]
        assert len(set(colours)) == len(colours)


def test_series_label_drops_the_panel_name():
    assert series_label("dist.left", "dist.left_fingers.grasp") == "fingers.grasp"
    assert series_label("box", "box_width") == "width"
    assert series_label("arm_q 2", "arm_q_7") == "7"
    assert series_label("touch", "box_supported") == "box_supported"
    assert series_label("box", "box") == "box"


def test_the_start_decision_and_its_scores_are_recorded(tmp_path):
    path = _episode(tmp_path / "e.rrd")
    summary = read_recording(path)
    start = summary.start
    assert (
        start is not None and start.rule == "joint" and start.chosen == {"a": "a_go", "b": "b_go"}
    )
    assert [(o.combination, o.score) for o in start.options] == [
        ({"a": "a_go", "b": "b_go"}, -0.2),
        ({"a": "a_wait", "b": "b_go"}, -1.5),
    ]
    (document,) = _column(path, "start", "TextDocument:text")
    text = document[0]
    assert "| **chosen** | -0.20 | a=a_go |" in text and "|  | -1.50 | a=a_wait |" in text
    assert "The same in every start: b=b_go." in text
    # the episode's box against the training boxes, nearest first
    assert text.index("| demo_0 | 0.200 | 0.200 | 0.35 | a=a_go |") < text.index("| demo_1 |")
    assert "start (joint rule, 2 demonstrated starts): a=a_go" in format_line(path)
    assert {"start/boxes/training", "start/boxes/episode"} <= set(summary.entity_paths)
    views = {v.name: v for v in read_views(path)}
    assert views["start"].kind == "TextDocument" and views["start map"].kind == "2D"


def format_line(path: Path) -> str:
    (line,) = _column(path, "events/start", "TextLog:text")
    return line[0]


def test_an_episode_that_ends_at_its_first_tick_shows_its_start(tmp_path):
    """A wrong start ends at t = 0: its layout puts the start decision in the middle (the plots
    would hold one point each)."""
    one = _episode(tmp_path / "one.rrd", ticks=1)
    views = [v.name for v in read_views(one)]
    assert "start" in views and "φ (exit)" not in views and "box" not in views
    full = [v.name for v in read_views(_episode(tmp_path / "full.rrd"))]
    assert "φ (exit)" in full and "box" in full and "start" in full


def test_a_hold_is_noted_once_until_its_variable_switches(tmp_path):
    """The sequencer notes a hold again each time its p re-crosses the threshold; the recording
    keeps one note per hold (per variable and held target) until the variable switches."""
    path = tmp_path / "h.rrd"
    seq = SimpleNamespace(events=[], notes=[], last_tick=None, start_decision=None)
    hold = "b runs b_go, never seen at a: a_go -> a_wait (held, p=0.70)"
    with EpisodeRecorder(path, feature_names=FEATURES, mp_names=MP_NAMES) as recorder:
        logger = EpisodeLogger(recorder, seq)
        for tick in range(8):
            t = tick * DT
            a = "a_go" if tick < 6 else "a_wait"
            held = {"a": "a_wait"} if tick in (1, 2, 4) else {}
            if tick in (1, 4):  # noted at 0.1 s and, after a dip, again at 0.4 s
                seq.notes.append(SequencerNote(t, "hold", "a", hold))
            if tick == 6:
                seq.events.append(TransitionEvent(t, "a", "a_go", "a_wait", 0.8))
            seq.last_tick = TickInfo(t, active={"a": a, "b": "b_go"}, held=held)
            logger(TickInfo(t, active={"a": a, "b": "b_go"}, features=np.zeros(4)))
        t = 8 * DT  # a new hold after the switch: noted
        seq.notes.append(SequencerNote(t, "hold", "a", hold.replace("a_go", "a_wait")))
        seq.last_tick = TickInfo(t, active={"a": "a_wait", "b": "b_go"}, held={"a": "a_back"})
        logger(TickInfo(t, active={"a": "a_wait", "b": "b_go"}, features=np.zeros(4)))
    notes = read_recording(path).notes
    assert [round(n.t, 3) for n in notes] == [0.1, 0.8]


def test_start_references_are_the_demonstrations_first_samples():
    demos = make_demonstrations(2, seed=0)
    refs = start_references(demos)
    assert [r.name for r in refs] == [d.name for d in demos]
    for ref, demo in zip(refs, demos, strict=True):
        assert ref.combination == {v: str(demo.labels[v][0]) for v in demo.variables}
        assert list(ref.values.values()) == demo.features[0].tolist()
