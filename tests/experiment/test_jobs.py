"""End to end: the main job on ``experiment=tiny`` (in-process and as a script, run side by side
and compared), replaying a demonstration into an ``.rrd``, and training/evaluating from your
own HDF5 file (no simulator)."""

from __future__ import annotations

import json
import logging
import os
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch
from hydra import compose, initialize_config_dir

from cpmp.cli.main import check_command, inspect_rrd_main
from cpmp.data.datafile import load_demonstrations
from cpmp.errors import ConfigError, DataError
from cpmp.evaluation.offline import activation_progress, progress_errors
from cpmp.experiment.checkpoint_jobs import evaluate_checkpoint, train_from_file
from cpmp.experiment.executors import default_workers
from cpmp.experiment.jobs import run_experiment
from cpmp.experiment.settings import ExperimentSettings
from cpmp.experiment.strategies import strategy_map, strategy_signatures
from cpmp.recordings import read_recording, read_views
from cpmp.recordings.demos import label_switches, record_demo_rrd
from cpmp.recordings.layout import blueprint_paths
from cpmp.records import CAUSE_REASONS, PendingSwitch
from cpmp.sequencer.sequencer import ConcurrentSequencer
from cpmp.sim import Box, Simulation, TaskConfig
from cpmp.worlds.two_point import make_demonstrations

# One thread: a second busy process on a 2-core machine slows torch's default two threads
# down many times over; the script below runs with one thread too (cli.run_job).
torch.set_num_threads(1)

ROOT = Path(__file__).resolve().parents[2]
CONF = ROOT / "conf"
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def compose_cfg(config_name: str, overrides: list[str]) -> Any:
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        return compose(config_name, overrides=overrides)


def without_timings(obj: Any) -> Any:
    """``obj`` without wall-clock fields (``seconds``) and paths (``files``, ``rrd``)."""
    if isinstance(obj, dict):
        return {
            k: without_timings(v) for k, v in obj.items() if k not in ("seconds", "files", "rrd")
        }
    if isinstance(obj, list):
        return [without_timings(v) for v in obj]
    return obj


# ------------------------------------------------------------------- experiment=tiny, twice
TINY = ["experiment=tiny", "task.compile_kinematics=false"]
"""``experiment=tiny`` as the tests below run it. The arm Jacobian is not compiled: compiling
costs every process seconds of CPU (``cpmp.sim.kinematics.COMPILE_SECONDS``: 20 s, 4 s from
torch's cache), more than the eager call loses over the few thousand ticks of a tiny run; no
assertion here depends on it (tests/sim/test_kinematics.py checks the compiled Jacobian against
the eager one; tests/test_packaging.py runs ``experiment=tiny`` as it ships)."""


@pytest.fixture(scope="module")
def tiny(tmp_path_factory, script_in_background):
    """Run ``experiment=tiny`` in-process and, at the same time, as ``scripts/experiment.py``
    in a subprocess (two cores, ~20 s for both), both with the eager arm Jacobian
    (:data:`TINY`). Yields the two run dirs and the script's stdout."""
    base = tmp_path_factory.mktemp("tiny")
    direct, script = base / "direct", base / "script"
    direct.mkdir()
    argv = [*TINY, "experiment.record=failures", f"hydra.run.dir={script}"]
    with script_in_background(base, "experiment.py", *argv, timeout=300) as run:
        cfg = compose_cfg("experiment", TINY)
        report_path = run_experiment(cfg, direct)
    return {
        "cfg": cfg,
        "direct": direct,
        "script": script,
        "report_path": report_path,
        "stdout": run.stdout.read_text(),
    }


@pytest.mark.slow
def test_report_fields(tiny):
    assert tiny["report_path"] == tiny["direct"] / "report.json"
    report = json.loads(tiny["report_path"].read_text())
    exp = report["experiment"]
    assert exp["name"] == "tiny"
    assert report["predictor"]["kind"] == "klr"
    assert report["progress"]["train_size"] == 3
    rep = report["reproduction"]["3"]
    assert rep["paper"] == {"W": 3, "I": 4, "C": 13, "distance_mean": 0.13, "distance_std": 0.08}
    assert report["seconds"] > 0


