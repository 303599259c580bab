"""What a recording must show to explain the sequencer's decisions, one test per defect seen in
rerun 0.41's viewer (#22): the blueprint names the logged entities, transition lines break
where their source MP is inactive, every series of a panel has its own colour, the start
decision is recorded with its scores, a hold is noted once with its duration and count, the
events log carries its times, no event row is wider than the log shows, no legend sits on a
small plot."""

from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from rerun.chunk import RrdReader

from cpmp.errors import ConfigError, UnknownMPError
from cpmp.experiment.reproduction import EpisodeLogger, start_references
from cpmp.recordings import (
    EVENT_WIDTH,
    EpisodeRecorder,
    StartReference,
    event_lines,
    format_summary,
    read_recording,
    read_views,
)
from cpmp.recordings.layout import (
    EVENT_INDENT,
    WARN_COLOR,
    blueprint_paths,
    series_label,
    start_map,
)
from cpmp.records import SequencerNote, StartDecision, StartOption, TickInfo, TransitionEvent
from cpmp.worlds.two_point import make_demonstrations

MP_NAMES = {"a": ["a_go", "a_wait", "a_back"], "b": ["b_go", "b_back"]}
FEATURES = ["box_width", "box_depth", "left_x", "left_y"]
DT = 0.1


def _column(path: Path, entity: str, column: str) -> list:
    """Values of one component column of one entity, in the viewer's order: by time, then as
    logged (row id)."""
    rows = []
    for chunk in RrdReader(path).stream():
        if chunk.entity_path != f"/{entity}":
            continue
        batch = chunk.to_record_batch()
        if column in batch.schema.names:
            times = batch.column("time").to_pylist() if "time" in batch.schema.names else None
            row_ids = batch.column("rerun.controls.RowId").to_pylist()
            values = batch.column(column).to_pylist()
            rows += zip(times or [0] * len(values), row_ids, values, strict=True)
    return [value for *_, value in sorted(rows, key=lambda row: row[:2])]


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
    # one column per start, best first: the rows stay short in a narrow panel
    assert "| start | 1 | 2 |" in text and "| score | -0.20 | -1.50 |" in text
    assert "| chosen | **chosen** |  |" in text and "| a | a_go | a_wait |" in text
    assert "| correct |" not in text and "Wrong start" not in text  # not known here
    assert "The same in every start: b=b_go." in text
    # the episode's box against the training boxes, nearest first, by start number
    assert text.index("| demo_0 | 0.200 | 0.200 | 0.35 | 1 |") < text.index("| demo_1 |")
    assert "start (joint rule, 2 demonstrated starts): a=a_go" in format_line(path)
    assert {"start/boxes/training", "start/boxes/episode"} <= set(summary.entity_paths)
    views = {v.name: v for v in read_views(path)}
    assert views["start"].kind == "TextDocument" and views["start map"].kind == "2D"


def format_line(path: Path) -> str:
    """The start's event text, its rows joined (a long event continues on indented rows)."""
    rows = _column(path, "events/start", "TextLog:text")
    return " ".join(row[0].strip() for row in rows)


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
    assert [n.text for n in notes] == [hold, hold.replace("a_go", "a_wait")]  # the first note
    rows = _column(path, "events/notes", "TextLog:text")
    assert _events(rows) == [
        f"0.10 s hold: {hold}; held 0.50 s, until a switched to a_wait at 0.60 s (noted 2 times)",
        f"0.80 s hold: {notes[1].text}; held 0.00 s, until the episode ended at 0.80 s",
    ]
    assert _column(path, "events/notes", "cpmp.Note:count") == [[2], [1]]
    assert _column(path, "events/notes", "cpmp.Note:held") == [["a_wait"], ["a_back"]]
    until = _column(path, "events/notes", "cpmp.Note:until")
    assert [round(u[0], 3) for u in until] == [0.6, 0.8]


def _events(rows: list) -> list[str]:
    """The events of a text log's rows: a row that starts with its time begins one, an
    indented row continues it (whitespace collapsed)."""
    events: list[str] = []
    for (row,) in rows:
        if row.startswith(" " * EVENT_INDENT):
            events[-1] += " " + row.strip()
        else:
            events.append(" ".join(row.split()))
    return events


