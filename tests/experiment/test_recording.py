"""Round trip of episode recordings: EpisodeRecorder -> .rrd -> read_recording / inspect_rrd."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

from cpmp.errors import ConfigError, CpmpError, CpmpFileError, DataError, UnknownMPError
from cpmp.experiment.recording import EpisodeRecorder, format_summary, read_recording

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
    from rerun.chunk import RrdReader

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
    assert [v[0] for v in active_text] == ["left_pos: approach", "left_pos: grasp"]


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
    assert "left_pos: approach -> grasp (p=0.71)" in text
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
    from rerun.chunk import RrdReader

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
    with pytest.raises(ConfigError, match="type must be one of"):
        EpisodeRecorder(
            tmp_path / "g.rrd",
            feature_names=FEATURES,
            mp_names=MP_NAMES,
            geoms=[{"body": "b", "type": "mesh", "size": [1]}],
        )
    with pytest.raises(ConfigError, match="needs at least 2"):
        EpisodeRecorder(
            tmp_path / "g.rrd",
            feature_names=FEATURES,
            mp_names=MP_NAMES,
            geoms=[{"body": "b", "type": "capsule", "size": [0.1]}],
        )
    assert list(tmp_path.iterdir()) == []


def _inspect_main():
    script = Path(__file__).resolve().parents[2] / "scripts" / "inspect_rrd.py"
    spec = importlib.util.spec_from_file_location("inspect_rrd", script)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.main


def test_inspect_rrd_cli(episode_file: Path, tmp_path: Path, capsys) -> None:
    main = _inspect_main()
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