@pytest.mark.slow
def test_report_counts_and_distances_are_those_of_the_episodes(tiny):
    """One seed: Table I's counts are the outcomes in ``episodes.json`` (std 0), the distance
    the mean over the complete episodes' switch distances."""
    report = json.loads(tiny["report_path"].read_text())
    rep = report["reproduction"]["3"]
    episodes = json.loads((tiny["direct"] / "episodes.json").read_text())
    outcomes = [e["outcome"] for e in episodes]
    counts = {
        "W": outcomes.count("wrong_start"),
        "C": outcomes.count("complete"),
        "I": len(outcomes) - outcomes.count("wrong_start") - outcomes.count("complete"),
    }
    assert rep["per_seed"] == {key: [count] for key, count in counts.items()}
    assert {key: rep[key] for key in counts} == counts
    assert [rep[f"{key}_std"] for key in counts] == [0.0, 0.0, 0.0]
    distances = [x for e in episodes if e["outcome"] == "complete" for x in e["distances"]]
    if distances:
        # the report pools per-seed means and stds: equal up to float rounding
        assert rep["distance_mean"] == pytest.approx(np.mean(distances), rel=1e-12)
        assert rep["distance_std"] == pytest.approx(np.std(distances), rel=1e-9, abs=1e-12)
    else:
        assert rep["distance_mean"] is None


@pytest.mark.slow
def test_report_progress_and_strategy_map_are_those_of_the_checkpoint(tiny):
    """The saved model, evaluated again on the saved test split and over the strategy grid,
    gives the report's progress errors and strategy-map accuracy."""

    report = json.loads(tiny["report_path"].read_text())
    run = tiny["direct"] / "seed_0"
    seq = ConcurrentSequencer.load(run / "model_D3.pt")
    test = load_demonstrations(run / "demos.h5", "test")
    errors = progress_errors(activation_progress(seq, test))
    for key in ("mae", "mae_first", "mae_last"):
        # the report holds the mean over seeds (here one): equal up to float rounding
        assert report["progress"][key] == pytest.approx(errors[key], rel=1e-12)
    train = load_demonstrations(run / "demos.h5", "train")
    task = TaskConfig.from_dict(tiny["cfg"].task)
    grid = report["strategy_map"]["grid"]
    again = strategy_map(seq, task, strategy_signatures(train), grid)
    assert report["strategy_map"]["accuracy"] == again.accuracy


@pytest.mark.slow
def test_report_markdown_has_papers_column(tiny):
    text = (tiny["direct"] / "report.md").read_text()
    assert "W / I / C (paper)" in text
    assert "| 3 / 4 / 13 |" in text
    assert "0.13 ± 0.08" in text


@pytest.mark.slow
def test_files_written(tiny):
    run = tiny["direct"]
    for name in ("fig6_progress.png", "fig7_strategy_map.png"):
        assert (run / name).read_bytes()[:8] == PNG_SIGNATURE
    demos_h5 = run / "seed_0" / "demos.h5"
    # tiny: 2 demos per strategy, 1 of each for training
    assert len(load_demonstrations(demos_h5, split="train")) == 3
    assert len(load_demonstrations(demos_h5, split="test")) == 3

    seq = ConcurrentSequencer.load(run / "seed_0" / "model_D3.pt")
    assert set(seq.graphs) == set(load_demonstrations(demos_h5)[0].variables)
    assert len(list((run / "seed_0" / "recordings").glob("*.rrd"))) == 2


@pytest.mark.slow
def test_recordings_agree_with_episodes_json(tiny):
    episodes = json.loads((tiny["direct"] / "episodes.json").read_text())
    assert len(episodes) == 2  # 1 seed x 1 training size x 2 boxes
    for episode in episodes:
        summary = read_recording(episode["rrd"])
        assert summary.outcome == episode["outcome"]
        assert summary.reason == episode["reason"]
        # one box, one unit: width and depth [m] in both
        meta = summary.metadata
        assert [meta["box_width_m"], meta["box_depth_m"]] == episode["box_size_m"]
        if episode["outcome"] != "wrong_start":
            assert summary.duration == pytest.approx(episode["duration"], abs=0.011)