def test_a_hold_ends_with_a_switch_to_another_mp_with_another_hold_or_the_outcome(tmp_path):
    """What ended a hold is said: a switch of its variable (to any MP: noted on the tick of a
    switch elsewhere it lasted 0 s), the coupling holding it to another MP, the outcome."""
    path = tmp_path / "h.rrd"
    with EpisodeRecorder(path, feature_names=FEATURES, mp_names=MP_NAMES) as recorder:
        for tick in range(10):
            recorder.log_tick(tick * DT, [0.0] * 4, {}, {"a": "a_go", "b": "b_go"})
        recorder.log_note(0.1, "hold", "a", "why a", held="a_wait")
        recorder.log_note(0.3, "hold", "a", "why a again", held="a_wait")
        recorder.log_note(0.4, "hold", "a", "why a_back", held="a_back")  # another MP held
        recorder.log_note(0.5, "hold", "b", "why b", held="b_back")
        recorder.log_transition(0.5, "b", "b_go", "b_back", 0.9)  # on the same tick
        recorder.log_note(0.6, "hold", "b", "no target given")  # logged as it comes
        recorder.log_note(0.7, "hold", "b", "no target given")
        with pytest.raises(UnknownMPError, match="a_nowhere"):
            recorder.log_note(0.7, "hold", "a", "x", held="a_nowhere")
        recorder.log_outcome(0.9, "incomplete", "deadlock", success=False)
    assert _events(_column(path, "events/notes", "TextLog:text")) == [
        "0.10 s hold: why a; held 0.30 s, until 0.40 s, then held to a_back (noted 2 times)",
        "0.40 s hold: why a_back; held 0.50 s, until the episode ended at 0.90 s",
        "0.50 s hold: why b; held 0.00 s, until b switched to b_back at 0.50 s",
        "0.60 s hold: no target given",
        "0.70 s hold: no target given",
    ]
    assert [n.text for n in read_recording(path).notes][:2] == ["why a", "why a_back"]


def test_no_event_row_is_wider_than_the_log_shows(tmp_path):
    """rerun 0.41 shows a text log entry's first line only and cuts it at the panel's edge: a
    long event is logged as rows of at most EVENT_WIDTH characters (what the events log shows
    in the default layout at 1920 px), its continuation rows indented below its text, the
    whole text kept; the record is in its first row, warnings are coloured (and the colour of
    one row does not carry over to the next)."""
    long_reason = "; ".join(
        f"b runs b_go at progress 0.{i}1 (demonstrated >= 0.9)" for i in range(6)
    )
    names = {"arm": ["reach_" + "x" * 90, "lift"], "b": ["b_go", "b_back"]}
    path = tmp_path / "long.rrd"
    decision = StartDecision(0.0, "joint", [StartOption({"arm": "lift", "b": "b_go"}, -0.5)], {})
    with EpisodeRecorder(path, feature_names=FEATURES, mp_names=names) as recorder:
        recorder.log_tick(0.0, [0.0] * 4, {}, {"arm": names["arm"][0], "b": "b_go"})
        recorder.log_start(decision)
        recorder.log_note(0.0, "hold", "arm", long_reason, held="lift")
        recorder.log_transition(1.0, "arm", names["arm"][0], "lift", 0.8, kind="recovery")
        recorder.log_note(1.0, "recovery", "arm", long_reason)
        recorder.log_transition(1.5, "b", "b_go", "b_back", 0.9)
        recorder.log_outcome(2.0, "incomplete", long_reason, success=False)
    entities = ["events/start", "events/transitions", "events/notes", "events/outcome"]
    entities += ["events/transitions/arm", "active/arm"]
    for name in entities:
        rows = [row[0] for row in _column(path, name, "TextLog:text")]
        assert rows and max(len(row) for row in rows) <= EVENT_WIDTH, name
        assert all(row[EVENT_INDENT - 1] == " " for row in rows)  # the text column
        assert rows[0].lstrip()[0].isdigit()  # the first row starts with the time
    notes = _events(_column(path, "events/notes", "TextLog:text"))
    assert notes[0].startswith(f"0.00 s hold: {long_reason}; held 1.00 s, until arm switched")
    assert notes[1] == f"1.00 s recovery: {long_reason}"
    (arm,) = _events(_column(path, "active/arm", "TextLog:text"))
    # a word longer than a row is broken across rows, none of it lost
    assert arm.replace(" ", "") == f"0.00sarm:{names['arm'][0]}"
    summary = read_recording(path)
    assert summary.reason == long_reason and [n.text for n in summary.notes] == [long_reason] * 2
    assert [e.kind for e in summary.transitions] == ["recovery", "switch"]
    # warnings (the recovery, the failed outcome) coloured, the switch after them not
    colours = {
        row[0]: colour
        for row, colour in zip(
            _column(path, "events/transitions", "TextLog:text"),
            _column(path, "events/transitions", "TextLog:color"),
            strict=True,
        )
    }
    warn = (WARN_COLOR[0] << 24) | (WARN_COLOR[1] << 16) | (WARN_COLOR[2] << 8) | 255
    assert [c for text, c in colours.items() if "[recovery]" in text] == [[warn]]
    assert [c for text, c in colours.items() if "[switch]" in text] == [[]]


