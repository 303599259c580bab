"""What a recording shows of a failure without a click (#36): the switching threshold and the
switch / hold / recovery marks on every p(switch) plot, every variable's p(switch) at once
above the tabs, legends above the curves, and ``cpmp-inspect-rrd`` printing the hold notes and
the start's score table in full."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from rerun.chunk import RrdReader

from cpmp.cli.main import inspect_rrd_main
from cpmp.errors import ConfigError
from cpmp.recordings import EpisodeRecorder, format_summary, read_recording, read_views
from cpmp.recordings.layout import (
    LEGEND_SPACE_NARROW,
    LEGEND_SPACE_WIDE,
    MARK_STYLES,
    OVERVIEW_NAME,
)
from cpmp.recordings.reader import _note_text
from cpmp.records import PendingSwitch, SequencerNote, StartDecision, StartOption

MP_NAMES = {
    "a": ["a_go", "a_wait", "a_back"],
    "b": ["b_go", "b_back"],
    "c": ["c_idle", "c_push"],
}
FEATURES = ["box_width", "box_depth"]
DT = 0.1
N_TICKS = 8
# Times are stored as integer nanoseconds.
TIME_TOL = 1e-9
DECISION = StartDecision(
    0.0,
    "joint",
    [
        StartOption({"a": "a_wait", "b": "b_go", "c": "c_idle"}, -1.5),
        StartOption({"a": "a_go", "b": "b_go", "c": "c_idle"}, -0.2),
        StartOption({"a": "a_back", "b": "b_back", "c": "c_idle"}, -4.25),
    ],
    {"a": "a_go", "b": "b_go", "c": "c_idle"},
)


def _episode(path: Path, threshold: float | None = 0.7, cause: PendingSwitch | None = None) -> Path:
    """``a`` is held from a_wait at 0.2 s (p 0.75) and switches at 0.4 s (p 0.8); ``b``
    recovers to b_back at 0.5 s (p 0.3); ``c`` never gets a successor p (no plot)."""
    with EpisodeRecorder(
        path, feature_names=FEATURES, mp_names=MP_NAMES, threshold=threshold
    ) as recorder:
        for tick in range(N_TICKS):
            t = tick * DT
            a = "a_go" if tick < 4 else "a_wait"
            b = "b_go" if tick < 5 else "b_back"
            target = {"a_go": "a_wait", "a_wait": "a_back"}[a]
            recorder.log_tick(
                t,
                [0.3, 0.2],
                {"a": {a: 0.1 * tick}},
                {"a": a, "b": b, "c": "c_idle"},
                {"a": {target: 0.25 * tick if tick < 4 else 0.1}, "b": {"b_back": 0.05 * tick}},
            )
            if tick == 0:
                recorder.log_start(DECISION)
            if tick == 2:
                recorder.log_note(t, "hold", "a", "b runs b_go: a_go -> a_wait held", held="a_wait")
            if tick == 3:
                recorder.log_note(t, "hold", "a", "b runs b_go: a_go -> a_wait held", held="a_wait")
            if tick == 4:
                recorder.log_transition(t, "a", "a_go", "a_wait", 0.8)
            if tick == 5:
                recorder.log_transition(t, "b", "b_go", "b_back", 0.3, "recovery")
        recorder.log_outcome(N_TICKS * DT, "incomplete", "deadlock", success=False, cause=cause)
    return path


def _series(path: Path, entity: str, column: str = "Scalars:scalars") -> list[tuple[float, list]]:
    """(time [s], value) rows of one component column of one entity (static: time 0)."""
    rows = []
    for chunk in RrdReader(path).stream():
        if chunk.entity_path != f"/{entity}":
            continue
        batch = chunk.to_record_batch()
        if column in batch.schema.names:
            times = (
                [t * 1e-9 for t in batch.column("time").cast("int64").to_pylist()]
                if "time" in batch.schema.names
                else [0.0] * batch.num_rows
            )
            rows += zip(times, batch.column(column).to_pylist(), strict=True)
    return sorted(rows, key=lambda row: row[0])


def _blueprint(path: Path) -> tuple[dict[str, dict], dict[str, tuple[int, list[str], str]]]:
    """view id -> {name, origin, contents, legend_visible, y_range, x_range: (start, end) [s]
    of its time axis}; container id -> (kind: 1 tabs,
    2 horizontal, 3 vertical, 4 grid; children's ids; name)."""
    reader = RrdReader(path)
    views: dict[str, dict] = {}
    containers: dict[str, tuple[int, list[str], str]] = {}
    for chunk in reader.stream(store=reader.blueprints()[0]):
        batch = chunk.to_record_batch()
        cells = {
            n: batch.column(n)[batch.num_rows - 1].as_py() for n in batch.schema.names if ":" in n
        }
        parts = chunk.entity_path.strip("/").split("/")
        key = "/".join(parts[:2])
        if "ContainerBlueprint:container_kind" in cells:
            children = [c.strip("/") for c in cells["ContainerBlueprint:contents"]]
            name = (cells.get("ContainerBlueprint:display_name") or [""])[0]
            containers[key] = (cells["ContainerBlueprint:container_kind"][0], children, name)
        if parts[0] != "view":
            continue
        view = views.setdefault(key, {})
        if "ViewBlueprint:display_name" in cells:
            view["name"] = cells["ViewBlueprint:display_name"][0]
        if "ViewBlueprint:space_origin" in cells:
            view["origin"] = cells["ViewBlueprint:space_origin"][0]
        if "ViewContents:query" in cells:
            view["contents"] = cells["ViewContents:query"]
        if "PlotLegend:corner" in cells:
            visible = cells.get("PlotLegend:visible")
            view["legend_visible"] = True if visible is None else visible[0]
        if "ScalarAxis:range" in cells:
            view["y_range"] = cells["ScalarAxis:range"][0]
        if "TimeAxis:view_range" in cells:
            bounds = cells["TimeAxis:view_range"][0]
            view["x_range"] = [bounds[end] * 1e-9 for end in ("start", "end")]  # ns
    return views, containers


@pytest.fixture
def episode_file(tmp_path: Path) -> Path:
    return _episode(tmp_path / "e.rrd")


def test_the_threshold_is_a_line_from_the_first_tick_to_the_last(episode_file):
    rows = _series(episode_file, "threshold")
    assert [t for t, _ in rows] == pytest.approx([0.0, (N_TICKS - 1) * DT], abs=TIME_TOL)
    assert [v for _, v in rows] == [[0.7], [0.7]]
    ((_, names),) = _series(episode_file, "threshold", "SeriesLines:names")
    assert names == ["threshold 0.7"]


def test_every_p_plot_draws_the_threshold_and_its_variables_event_marks(episode_file):
    views = [v for v in read_views(episode_file) if v.origin.startswith("transition/")]
    # a and b each: the overview's small plot and the tab's p(switch to); c has no p logged
    assert sorted(v.origin for v in views) == ["transition/a"] * 2 + ["transition/b"] * 2
    marks = {"a": ["hold", "switch"], "b": ["recovery"]}
    for view in views:
        variable = view.origin.split("/")[1]
        assert "+ threshold" in view.contents
        for kind in MARK_STYLES:
            line = f"+ marks/{variable}/{kind}"
            assert (line in view.contents) == (kind in marks[variable]), (view, kind)
    logged = set(read_recording(episode_file).entity_paths)
    assert {"marks/a/hold", "marks/a/switch", "marks/b/recovery"} <= logged


def test_the_marks_sit_at_the_events_time_and_p(episode_file):
    # the hold at its first note (0.2 s), at the held target's p of that tick; noted again at
    # 0.3 s: one hold, one mark
    def points(entity: str) -> list[tuple[float, float]]:
        return [(t, value) for t, (value,) in _series(episode_file, entity)]

    assert points("marks/a/hold") == [pytest.approx((0.2, 0.5))]
    assert points("marks/a/switch") == [pytest.approx((0.4, 0.8))]
    assert points("marks/b/recovery") == [pytest.approx((0.5, 0.3))]
    ((_, markers),) = _series(episode_file, "marks/b/recovery", "SeriesPoints:markers")
    ((_, names),) = _series(episode_file, "marks/b/recovery", "SeriesPoints:names")
    assert names == ["recovery"] and len(markers) == 1


def test_without_a_threshold_no_line_is_drawn(tmp_path):
    path = _episode(tmp_path / "n.rrd", threshold=None)
    assert "threshold" not in read_recording(path).entity_paths
    assert not [v for v in read_views(path) if "+ threshold" in v.contents]
    with pytest.raises(ConfigError, match="threshold"):
        EpisodeRecorder(
            tmp_path / "bad.rrd", feature_names=FEATURES, mp_names=MP_NAMES, threshold=float("nan")
        )


def test_an_overview_shows_every_variables_p_without_a_click(episode_file):
    """A grid of one small p(switch) plot per variable with a successor p, outside any tabs
    (what a tab hides needs a click), titled by the variable, without a legend."""
    views, containers = _blueprint(episode_file)
    parent = {child: key for key, (_, children, _) in containers.items() for child in children}
    (grid,) = [key for key, (_, _, name) in containers.items() if name == OVERVIEW_NAME]
    kind, children, _ = containers[grid]
    assert kind == 4  # grid
    assert [views[c]["name"] for c in children] == ["a", "b"]
    for child in children:
        assert views[child]["legend_visible"] is False
        assert views[child]["y_range"] == [0.0, 1.0]
    key = grid
    while key in parent:  # no tabs above it: shown as the recording opens
        key = parent[key]
        assert containers[key][0] != 1


def _room(duration: float, space: float) -> list[float]:
    """The time axis of a plot whose first ``space`` of its width holds its legend."""
    return [-duration * space / (1 - space), duration]


def test_legends_sit_left_of_the_curves(episode_file):
    """rerun puts a legend in a plot's corner only: a plot with a legend starts its time axis
    before t = 0, so the legend (top left) sits where no curve is; the plots without one keep
    the viewer's axis. Probabilities keep [0, 1]."""
    views, _ = _blueprint(episode_file)
    end = (N_TICKS - 1) * DT
    (phi,) = [v for v in views.values() if v.get("name") == "φ (exit)"]
    assert phi["legend_visible"] is True and phi["y_range"] == [0.0, 1.0]
    assert phi["x_range"] == pytest.approx(_room(end, LEGEND_SPACE_NARROW))
    assert _room(end, LEGEND_SPACE_NARROW)[0] < 0  # the legend's room is before the data
    features = [v for v in views.values() if v.get("origin") == "features"]
    assert features and all(v["legend_visible"] is True for v in features)
    for view in features:
        assert view["x_range"] == pytest.approx(_room(end, LEGEND_SPACE_WIDE))
    tab = {
        (v["name"], v["origin"]): v
        for v in views.values()
        if v.get("name") in ("p(switch to)", "entry 1 − φ")
    }
    for key in (("p(switch to)", "transition/a"), ("entry 1 − φ", "progress/a")):
        assert tab[key]["legend_visible"] is False and "x_range" not in tab[key]
        assert tab[key]["y_range"] == [0.0, 1.0]
    # b logged no φ: its p plot names its series (b_back, the threshold, the recovery mark)
    b = tab["p(switch to)", "transition/b"]
    assert b["legend_visible"] is True
    assert b["x_range"] == pytest.approx(_room(end, LEGEND_SPACE_NARROW))


def test_a_p_plot_with_its_own_legend_gets_room_for_it(tmp_path):
    """Without φ logged, the tab's p plot shows the legend: its targets, the threshold and the
    marks; a recording of one tick (no time to speak of) keeps the viewer's time axis."""
    path = tmp_path / "p.rrd"
    with EpisodeRecorder(path, feature_names=FEATURES, mp_names=MP_NAMES) as recorder:
        for tick in range(3):
            recorder.log_tick(tick * DT, [0.0, 0.0], {}, {"a": "a_go"}, {"a": {"a_wait": 0.9}})
        recorder.log_transition(0.2, "a", "a_go", "a_wait", 0.9)
    views, _ = _blueprint(path)
    (plot,) = [v for v in views.values() if v.get("name") == "p(switch to)"]
    assert plot["contents"] == ["+ transition/a/a_wait", "+ threshold", "+ marks/a/switch"]
    assert plot["legend_visible"] is True
    assert plot["x_range"] == pytest.approx(_room(2 * DT, LEGEND_SPACE_NARROW))
    one = tmp_path / "one.rrd"
    with EpisodeRecorder(one, feature_names=FEATURES, mp_names=MP_NAMES) as recorder:
        recorder.log_tick(0.0, [0.0, 0.0], {}, {"a": "a_go"}, {"a": {"a_wait": 0.9}})
    views, _ = _blueprint(one)
    assert not [v for v in views.values() if "x_range" in v]


def test_inspect_rrd_prints_hold_notes_and_the_start_table_in_full(episode_file, capsys):
    assert inspect_rrd_main([str(episode_file)]) == 0
    out = capsys.readouterr().out
    assert (
        "hold: b runs b_go: a_go -> a_wait held; held 0.20 s, until a switched to a_wait at "
        "0.40 s (noted 2 times)"
    ) in out
    table = [line.strip() for line in out.splitlines() if line.strip().startswith("-")]
    assert table == [
        "-0.20  a=a_go, b=b_go, c=c_idle  (chosen)",
        "-1.50  a=a_wait, b=b_go, c=c_idle",
        "-4.25  a=a_back, b=b_back, c=c_idle",
    ]
    assert inspect_rrd_main([str(episode_file), "--json"]) == 0
    record = json.loads(capsys.readouterr().out)
    assert record["notes"][0]["text"] == "b runs b_go: a_go -> a_wait held"  # the first note
    assert record["note_texts"][0].endswith("until a switched to a_wait at 0.40 s (noted 2 times)")
    assert len(record["start"]["options"]) == 3


def test_a_hold_that_lasted_to_the_end_reads_so(tmp_path):
    path = tmp_path / "h.rrd"
    with EpisodeRecorder(path, feature_names=FEATURES, mp_names=MP_NAMES) as recorder:
        for tick in range(5):
            recorder.log_tick(tick * DT, [0.0, 0.0], {}, {"a": "a_go"}, {"a": {"a_wait": 0.8}})
        recorder.log_note(0.1, "hold", "a", "why", held="a_wait")
        recorder.log_note(0.2, "recovery", "b", "b stalled")
        recorder.log_outcome(0.5, "incomplete", "deadlock", success=False)
    summary = read_recording(path)
    assert summary.note_texts == [
        "why; held 0.40 s, until the episode ended at 0.50 s",
        "b stalled",
    ]
    assert "hold: why; held 0.40 s, until the episode ended at 0.50 s" in format_summary(summary)


def test_a_hold_of_an_older_file_still_says_how_long_it_was_held():
    """Files written before ``ended_by`` was recorded: the duration and the end time."""
    note = SequencerNote(1.0, "hold", "a", "why")
    cells = {"until": 1.5, "count": 3, "ended_by": None, "then": None}
    assert _note_text(note, cells) == "why; held 0.50 s, until 1.50 s (noted 3 times)"
    assert _note_text(SequencerNote(1.0, "recovery", "a", "x"), {"until": None}) == "x"


def _tabs_and_time(path: Path) -> tuple[dict[str, str], dict[str, str], dict | None]:
    """The blueprint's tabs containers (name -> the id of their active tab), every container's
    name by id, and the time panel's selection (``{"min", "max"}`` in ns, or ``None``)."""
    reader = RrdReader(path)
    active: dict[str, str] = {}
    names: dict[str, str] = {}
    selection = None
    for chunk in reader.stream(store=reader.blueprints()[0]):
        batch = chunk.to_record_batch()
        cells = {
            n: batch.column(n)[batch.num_rows - 1].as_py() for n in batch.schema.names if ":" in n
        }
        key = "/".join(chunk.entity_path.strip("/").split("/")[:2])
        name = (cells.get("ContainerBlueprint:display_name") or [""])[0]
        if "ContainerBlueprint:container_kind" in cells:
            names[key] = name
        if cells.get("ContainerBlueprint:active_tab"):
            active[name] = cells["ContainerBlueprint:active_tab"][0]
        if chunk.entity_path == "/time_panel":
            selection = (cells.get("TimePanelBlueprint:time_selection") or [None])[0]
    return active, names, selection


def test_a_failure_opens_on_the_variable_that_failed(tmp_path):
    """The probability tabs open on the cause's variable (here the second tab, ``b``), and the
    time panel selects its pending switch: from its best p to the last tick."""
    cause = PendingSwitch(
        "b", "b_back", "b_go", "below_threshold", best_p=0.35, best_t=0.6, threshold=0.7
    )
    active, names, selection = _tabs_and_time(_episode(tmp_path / "f.rrd", cause=cause))
    assert names[active["probabilities"]] == "b"
    assert selection == {"min": round(0.6e9), "max": round((N_TICKS - 1) * DT * 1e9)}
    # without a cause: the first variable's tab, nothing selected
    active, names, selection = _tabs_and_time(_episode(tmp_path / "ok.rrd"))
    assert names[active["probabilities"]] == "a"
    assert selection is None