@pytest.mark.slow
def test_every_incomplete_episode_names_its_cause(tiny):
    """Issue #36: every incomplete episode of the run carries a named cause (variable,
    expected MP, best p, reason) in ``episodes.json``, in its recording and its reason."""
    episodes = json.loads((tiny["direct"] / "episodes.json").read_text())
    for episode in episodes:
        cause = episode["cause"]
        if episode["outcome"] in ("complete", "wrong_start"):
            assert cause is None
            continue
        assert cause["reason"] in CAUSE_REASONS and cause["reason"] != "unknown"
        if cause["reason"] != "task_unfinished":
            assert cause["variable"] and cause["current"] and "best_p" in cause
        if cause["reason"] in ("below_threshold", "still_improving", "held", "given_up"):
            assert cause["expected"] and 0.0 <= cause["best_p"] <= 1.0
        described = PendingSwitch.from_dict(cause).describe()
        assert episode["reason"].endswith(described)
        if episode["rrd"]:
            assert read_recording(episode["rrd"]).cause == PendingSwitch.from_dict(cause)
    report = json.loads(tiny["report_path"].read_text())
    incomplete = [e for e in episodes if e["outcome"] in ("incomplete", "diverged")]
    assert sum(report["reproduction"]["3"]["causes"].values()) == len(incomplete)


@pytest.mark.slow
def test_inspect_rrd_prints_transitions(tiny, demo_rrd, capsys):
    episodes = json.loads((tiny["direct"] / "episodes.json").read_text())
    paths = [e["rrd"] for e in episodes] + [str(demo_rrd)]
    summaries = {path: read_recording(path) for path in paths}
    # the demo replay always switches MPs; the sequencer's episodes may not (wrong start)
    assert summaries[str(demo_rrd)].transitions
    assert inspect_rrd_main(paths) == 0
    out = capsys.readouterr().out
    blocks = out.split("== ")[1:]
    assert len(blocks) == len(paths)
    for path, block in zip(paths, blocks, strict=True):
        summary = summaries[path]
        assert block.startswith(path)
        assert f"transitions ({len(summary.transitions)}):" in block
        listed = block.split("transitions (")[1].split("notes (")[0].split("outcome:")[0]
        lines = [line for line in listed.splitlines() if " -> " in line]
        assert len(lines) == len(summary.transitions)
        if summary.notes:
            assert f"notes ({len(summary.notes)}):" in block
        for line, event in zip(lines, summary.transitions, strict=True):
            assert f"{event.variable}: {event.source} -> {event.target}" in line
        assert f"outcome: {summary.outcome}" in block


@pytest.mark.slow
def test_record_failures_keeps_the_first_episode_and_every_failure(tiny):
    """The script ran with ``experiment.record=failures``, the in-process run with ``all``."""
    every = json.loads((tiny["direct"] / "episodes.json").read_text())
    kept = json.loads((tiny["script"] / "episodes.json").read_text())
    assert all(e["rrd"] and Path(e["rrd"]).is_file() for e in every)
    for i, e in enumerate(kept):
        wanted = i == 0 or e["outcome"] != "complete"
        assert bool(e["rrd"]) == wanted
        if wanted:
            assert Path(e["rrd"]).is_file()
    names = {p.name for p in (tiny["script"] / "seed_0" / "recordings").glob("*")}
    assert names == {Path(e["rrd"]).name for e in kept if e["rrd"]}


@pytest.mark.slow
def test_script_prints_report_path_last_and_same_numbers(tiny):
    script_report = tiny["script"] / "report.json"
    assert tiny["stdout"].strip().splitlines()[-1] == str(script_report)
    direct = json.loads((tiny["direct"] / "report.json").read_text())
    again = json.loads(script_report.read_text())
    assert (again["experiment"].pop("record"), direct["experiment"].pop("record")) == (
        "failures",
        "all",
    )  # the script keeps only failures' recordings; every number is the same
    assert without_timings(again) == without_timings(direct)
    episodes = [json.loads((tiny[k] / "episodes.json").read_text()) for k in ("direct", "script")]
    assert without_timings(episodes[0]) == without_timings(episodes[1])


@pytest.fixture(scope="module")
def demo_rrd(tiny) -> Path:
    """The first collected demonstration of the tiny run, replayed into an ``.rrd``."""

    demo = load_demonstrations(tiny["direct"] / "seed_0" / "demos.h5")[0]
    meta = demo.metadata
    box = Box(meta["box_width"], meta["box_depth"], meta["box_height"])
    path = tiny["direct"] / "demo_000.rrd"
    assert record_demo_rrd(demo, box, TaskConfig.from_dict(tiny["cfg"].task), path) == path
    return path