def test_event_lines_wrap_at_the_width_and_keep_every_word():
    text = "left_fingers: preshape -> grasp " * 6
    rows = event_lines(3.25, text, width=40)
    assert rows[0].startswith("  3.25 s  left_fingers:")
    assert all(len(row) <= 40 for row in rows) and len(rows) > 3
    assert all(row.startswith(" " * EVENT_INDENT) and row[EVENT_INDENT] != " " for row in rows[1:])
    assert " ".join(row.strip() for row in rows).split()[2:] == text.split()
    assert event_lines(1234.5, "x") == ["1234.50 s  x"]
    assert event_lines(0.0, "") == ["  0.00 s"]
    with pytest.raises(ConfigError, match="width"):
        event_lines(0.0, "x", width=12)


def _blueprint_tree(path: Path) -> tuple[dict[str, dict], dict[str, tuple[int, list[str], str]]]:
    """The stored blueprint: view id -> {name, legend_visible, monospace, columns}, and
    container id -> (kind: 1 tabs, 2 horizontal, 3 vertical, 4 grid; children's ids; name)."""
    reader = RrdReader(path)
    views: dict[str, dict] = {}
    containers: dict[str, tuple[int, list[str], str]] = {}
    for chunk in reader.stream(store=reader.blueprints()[0]):
        batch = chunk.to_record_batch()
        cells = {
            n: batch.column(n)[batch.num_rows - 1].as_py()
            for n in batch.schema.names
            if ":" in n  # components (the time columns are timestamps)
        }
        parts = chunk.entity_path.strip("/").split("/")
        key = "/".join(parts[:2])
        if "ContainerBlueprint:container_kind" in cells:
            kind = cells["ContainerBlueprint:container_kind"][0]
            children = [c.strip("/") for c in cells["ContainerBlueprint:contents"]]
            name = (cells.get("ContainerBlueprint:display_name") or [""])[0]
            containers[key] = (kind, children, name)
        view = views.setdefault(key, {}) if parts[0] == "view" else {}
        if "ViewBlueprint:display_name" in cells:
            view["name"] = cells["ViewBlueprint:display_name"][0]
        if "PlotLegend:corner" in cells:
            visible = cells.get("PlotLegend:visible")
            view["legend_visible"] = True if visible is None else visible[0]
        if "TextLogFormat:monospace_body" in cells:
            view["monospace"] = cells["TextLogFormat:monospace_body"][0]
        if "TextLogColumns:text_log_columns" in cells:
            view["columns"] = cells["TextLogColumns:text_log_columns"]
    return views, containers


def test_no_legend_covers_a_small_plot(tmp_path):
    """The feature panels are tabs, each plot the column's width (six small plots side by side
    had legends over a third of their curves), each with its legend; a variable's tab shows one
    legend, φ's (entry and the transitions draw each MP in its colour)."""
    views, containers = _blueprint_tree(_episode(tmp_path / "e.rrd"))
    parent = {child: key for key, (_, children, _) in containers.items() for child in children}
    feature_views = [k for k, v in views.items() if v.get("name") in ("box", "left")]
    assert len(feature_views) == 2
    for key in feature_views:
        kind, siblings, _ = containers[parent[key]]
        assert kind == 1 and set(feature_views) <= set(siblings)  # tabs: one plot at a time
        assert views[key]["legend_visible"] is True
    tabs = {name: children for _, children, name in containers.values() if name in ("a", "b")}
    assert set(tabs) == {"a", "b"}
    for children in tabs.values():
        shown = {views[c]["name"]: views[c]["legend_visible"] for c in children}
        assert shown == {"φ (exit)": True, "entry 1 − φ": False, "p(switch to)": False}
    events = next(v for v in views.values() if v.get("name") == "events")
    assert events["monospace"] is True  # EVENT_WIDTH characters take a known width
    assert {"kind": 2, "visible": False} in events["columns"]  # 2 = level: the text gets it


def test_start_references_are_the_demonstrations_first_samples():
    demos = make_demonstrations(2, seed=0)
    refs = start_references(demos)
    assert [r.name for r in refs] == [d.name for d in demos]
    for ref, demo in zip(refs, demos, strict=True):
        assert ref.combination == {v: str(demo.labels[v][0]) for v in demo.variables}
        assert list(ref.values.values()) == demo.features[0].tolist()


