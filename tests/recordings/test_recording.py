"""Round trip of episode recordings: EpisodeRecorder -> .rrd -> read_recording / inspect_rrd."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from rerun.chunk import RrdReader

import cpmp.recordings as recording
from cpmp.cli.main import inspect_rrd_main as main
from cpmp.errors import ConfigError, CpmpError, CpmpFileError, DataError, UnknownMPError
from cpmp.recordings import (
    MAX_SERIES_PER_PANEL,
    EpisodeRecorder,
    format_summary,
    group_features,
    read_recording,
    read_views,
)
from cpmp.recordings import layout as recording_layout
from cpmp.recordings import reader as recording_reader
from cpmp.recordings import writer as recording_writer
from cpmp.records import PendingSwitch, SequencerNote, TransitionEvent

MP_NAMES = {"left_pos": ["approach", "grasp", "lift"], "right_fingers": ["open", "close"]}
FEATURES = ["box_x", "box_z"]
GEOMS = [
    {"body": "box", "type": "box", "size": [0.1, 0.2, 0.05], "rgba": [1, 0, 0, 1]},
    {"body": "arm", "type": "capsule", "size": [0.04, 0.15, 0.0], "pos": [0, 0, 0.1]},
    {"body": "arm", "type": "sphere", "size": [0.05]},
    {"body": "arm", "type": "cylinder", "size": [0.03, 0.1], "quat": [0.7071, 0.7071, 0, 0]},
]
DT = 0.1
N_TICKS = 7
# Times are stored as integer nanoseconds: 1e-9 s is the round-trip resolution.
TIME_TOL = 1e-9


def _write_episode(path: Path) -> Path:
    """A 7-tick episode, flushed in several column batches (flush_every=3), two transitions."""
    with EpisodeRecorder(
        path,
        feature_names=FEATURES,
        mp_names=MP_NAMES,
        episode="demo_07",
        geoms=GEOMS,
        metadata={"seed": 7, "box": [0.3, 0.2]},
        flush_every=3,
    ) as recorder:
        for tick in range(N_TICKS):
            t = tick * DT
            phi = tick / (N_TICKS - 1)
            left = "approach" if tick < 4 else "grasp"
            fingers = "open" if tick < 2 else "close"
            recorder.log_tick(
                t,
                [tick, -2.0 * tick],
                progress={"left_pos": {"approach": phi, "grasp": 0.5 * phi}},
                active={"left_pos": left, "right_fingers": fingers},
                transition_probs={"left_pos": {"grasp": phi}},
                body_poses={"box": ([0.0, 0.0, 0.01 * tick], [0.0, 1.0, 0.0, 0.0])},
            )
            if tick == 2:
                recorder.log_transition(t, "right_fingers", "open", "close", 0.55)
            if tick == 4:
                recorder.log_transition(t, "left_pos", "approach", "grasp", 0.71)
        recorder.log_outcome(0.75, "success", "box in container")
    return path


@pytest.fixture
def episode_file(tmp_path: Path) -> Path:
    return _write_episode(tmp_path / "episode.rrd")


def _column(path: Path, entity: str, column: str) -> tuple[list[float], list]:
    """(times [s], values) of one component column of one entity, sorted by time (static: 0)."""

    rows = []
    for chunk in RrdReader(path).stream():
        if chunk.entity_path != f"/{entity}":
            continue
        batch = chunk.to_record_batch()
        if column not in batch.schema.names:
            continue
        if "time" in batch.schema.names:
            times = batch.column("time").cast("int64").to_pylist()
        else:  # static data: no timeline
            times = [0] * batch.num_rows
        rows += zip((t * 1e-9 for t in times), batch.column(column).to_pylist(), strict=True)
    rows.sort(key=lambda row: row[0])
    return [t for t, _ in rows], [value for _, value in rows]


def test_round_trip_transitions_and_outcome(episode_file: Path) -> None:
    summary = read_recording(episode_file)
    assert summary.episodes == ["demo_07"]
    assert [(e.variable, e.source, e.target) for e in summary.transitions] == [
        ("right_fingers", "open", "close"),
        ("left_pos", "approach", "grasp"),
    ]
    assert [e.t for e in summary.transitions] == pytest.approx([0.2, 0.4], abs=TIME_TOL)
    # probability is stored as float64: exact up to float formatting.
    assert [e.probability for e in summary.transitions] == pytest.approx([0.55, 0.71], abs=1e-12)
    assert summary.outcome == "success"
    assert summary.reason == "box in container"
    assert summary.n_ticks == N_TICKS
    assert summary.duration == pytest.approx(0.75, abs=TIME_TOL)
    assert summary.metadata == {"seed": 7, "box": [0.3, 0.2]}


def test_entity_paths(episode_file: Path) -> None:
    paths = set(read_recording(episode_file).entity_paths)
    expected = {
        "features/box_x",
        "features/box_z",
        "progress/left_pos/approach/phi",
        "progress/left_pos/approach/entry",
        "progress/left_pos/approach/exit",
        "progress/left_pos/grasp/phi",
        "transition/left_pos/grasp",
        "active/left_pos",
        "active/right_fingers/index",
        "events/transitions",
        "events/outcome",
        "world/box",
        "world/box/geom_0",
        "world/arm/geom_3",
    }
    assert expected <= paths, expected - paths
    assert not any(path.startswith("__properties") for path in paths)


def test_scalar_values_round_trip(episode_file: Path) -> None:
    times, box_z = _column(episode_file, "features/box_z", "Scalars:scalars")
    assert times == pytest.approx([i * DT for i in range(N_TICKS)], abs=TIME_TOL)
    assert [v[0] for v in box_z] == pytest.approx([-2.0 * i for i in range(N_TICKS)])
    _, phi = _column(episode_file, "progress/left_pos/approach/phi", "Scalars:scalars")
    _, entry = _column(episode_file, "progress/left_pos/approach/entry", "Scalars:scalars")
    _, exit_ = _column(episode_file, "progress/left_pos/approach/exit", "Scalars:scalars")
    phi_values = np.array([v[0] for v in phi])
    assert phi_values == pytest.approx(np.linspace(0, 1, N_TICKS))
    assert [v[0] for v in entry] == pytest.approx(1.0 - phi_values)
    assert [v[0] for v in exit_] == pytest.approx(phi_values)
    _, index = _column(episode_file, "active/left_pos/index", "Scalars:scalars")
    assert [v[0] for v in index] == [0, 0, 0, 0, 1, 1, 1]
    _, active_text = _column(episode_file, "active/left_pos", "TextLog:text")
    assert [v[0] for v in active_text] == [
        "  0.00 s  left_pos: approach",
        "  0.40 s  left_pos: grasp",
    ]


def test_a_recording_with_geoms_opens_on_its_scene(episode_file: Path) -> None:
    assert [v.kind for v in read_views(episode_file) if v.name == "scene"] == ["3D"]


def test_poses_and_geoms(episode_file: Path) -> None:
    _, quaternions = _column(episode_file, "world/box", "Transform3D:quaternion")
    # wxyz (0, 1, 0, 0) is stored in rerun's xyzw order.
    assert quaternions[0][0] == pytest.approx([1.0, 0.0, 0.0, 0.0])
    _, translations = _column(episode_file, "world/box", "Transform3D:translation")
    assert translations[-1][0] == pytest.approx([0.0, 0.0, 0.06], abs=1e-7)  # float32
    _, lengths = _column(episode_file, "world/arm/geom_1", "Capsules3D:lengths")
    assert lengths[0] == pytest.approx([0.3], abs=1e-7)  # twice the MuJoCo half-length
    _, offsets = _column(episode_file, "world/arm/geom_1", "Capsules3D:translations")
    assert offsets[0][0] == pytest.approx([0.0, 0.0, -0.15], abs=1e-7)  # centred like MuJoCo
    _, half_sizes = _column(episode_file, "world/box/geom_0", "Boxes3D:half_sizes")
    assert half_sizes[0][0] == pytest.approx([0.1, 0.2, 0.05], abs=1e-7)


def test_format_summary_lists_transitions(episode_file: Path) -> None:
    text = format_summary(read_recording(episode_file))
    assert "demo_07" in text
    assert "ticks: 7" in text
    assert "left_pos: approach -> grasp (p=0.71) [switch]" in text
    assert "outcome: success (box in container)" in text


def test_missing_and_garbage_files(tmp_path: Path) -> None:
    with pytest.raises(CpmpFileError, match="does not exist"):
        read_recording(tmp_path / "missing.rrd")
    garbage = tmp_path / "garbage.rrd"
    garbage.write_bytes(b"this is not a rerun file at all, just some bytes" * 10)
    with pytest.raises(CpmpFileError, match="rerun recording"):
        read_recording(garbage)
    with pytest.raises(CpmpFileError):
        read_recording(tmp_path)


def test_truncated_file_raises(episode_file: Path, tmp_path: Path) -> None:
    truncated = tmp_path / "truncated.rrd"
    data = episode_file.read_bytes()
    truncated.write_bytes(data[: len(data) // 2])
    with pytest.raises(CpmpFileError, match=r"truncated\.rrd"):
        read_recording(truncated)


def test_episodes_get_distinct_recording_ids(tmp_path: Path) -> None:

    first = _write_episode(tmp_path / "first.rrd")
    second = _write_episode(tmp_path / "second.rrd")
    ids = [RrdReader(p).recordings()[0].recording_id for p in (first, second)]
    assert ids[0] != ids[1]


def test_failed_episode_leaves_no_file(tmp_path: Path) -> None:
    target = tmp_path / "failed.rrd"
    with pytest.raises(RuntimeError, match="simulated crash"):
        with EpisodeRecorder(target, feature_names=FEATURES, mp_names=MP_NAMES) as recorder:
            recorder.log_tick(0.0, [1.0, 2.0], {}, {"left_pos": "approach"})
            raise RuntimeError("simulated crash")
    assert list(tmp_path.iterdir()) == []


def test_failed_episode_keeps_previous_file(tmp_path: Path) -> None:
    target = tmp_path / "episode.rrd"
    target.write_bytes(b"previous")
    recorder = EpisodeRecorder(target, feature_names=FEATURES, mp_names=MP_NAMES)
    with pytest.raises(DataError, match=r"shape \(2,\)"):
        recorder.log_tick(0.0, [1.0, 2.0, 3.0], {}, {})
    recorder.abort()
    assert target.read_bytes() == b"previous"
    assert [p.name for p in tmp_path.iterdir()] == ["episode.rrd"]


def test_close_is_idempotent_and_final(tmp_path: Path) -> None:
    recorder = EpisodeRecorder(tmp_path / "e.rrd", feature_names=[], mp_names=MP_NAMES)
    recorder.log_tick(0.0, [], {}, {"left_pos": "lift"})
    assert recorder.close() == tmp_path / "e.rrd"
    assert recorder.close() == tmp_path / "e.rrd"
    with pytest.raises(CpmpError, match="closed"):
        recorder.log_outcome(1.0, "failure")
    assert read_recording(tmp_path / "e.rrd").n_ticks == 1


def test_invalid_arguments(tmp_path: Path) -> None:
    recorder = EpisodeRecorder(tmp_path / "e.rrd", feature_names=FEATURES, mp_names=MP_NAMES)
    with pytest.raises(UnknownMPError, match="unknown MP 'jump'"):
        recorder.log_tick(0.0, [0, 0], {"left_pos": {"jump": 0.5}}, {})
    with pytest.raises(UnknownMPError, match="unknown control variable"):
        recorder.log_transition(0.0, "head", "a", "b", 0.5)
    with pytest.raises(DataError, match="quaternion"):
        recorder.log_tick(0.0, [0, 0], {}, {}, body_poses={"box": ([0, 0, 0], [1, 0, 0])})
    recorder.log_tick(1.0, [0, 0], {}, {})
    with pytest.raises(DataError, match="non-decreasing"):
        recorder.log_tick(0.5, [0, 0], {}, {})
    recorder.abort()
    for geom, message in (
        ({"body": "b", "type": "mesh", "size": [1]}, "type must be one of"),
        ({"body": "b", "type": "capsule", "size": [0.1]}, "needs at least 2"),
    ):
        with pytest.raises(ConfigError, match=message):
            EpisodeRecorder(
                tmp_path / "g.rrd", feature_names=FEATURES, mp_names=MP_NAMES, geoms=[geom]
            )
    assert list(tmp_path.iterdir()) == []


def test_inspect_rrd_cli(episode_file: Path, tmp_path: Path, capsys) -> None:

    assert main([str(episode_file)]) == 0
    out = capsys.readouterr().out
    assert "right_fingers: open -> close (p=0.55)" in out
    assert "left_pos: approach -> grasp (p=0.71)" in out
    assert "outcome: success" in out

    assert main([str(episode_file), "--json"]) == 0
    record = json.loads(capsys.readouterr().out)
    assert record["n_ticks"] == N_TICKS
    assert record["transitions"][1]["target"] == "grasp"

    bad = tmp_path / "bad.rrd"
    bad.write_text("not an rrd")
    assert main([str(episode_file), str(bad)]) == 2
    captured = capsys.readouterr()
    assert "left_pos: approach -> grasp" in captured.out
    assert captured.err.count("\n") == 1
    assert "error" in captured.err and "bad.rrd" in captured.err


def test_recovery_transitions_and_notes_round_trip(tmp_path: Path) -> None:
    """What the sequencer decided and why: a held transition and a stall recovery are in the
    recording and in its summary."""
    path = tmp_path / "notes.rrd"
    with EpisodeRecorder(path, feature_names=FEATURES, mp_names=MP_NAMES) as recorder:
        for tick in range(3):
            recorder.log_tick(
                tick * DT,
                [tick, 0.0],
                progress={"left_pos": {"approach": 0.5}},
                active={"left_pos": "approach", "right_fingers": "open"},
            )
        recorder.log_note(0.1, "hold", "left_pos", "approach -> grasp held: right_fingers=open")
        recorder.log_transition(0.2, "left_pos", "approach", "grasp", 0.4, kind="recovery")
        recorder.log_note(0.2, "recovery", "left_pos", "stalled 1.0 s")
    summary = read_recording(path)
    assert [(e.target, e.kind) for e in summary.transitions] == [("grasp", "recovery")]
    assert [(n.kind, n.variable) for n in summary.notes] == [
        ("hold", "left_pos"),
        ("recovery", "left_pos"),
    ]
    assert summary.notes[0].text == "approach -> grasp held: right_fingers=open"
    assert summary.notes[1].t == pytest.approx(0.2, abs=TIME_TOL)
    assert "hold" in format_summary(summary) and "[recovery]" in format_summary(summary)


def test_events_of_one_time_keep_their_rows_together(tmp_path: Path) -> None:
    """Two events at one time, each of several rows: the second's rows follow the first's, one
    ROW_STEP apart (rerun 0.41 sorts rows of one time stamp either way: it showed a note's
    second row below the first row of a transition at its time), and each reads back at its
    own time, which its record holds."""
    path = tmp_path / "same.rrd"
    with EpisodeRecorder(path, feature_names=FEATURES, mp_names=MP_NAMES) as recorder:
        for tick in range(3):
            recorder.log_tick(tick * DT, [tick, 0.0], {}, {"left_pos": "approach"})
        recorder.log_note(0.2, "recovery", "left_pos", "a stall of 1 s resolved: " * 3)
        recorder.log_transition(0.2, "left_pos", "approach", "grasp", 0.4, kind="recovery")
        recorder.log_outcome(0.2, "incomplete", "deadlock; " * 8, success=False)
    step = recording_writer.ROW_STEP
    note_times, notes = _column(path, "events/notes", "TextLog:text")
    move_times, moves = _column(path, "events/transitions", "TextLog:text")
    end_times, ends = _column(path, "events/outcome", "TextLog:text")
    assert len(notes) > 1 and len(moves) == 1 and len(ends) > 1
    rows = len(notes) + len(moves) + len(ends)
    assert note_times + move_times + end_times == pytest.approx(
        [0.2 + k * step for k in range(rows)], abs=step / 10
    )
    assert notes[0][0].startswith("  0.20 s  recovery: a stall")
    assert moves[0][0].startswith("  0.20 s  left_pos: approach -> grasp")
    assert ends[0][0].startswith("  0.20 s  outcome: incomplete")
    # a variable's own copy of the transition sits where the events log's does
    own_times, own = _column(path, "events/transitions/left_pos", "TextLog:text")
    assert own == moves and own_times == pytest.approx(move_times, abs=step / 10)
    _, record_times = _column(path, "events/transitions", "cpmp.Transition:t")
    assert record_times == [[pytest.approx(0.2, abs=TIME_TOL)]]
    summary = read_recording(path)
    assert summary.notes[0].t == pytest.approx(0.2, abs=TIME_TOL)
    assert summary.transitions[0].t == pytest.approx(0.2, abs=TIME_TOL)
    assert summary.duration == pytest.approx(0.2, abs=TIME_TOL)


# Feature names shaped like the simulator's (box, each hand, touch flags, goal distances), made
# up here: the grouping rule must find the panels from the names alone.
ROBOT_FEATURES = [
    *(f"box_{a}" for a in ("width", "depth", "x", "z")),
    *(f"{side}_ee_{a}" for side in ("left", "right") for a in ("x", "y", "z")),
    "left_palm_contact",
    "right_palm_contact",
    "box_supported",
    *(f"dist.{side}_{mp}" for side in ("left", "right") for mp in ("rot.home", "fingers.grasp")),
    *(f"dist.{side}_fingers.{mp}" for side in ("left", "right") for mp in ("relax", "release")),
    *(f"dist.{side}_fingers.preshape" for side in ("left", "right")),
    *(f"dist.{side}_rot.down" for side in ("left", "right")),
]
ROBOT_MPS = {
    "left_pos": ["home", "reach", "lift"],
    "right_fingers": ["relax", "grasp", "release"],
}


def _write_robot_episode(path: Path) -> Path:
    """6 ticks; right_fingers grasps at tick 2 and releases at tick 4 (p = 0.68), then a
    deadlock ends the episode."""
    with EpisodeRecorder(
        path, feature_names=ROBOT_FEATURES, mp_names=ROBOT_MPS, episode="D3_episode_004"
    ) as recorder:
        for tick in range(6):
            fingers = ["relax", "relax", "grasp", "grasp", "release", "release"][tick]
            recorder.log_tick(
                tick * DT,
                np.full(len(ROBOT_FEATURES), float(tick)),
                progress={"right_fingers": {fingers: 0.2 * tick}},
                active={"left_pos": "reach" if tick else "home", "right_fingers": fingers},
                transition_probs={"right_fingers": {"release": 0.1 * tick}},
            )
            if tick == 2:
                recorder.log_transition(tick * DT, "right_fingers", "relax", "grasp", 0.9)
            if tick == 4:
                recorder.log_transition(tick * DT, "right_fingers", "grasp", "release", 0.68)
                recorder.log_note(tick * DT, "hold", "left_pos", "reach -> lift held")
        recorder.log_outcome(0.6, "incomplete", "deadlock", success=False)
    return path


@pytest.fixture
def robot_file(tmp_path: Path) -> Path:
    return _write_robot_episode(tmp_path / "robot.rrd")


def test_group_features_panels_from_names() -> None:
    groups = group_features(ROBOT_FEATURES)
    assert list(groups) == ["box", "left", "right", "touch", "dist.left", "dist.right"]
    assert groups["touch"] == ["left_palm_contact", "right_palm_contact", "box_supported"]
    assert groups["left"] == ["left_ee_x", "left_ee_y", "left_ee_z"]
    assert all(name.startswith("dist.left_") for name in groups["dist.left"])
    # A partition of the names, in their order, at most MAX_SERIES_PER_PANEL per panel.
    flat = [name for members in groups.values() for name in members]
    assert sorted(flat) == sorted(ROBOT_FEATURES)
    assert all(len(members) <= MAX_SERIES_PER_PANEL for members in groups.values())
    for members in groups.values():
        assert members == sorted(members, key=ROBOT_FEATURES.index)


def test_group_features_splits_and_merges() -> None:
    joints = [f"arm_q_{i}" for i in range(11)]
    groups = group_features(joints, max_series=4)
    assert list(groups) == ["arm_q 1", "arm_q 2", "arm_q 3"]
    assert [len(m) for m in groups.values()] == [4, 4, 3]
    assert group_features(["x", "y", "hand_a", "hand_b"]) == {
        "other": ["x", "y"],
        "hand": ["hand_a", "hand_b"],
    }
    assert group_features(["grip_force", "pos"]) == {"touch": ["grip_force"], "pos": ["pos"]}
    with pytest.raises(ConfigError, match="max_series"):
        group_features(["a"], max_series=0)


def test_explicit_feature_groups(tmp_path: Path) -> None:
    path = tmp_path / "g.rrd"
    with EpisodeRecorder(
        path, feature_names=["a", "b", "c"], mp_names=MP_NAMES, feature_groups={"ab": ["a", "b"]}
    ) as recorder:
        recorder.log_tick(0.0, [1.0, 2.0, 3.0], {}, {})
    assert read_recording(path).feature_groups == {"ab": ["a", "b"], "other": ["c"]}
    for groups, message in (
        ({"ab": ["a", "z"]}, "unknown features"),
        ({"x": ["a"], "y": ["a"]}, "several groups"),
        ({"x": []}, "needs a name"),
    ):
        with pytest.raises(ConfigError, match=message):
            EpisodeRecorder(
                tmp_path / "bad.rrd",
                feature_names=["a", "b", "c"],
                mp_names=MP_NAMES,
                feature_groups=groups,
            )
    assert not (tmp_path / "bad.rrd").exists()


def test_feature_panels_in_blueprint(robot_file: Path) -> None:
    """Every feature group is a time-series panel named after it, showing its features only."""
    groups = group_features(ROBOT_FEATURES)
    assert read_recording(robot_file).feature_groups == groups
    panels = {v.name: v for v in read_views(robot_file) if v.origin == "features"}
    assert set(panels) == set(groups)
    for group, members in groups.items():
        assert panels[group].kind == "TimeSeries"
        assert panels[group].contents == [f"+ features/{name}" for name in members]
    # nothing 3D logged here (no geoms, no body poses): no empty scene view
    assert "scene" not in [v.name for v in read_views(robot_file)]
    # Each feature's series is named by the feature less its panel's name (a narrow legend),
    # not by its entity path; a name without the panel's prefix stays whole.
    _, names = _column(robot_file, "features/dist.left_fingers.grasp", "SeriesLines:names")
    assert names == [["fingers.grasp"]]
    _, names = _column(robot_file, "features/box_supported", "SeriesLines:names")
    assert names == [["box_supported"]]


def test_transition_text_active_mps_and_outcome_readable(robot_file: Path) -> None:
    """What the viewer shows without scrolling: the transition sentence as the events log's
    first column, the active MPs (status document, state lanes) and the outcome at the end."""
    times, texts = _column(robot_file, "events/transitions", "TextLog:text")
    # one event per transition, wrapped into rows of EVENT_WIDTH at most, in order, each row
    # ROW_STEP after the one above it
    expected = {
        0.2: recording_layout.event_lines(0.2, "right_fingers: relax -> grasp (p=0.90) [switch]"),
        0.4: recording_layout.event_lines(0.4, "right_fingers: grasp -> release (p=0.68) [switch]"),
    }
    assert expected[0.2] == ["  0.20 s  right_fingers: relax -> grasp (p=0.90) [switch]"]
    assert expected[0.4][0] == "  0.40 s  right_fingers: grasp -> release (p=0.68)"
    assert [x[0] for x in texts] == expected[0.2] + expected[0.4]
    step = recording_writer.ROW_STEP
    assert times == pytest.approx([0.2, 0.4, 0.4 + step], abs=step / 10)
    outcome_times, outcome = _column(robot_file, "events/outcome", "TextLog:text")
    assert outcome == [["  0.60 s  outcome: incomplete (deadlock)"]]
    assert outcome_times == pytest.approx([0.6], abs=TIME_TOL)
    _, level = _column(robot_file, "events/outcome", "TextLog:level")
    assert level == [["WARN"]]

    _, states = _column(robot_file, "active/right_fingers", "StateChange:state")
    assert [s[0] for s in states] == ["relax", "grasp", "release"]

    times, status = _column(robot_file, "status", "TextDocument:text")
    documents = [d[0] for d in status]
    # The latest document at t = 0.3 s (what the viewer shows there): grasp active, and the
    # transition that made it so.
    at_03 = [d for t, d in zip(times, documents, strict=True) if t <= 0.3 + TIME_TOL][-1]
    assert "| right_fingers | grasp |" in at_03 and "| left_pos | reach |" in at_03
    assert "right_fingers: relax -> grasp (p=0.90) [switch]" in at_03
    final = documents[-1]
    assert "| right_fingers | release |" in final
    assert "right_fingers: grasp -> release (p=0.68) [switch]" in final
    assert "last note: hold at 0.40 s: reach -> lift held" in final
    assert "outcome: incomplete (deadlock)" in final

    views = {v.name: v for v in read_views(robot_file)}
    assert views["status"].kind == "TextDocument" and views["status"].origin == "status"
    assert views["active MPs"].kind == "StateTimeline" and views["active MPs"].origin == "active"
    assert "+ events/outcome" in views["events"].contents
    assert "+ events/notes" in views["events"].contents
    # The time panel is one row (2 = collapsed): the views get the height, the events log
    # lists every event with its time.
    assert _blueprint_column(robot_file, "TimePanelBlueprint:state") == [[2]]


def _blueprint_column(path: Path, column: str) -> list:

    reader = RrdReader(path)
    values = []
    for chunk in reader.stream(store=reader.blueprints()[0]):
        batch = chunk.to_record_batch()
        if column in batch.schema.names:
            values += batch.column(column).to_pylist()
    return values


def test_text_logs_show_the_text_first(robot_file: Path) -> None:
    """The events and active-MP logs show the message body (which starts with its time) as
    their first column and hide the entity path and the time column (which the viewer cuts to
    ``+3…``)."""
    columns = _blueprint_column(robot_file, "TextLogColumns:text_log_columns")
    assert len(columns) == 2  # events and the active-MP log
    for cells in columns:
        assert cells[0] == {"kind": 3, "visible": True}  # 3 = Body
        assert {"kind": 1, "visible": False} in cells  # 1 = EntityPath
    timelines = _blueprint_column(robot_file, "TextLogColumns:timeline_columns")
    assert timelines == [[{"timeline": "time", "visible": False}]] * 2


def test_public_names_importable_from_recording() -> None:

    assert recording.EpisodeRecorder is recording_writer.EpisodeRecorder
    assert recording.read_recording is recording_reader.read_recording
    assert recording.group_features is recording_layout.group_features
    modules = (recording_layout, recording_reader, recording_writer)
    assert set(recording.__all__) == set().union(*(m.__all__ for m in modules))


def test_read_views_of_bad_files(tmp_path: Path) -> None:
    with pytest.raises(CpmpFileError, match=r"^recording .*missing\.rrd does not exist$"):
        read_views(tmp_path / "missing.rrd")
    garbage = tmp_path / "garbage.rrd"
    garbage.write_bytes(b"not a rerun file" * 20)
    with pytest.raises(CpmpFileError, match="rerun recording"):
        read_views(garbage)


def test_summary_holds_the_sequencers_own_records(tmp_path: Path) -> None:
    """A transition and a note the sequencer made read back as the same core records (equal but
    for the time's nanosecond resolution; a recording keeps no feature vector, so ``state`` is
    None and ``to_dict`` leaves it out)."""

    event = TransitionEvent(0.2, "left_pos", "approach", "grasp", 0.4, np.ones(2), "recovery")
    note = SequencerNote(0.1, "hold", "left_pos", "approach -> grasp held")
    path = tmp_path / "records.rrd"
    with EpisodeRecorder(path, feature_names=FEATURES, mp_names=MP_NAMES) as recorder:
        recorder.log_tick(0.0, [0.0, 0.0], {}, {"left_pos": "approach", "right_fingers": "open"})
        recorder.log_note(note.t, note.kind, note.variable, note.text)
        e = event
        recorder.log_transition(e.t, e.variable, e.source, e.target, e.probability, e.kind)
    summary = read_recording(path)
    (got,) = summary.transitions
    assert type(got) is TransitionEvent and got.state is None
    assert got.t == pytest.approx(event.t, abs=TIME_TOL)
    assert replace(got, t=event.t) == event
    (got_note,) = summary.notes
    assert type(got_note) is SequencerNote
    assert replace(got_note, t=note.t) == note
    data = json.loads(json.dumps(summary.to_dict()))
    fields = ["t", "variable", "source", "target", "probability", "kind"]
    assert list(data["transitions"][0]) == fields
    assert data["notes"][0]["text"] == note.text


def test_an_incomplete_episodes_cause_is_in_the_recording_and_its_summary(
    tmp_path: Path, capsys
) -> None:
    """The outcome names the switch that never came; an event marks when its p was best."""
    path = tmp_path / "cause.rrd"
    cause = PendingSwitch("left_pos", "approach", "grasp", "still_improving", 0.91, 0.1, 0.9, 0.65)
    with EpisodeRecorder(path, feature_names=FEATURES, mp_names=MP_NAMES) as recorder:
        for tick in range(4):
            recorder.log_tick(
                tick * DT,
                [tick, 0.0],
                progress={},
                active={"left_pos": "approach", "right_fingers": "open"},
            )
        recorder.log_outcome(3 * DT, "incomplete", "deadlock", success=False, cause=cause)
    summary = read_recording(path)
    assert summary.cause == cause
    assert summary.reason == f"deadlock; {cause.describe()}"
    assert summary.to_dict()["cause"]["best_p"] == 0.91
    text = format_summary(summary)
    assert f"cause: {cause.describe()}" in text
    assert "variable=left_pos" in text and "expected=grasp" in text and "best_p=0.910" in text
    assert main([str(path)]) == 0
    assert "left_pos approach -> grasp never fired: p reached 0.910" in capsys.readouterr().out
    assert "events/outcome" in summary.entity_paths
    assert summary.duration == pytest.approx(3 * DT)