@pytest.mark.slow
def test_demo_replayed_into_rrd(tiny, demo_rrd):

    demo = load_demonstrations(tiny["direct"] / "seed_0" / "demos.h5")[0]
    meta = demo.metadata
    path = demo_rrd
    summary = read_recording(path)
    assert summary.episodes == [demo.name]
    assert summary.outcome == "complete"
    expected = [(e.variable, e.source, e.target) for e in label_switches(demo)]
    assert expected, "a demonstration switches MPs"
    assert [(e.variable, e.source, e.target) for e in summary.transitions] == expected
    assert all(e.probability == 1.0 for e in summary.transitions)
    switch_times = [e.t for e in label_switches(demo)]
    # times are stored as integer nanoseconds
    assert [e.t for e in summary.transitions] == pytest.approx(switch_times, abs=1e-8)
    assert summary.metadata["kind"] == "demonstration"
    assert summary.metadata["strategy"] == meta["strategy"]
    assert not any(p.startswith("progress") for p in summary.entity_paths)
    assert any(p.startswith("world/") for p in summary.entity_paths)
    assert f"features/{demo.feature_names[0]}" in summary.entity_paths
    # the replay reproduces the demonstration up to its last switch (the demonstrator keeps
    # recording until it is done; the replay stops once the episode is complete)
    assert switch_times[-1] <= summary.duration <= demo.duration + 1e-9


@pytest.mark.slow
def test_demo_rrd_rejects_non_simulator_demos(tiny, tmp_path):

    synthetic = make_demonstrations(1, seed=0)[0]
    task = TaskConfig.from_dict(tiny["cfg"].task)
    with pytest.raises(DataError, match="feature names"):
        record_demo_rrd(synthetic, Box(0.2, 0.15, 0.1), task, tmp_path / "bad.rrd")
    assert list(tmp_path.iterdir()) == []


# ---------------------------------------------------------- your own demonstrations (no sim)
def train(demo_file: Path, run_dir: Path, *overrides: str) -> Path:
    run_dir.mkdir()
    cfg = compose_cfg("train", [f"data.path={demo_file}", *overrides])
    return train_from_file(cfg, run_dir)


@pytest.fixture(scope="module")
def checkpoint(demo_file, tmp_path_factory) -> Path:
    return train(demo_file, tmp_path_factory.mktemp("train") / "run")


def test_train_from_file_writes_checkpoint(checkpoint):
    assert checkpoint.name == "model.pt"
    assert checkpoint.is_file()
    summary = json.loads((checkpoint.parent / "train_summary.json").read_text())
    assert summary["split"] == "train"
    assert summary["n_demos"] == 4


def test_evaluate_checkpoint_on_test_split(checkpoint, demo_file, tmp_path):
    cfg = compose_cfg("evaluate", [f"data.path={demo_file}", f"checkpoint={checkpoint}"])
    out = evaluate_checkpoint(cfg, tmp_path)
    assert out == tmp_path / "evaluation.json"
    result = json.loads(out.read_text())
    assert result["split"] == "test"
    assert result["n_demos"] == 2
    # Synthetic attractor demos are easy: the KLR predictor's progress error is ~0.08.
    assert result["progress"]["mae"] < 0.1
    assert set(result["progress"]["per_node"]) == {
        f"{v}/{v}_{mp}" for v in ("a", "b") for mp in ("go", "wait", "back")
    }
    replay = result["replay"]
    # every variable matches in a demo counted in all_match
    assert replay["all_match"] <= min(replay["sequence_match"].values())
    assert "Progress MAE" in (tmp_path / "evaluation.md").read_text()
    assert (tmp_path / "fig6_progress.png").read_bytes()[:8] == PNG_SIGNATURE


def test_same_seed_gives_identical_predictions(checkpoint, demo_file, tmp_path):

    again = train(demo_file, tmp_path / "again")
    test = load_demonstrations(demo_file, split="test")
    first, second = (
        activation_progress(ConcurrentSequencer.load(p), test) for p in (checkpoint, again)
    )
    assert len(first) == len(second) > 0
    for a, b in zip(first, second, strict=True):
        np.testing.assert_array_equal(a.predicted, b.predicted)


# -------------------------------------------------------- experiment.workers (parallel jobs)
@pytest.mark.parametrize("bad", [0, -2, 1.5, True])
def test_bad_worker_count_is_a_config_error(bad):
    """The settings refuse what the Hydra schema would let through from Python."""

    with pytest.raises(ConfigError, match=r"experiment\.workers must be an integer >= 1"):
        ExperimentSettings.from_cfg({"workers": bad})


@pytest.mark.parametrize("bad", ["1.5", "true"])
def test_bad_worker_override_is_refused_at_composition(bad):
    """Not an integer: the schema refuses the override before any job is built."""

    with pytest.raises(ConfigError, match=r"experiment\.workers"):
        check_command("experiment", ["experiment=tiny", f"experiment.workers={bad}"])