def test_start_references_carry_the_box_size_in_metres():
    """A demonstration whose metadata has its box adds the axes the start map is drawn in."""
    demos = make_demonstrations(2, seed=0)
    demos[0].metadata = {**(demos[0].metadata or {}), "box_width": 0.21, "box_depth": 0.13}
    refs = start_references(demos)
    assert (refs[0].values["box_width_m"], refs[0].values["box_depth_m"]) == (0.21, 0.13)
    assert "box_width_m" not in refs[1].values


def _wrong_start(path: Path) -> Path:
    """A one-tick episode: start 1 chosen, the demonstrator's start 2, boxes in metres."""
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
        StartReference("demo_0", {"a": "a_go", "b": "b_go"}, {"w_m": 0.20, "d_m": 0.12}),
        StartReference("demo_1", {"a": "a_wait", "b": "b_go"}, {"w_m": 0.26, "d_m": 0.20}),
    ]
    with EpisodeRecorder(path, feature_names=FEATURES, mp_names=MP_NAMES) as recorder:
        recorder.log_tick(0.0, [0.5, 0.2, 0, 0], {}, {"a": "a_go", "b": "b_go"})
        recorder.log_start(
            decision,
            references,
            ["w_m", "d_m"],
            correct={"a": "a_wait"},
            values={"w_m": 0.23, "d_m": 0.13},
        )
        recorder.log_outcome(0.0, "wrong_start", "a differs", success=False)
    return path


def test_a_wrong_start_marks_the_demonstrators_start(tmp_path):
    """The outcome names some variables, the starts all: the document matches them for the
    reader, in the starts' columns and in a sentence."""
    (document,) = _column(_wrong_start(tmp_path / "w.rrd"), "start", "TextDocument:text")
    text = document[0]
    assert "| chosen | **chosen** |  |" in text and "| correct |  | **correct** |" in text
    assert "**Wrong start**: the demonstrator starts this box with a=a_wait (start 2)" in text
    assert "| map colour | blue | orange |" in text
    # the box in metres, as given (not the features): w_m 0.23 against 0.20 and 0.26
    assert "| **episode** | 0.230 | 0.130 | 0 | 1 |" in text
    assert "| demo_0 | 0.200 | 0.120 |" in text


def test_the_start_map_has_a_frame_a_key_and_names_off_the_dots(tmp_path):
    path = _wrong_start(tmp_path / "w.rrd")
    dots = np.array(_column(path, "start/boxes/training", "Points2D:positions")[0])
    radius = _column(path, "start/boxes/training", "Points2D:radii")[0][0]
    names = np.array(_column(path, "start/boxes/training_names", "Points2D:positions")[0])
    assert _column(path, "start/boxes/training_names", "Points2D:labels")[0] == [
        "demo_0",
        "demo_1",
    ]
    assert dots[:, 0] == pytest.approx([0.20, 0.26])
    assert dots[:, 1] == pytest.approx([-0.12, -0.20])  # depth upwards: the view's y runs down
    # each name is anchored below its dot, clear of it (a label hangs below its anchor)
    assert names[:, 0] == pytest.approx(dots[:, 0])
    assert np.all(names[:, 1] - dots[:, 1] > radius)
    episode = np.array(_column(path, "start/boxes/episode", "Points2D:positions")[0])
    episode_radius = _column(path, "start/boxes/episode", "Points2D:radii")[0][0]
    episode_name = np.array(_column(path, "start/boxes/episode_name", "Points2D:positions")[0])
    assert episode[0] == pytest.approx([0.23, -0.13])
    assert episode_name[0, 1] - episode[0, 1] > episode_radius
    ticks = _column(path, "start/boxes/tick_values", "Points2D:labels")[0]
    assert "0.2" in ticks and len(ticks) >= 4
    titles = _column(path, "start/boxes/axis_titles", "Points2D:labels")[0]
    assert titles == ["w_m →", "↑ d_m"]
    assert _column(path, "start/boxes/key_names", "Points2D:labels")[0] == ["start 1", "start 2"]
    key = _column(path, "start/boxes/key", "Points2D:colors")[0]
    assert key[:2] == [
        _column(path, "start/boxes/training", "Points2D:colors")[0][i] for i in (0, 1)
    ]


def test_a_start_axis_must_be_a_feature_or_a_given_value(tmp_path):
    decision = StartDecision(0.0, "joint", [StartOption({"a": "a_go"}, -0.1)], {"a": "a_go"})
    ref = StartReference("demo_0", {"a": "a_go"}, {"w_m": 0.2})
    with EpisodeRecorder(tmp_path / "x.rrd", feature_names=FEATURES, mp_names=MP_NAMES) as rec:
        with pytest.raises(ConfigError, match=r"unknown \['w_m'\]"):
            rec.log_start(decision, [ref], ["w_m"])
        with pytest.raises(UnknownMPError):
            rec.log_start(decision, [ref], ["w_m"], correct={"a": "a_fly"}, values={"w_m": 0.1})
        rec.log_start(decision, [ref], ["w_m"], values={"w_m": 0.1})


def test_the_start_map_bounds_hold_everything_it_draws():
    """The view is zoomed to the map (the viewer's default left most of the view empty): every
    dot, anchor and line end lies inside the bounds."""
    references = [
        StartReference("d0", {"a": "a_go"}, {"w": 0.20, "d": 0.12}),
        StartReference("d1", {"a": "a_wait"}, {"w": 0.26, "d": 0.20}),
    ]
    drawn = start_map(references, ["w", "d"], [0.23, 0.13], [{"a": "a_go"}, {"a": "a_wait"}])
    corners = []
    for _, archetype in drawn.entities:
        for batch in archetype.as_component_batches():
            name = str(batch.component_descriptor())
            if "positions" in name or "strips" in name:
                values = batch.as_arrow_array().to_pylist()
                corners += [p for v in values for p in (v if isinstance(v[0], list) else [v])]
    xy = np.array(corners)
    (x0, x1), (y0, y1) = drawn.x_range, drawn.y_range
    assert len(xy) > 10
    assert np.all((xy[:, 0] > x0) & (xy[:, 0] < x1) & (xy[:, 1] > y0) & (xy[:, 1] < y1))
    # and they are not much larger than the drawing: under twice its extent
    assert (x1 - x0) < 2 * np.ptp(xy[:, 0]) and (y1 - y0) < 2 * np.ptp(xy[:, 1])


def test_inspect_tells_the_start_as_the_viewer_does(tmp_path):
    """The recording keeps the training starts with their distances (nearest first) and the
    demonstrator's start for this episode; ``read_recording`` returns them and
    ``format_summary`` (``cpmp-inspect-rrd``) prints them, as the start panel shows them."""
    decision = StartDecision(
        0.0,
        "joint",
        [StartOption({"a": "a_go", "b": "b_go"}, -0.2), StartOption({"a": "a_wait"}, -1.5)],
        {"a": "a_go", "b": "b_go"},
    )
    references = [
        StartReference("far", {"a": "a_wait", "b": "b_go"}, {"w_m": 0.6, "d_m": 0.5}),
        StartReference("near", {"a": "a_go", "b": "b_go"}, {"w_m": 0.25, "d_m": 0.1}),
    ]
    here = {"w_m": 0.3, "d_m": 0.2}
    path = tmp_path / "s.rrd"
    with EpisodeRecorder(path, feature_names=FEATURES, mp_names=MP_NAMES) as recorder:
        recorder.log_tick(0.0, [0.3, 0.3, 0, 0], {"a": {"a_go": 0.1}}, {"a": "a_go", "b": "b_go"})
        recorder.log_start(
            decision, references, ["w_m", "d_m"], correct={"a": "a_wait"}, values=here
        )
        recorder.log_outcome(0.0, "wrong_start", "a differs", success=False)
    summary = read_recording(path)
    # each axis in units of its range over the training starts (0.35 and 0.4)
    span = np.array([0.35, 0.4])
    expected = {
        ref.name: float(
            np.linalg.norm(
                (np.array([ref.values["w_m"], ref.values["d_m"]]) - np.array([0.3, 0.2])) / span
            )
        )
        for ref in references
    }
    assert [r["name"] for r in summary.start_references] == ["near", "far"]
    for ref in summary.start_references:
        assert ref["distance"] == pytest.approx(expected[ref["name"]])
    assert summary.start_references[0]["combination"] == {"a": "a_go", "b": "b_go"}
    assert summary.start_references[1]["values"] == {"w_m": 0.6, "d_m": 0.5}
    assert summary.start_correct == {"a": "a_wait"}
    text = format_summary(summary)
    assert "the demonstrator starts this episode with a=a_wait" in text
    near = text.index(f"{expected['near']:6.2f}  near: w_m 0.250, d_m 0.100; a=a_go, b=b_go")
    assert near < text.index(f"{expected['far']:6.2f}  far: w_m 0.600")
    assert summary.to_dict()["start_references"] == summary.start_references