def test_default_workers_is_cores_or_seeds():

    cores = len(os.sched_getaffinity(0))
    assert default_workers(1) == 1
    assert default_workers(cores + 3) == cores
    for name in ("quick", "full", "tiny"):
        assert compose_cfg("experiment", [f"experiment={name}"]).experiment.workers is None


@pytest.mark.slow
def test_two_workers_give_the_serial_report(tmp_path, caplog):
    """Two seeds of ``experiment=tiny`` run serially, on two worker processes and as submitit
    jobs (``cluster=local``, two at once): every number of the report and of every episode is
    the same; the workers' log lines reach this process, prefixed with their job. The Jacobian
    is eager (:data:`TINY`): each worker and each submitit job is a fresh process that would
    compile it again."""

    overrides = [*TINY, "experiment.seeds=[0,1]", "experiment.record=none"]
    runs = {}
    executors = {
        1: ["experiment.workers=1"],
        2: ["experiment.workers=2"],
        3: [
            "experiment.workers=2",
            "experiment.executor=submitit",
            f"executor.folder={tmp_path / 'submitit'}",
        ],
    }
    for run, more in executors.items():
        cfg = compose_cfg("experiment", [*overrides, *more])
        with caplog.at_level(logging.INFO, logger="cpmp"):
            runs[run] = run_experiment(cfg, tmp_path / f"run_{run}").parent
        if run == 2:
            messages = [record.getMessage() for record in caplog.records]
    reports = [json.loads((runs[w] / "report.json").read_text()) for w in runs]
    assert [r["seed"] for r in reports[1]["per_seed"]] == [0, 1]
    assert without_timings(reports[0]) == without_timings(reports[1])
    assert without_timings(reports[0]) == without_timings(reports[2])
    assert (runs[1] / "report.md").read_text() == (runs[2] / "report.md").read_text()
    assert (runs[1] / "report.md").read_text() == (runs[3] / "report.md").read_text()
    episodes = [json.loads((runs[w] / "episodes.json").read_text()) for w in runs]
    assert len(episodes[0]) == 4  # 2 seeds x 2 boxes
    assert without_timings(episodes[0]) == without_timings(episodes[1])
    assert without_timings(episodes[0]) == without_timings(episodes[2])
    timings = [json.loads((runs[w] / "timings.json").read_text()) for w in runs]
    assert [(t["executor"], t["workers"]) for t in timings] == [
        ("local", 1),
        ("local", 2),
        ("submitit", 2),
    ]
    for run in (2, 3):
        for seed in (0, 1):
            assert (runs[run] / f"seed_{seed}" / "model_D3.pt").is_file()
            assert (runs[run] / f"seed_{seed}" / "lightning" / "D3").is_dir()
    assert any(m.startswith("[seed 1 D=3] ") and "reproduce" in m for m in messages)
    assert any(m.startswith("[seed 0] ") and "collect" in m for m in messages)
    assert len(list((tmp_path / "submitit").glob("*_result.pkl"))) == 4  # 2 seeds x (1 + 1 D)


@pytest.mark.slow
def test_a_wrong_start_recording_shows_its_scene_and_its_start_decision(tiny):
    """A wrong start ends at t = 0, before any control tick: its recording still has every
    body's pose, every feature, the active MPs and the status at t = 0, and the start decision
    with every demonstrated start's score (the chosen one the best), laid out in the middle;
    every recording's views name only logged entities."""
    episodes = json.loads((tiny["direct"] / "episodes.json").read_text())
    task = TaskConfig.from_dict(tiny["cfg"].task)
    for episode in episodes:
        summary = read_recording(episode["rrd"])
        paths = set(summary.entity_paths)
        assert set(blueprint_paths(read_views(episode["rrd"]))) <= paths
        assert summary.start is not None and summary.start.options
        best = max(summary.start.options, key=lambda o: o.score)
        assert best.combination == summary.start.chosen
        if episode["outcome"] != "wrong_start":
            continue
        sim = Simulation(task, Box(0.2, 0.15, 0.1))  # its bodies and features: any box's
        assert {f"world/{body}" for body in sim.body_poses()} <= paths
        assert {f"features/{name}" for name in sim.feature_names} <= paths
        assert {f"active/{v}" for v in sim.variables} | {"status", "start"} <= paths
        assert summary.n_ticks == 1
        names = [v.name for v in read_views(episode["rrd"])]
        assert "start" in names and "start map" in names
