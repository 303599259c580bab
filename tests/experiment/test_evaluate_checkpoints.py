"""``cpmp-evaluate`` reads every checkpoint kind ``cpmp-train`` and the main job write (every
predictor option with the learned sequencer, and the ``goal_nearest`` and ``bc`` baselines)
through one loader, :func:`cpmp.evaluation.checkpoints.load_sequencer`."""

from __future__ import annotations

import json
import logging
from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir

from cpmp.baselines.bc import BCSequencer
from cpmp.baselines.goal_nearest import GoalNearestSequencer
from cpmp.cli.main import CONF_DIR, run_job
from cpmp.data.datafile import load_demonstrations, save_demonstrations
from cpmp.errors import DataError
from cpmp.evaluation.checkpoints import load_sequencer
from cpmp.evaluation.offline import activation_progress, progress_errors, replay_demonstrations
from cpmp.experiment.checkpoint_jobs import evaluate_checkpoint, train_from_file
from cpmp.sequencer.sequencer import ConcurrentSequencer

PREDICTORS = sorted(p.stem for p in (CONF_DIR / "predictor").glob("*.yaml"))
FAST = {"mlp": ["predictor.epochs=20"], "klr_sparse": ["predictor.refine_iter=5"]}
"""Fits cut short (mlp's epochs, klr_sparse's refinement): the test is about loading and
evaluating, not about their fit."""
KINDS = [(name, [f"predictor={name}", *FAST.get(name, [])]) for name in PREDICTORS] + [
    ("goal_nearest", ["sequencer=goal_nearest"]),
    ("bc", ["sequencer=bc"]),
]
BASELINES = {"goal_nearest": GoalNearestSequencer, "bc": BCSequencer}


def compose_cfg(name: str, overrides: list[str]):
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        return compose(name, overrides=overrides)


@pytest.mark.parametrize(("name", "overrides"), KINDS, ids=[k for k, _ in KINDS])
def test_evaluate_reads_every_checkpoint_kind(tmp_path, demo_file, name, overrides):
    train_dir, eval_dir = tmp_path / "train", tmp_path / "evaluate"
    train_dir.mkdir()
    eval_dir.mkdir()
    data = f"data.path={demo_file}"
    checkpoint = train_from_file(compose_cfg("train", [data, *overrides]), train_dir)
    seq = load_sequencer(checkpoint)
    baseline = name in BASELINES
    assert isinstance(seq, BASELINES.get(name, ConcurrentSequencer))

    cfg = compose_cfg("evaluate", [data, f"checkpoint={checkpoint}"])
    out = json.loads(evaluate_checkpoint(cfg, eval_dir).read_text())
    assert out["n_demos"] == 2 and out["split"] == "test"
    if baseline:
        assert out["model"]["sequencer"] == name
        assert out["model"]["predictor"] == "none"
        assert out["model"]["used_to_switch"] is False
    else:
        options = seq.predictor.spec()["config"]
        assert out["model"] == {
            "sequencer": "learned",
            "predictor": seq.predictor.kind,
            "feature_weighting": options.get("feature_weighting"),
            "feature_scaling": options.get("feature_scaling"),
            "switch_rule": seq.config.switch_rule,
            "coupling": seq.config.coupling,
        }
        weighting = options.get("feature_weighting")
        text = (eval_dir / "evaluation.md").read_text()
        assert f"predictor `{seq.predictor.kind}`" in text
        assert weighting is None or f"feature weighting `{weighting}`" in text
    # the loaded checkpoint, evaluated again on the file's test split, gives the same numbers
    test = load_demonstrations(demo_file, split="test")
    progress = out["progress"]
    assert progress == progress_errors(activation_progress(seq, test))
    assert set(progress["per_node"]) == {f"{v}/{mp}" for v, mp in seq.node_keys}
    replay = out["replay"]
    again = replay_demonstrations(seq, test)
    assert replay["sequence_match"] == again["sequence_match"]
    assert replay["all_match"] == again["all_match"]
    assert set(replay["sequence_match"]) == set(seq.graphs)
    # every variable matches in a demo counted in all_match
    assert replay["all_match"] <= min(replay["sequence_match"].values())
    markdown = (eval_dir / "evaluation.md").read_text()
    if baseline:
        assert f"sequencer={name} trains no progress predictor" in markdown
        assert "nearest-training-sample lookup" in markdown and "never uses to switch" in markdown
    else:
        assert f"predictor `{seq.predictor.kind}`" in markdown
    assert (eval_dir / "fig6_progress.png").stat().st_size > 0


def test_paper_and_cpmp_klr_are_told_apart_in_log_and_report(tmp_path, demo_file, caplog):
    """``predictor=klr`` and ``predictor=paper`` are both kind ``klr``: the train log and
    evaluation.md name the feature weighting, and the log counts the graphs' nodes (6 in the
    synthetic task)."""
    data = f"data.path={demo_file}"
    for preset, weighting in (("klr", "path"), ("paper", "none")):
        run = tmp_path / preset
        run.mkdir()
        overrides = [data, f"predictor={preset}"]
        with caplog.at_level(logging.INFO, logger="cpmp"):
            checkpoint = train_from_file(compose_cfg("train", overrides), run)
        fitted = [r.getMessage() for r in caplog.records if r.getMessage().startswith("fitted")]
        assert fitted[-1].startswith(f"fitted klr ({weighting} weighting) on 6 nodes in ")
        cfg = compose_cfg("evaluate", [data, f"checkpoint={checkpoint}"])
        evaluate_checkpoint(cfg, run)
        assert f"`klr` (feature weighting `{weighting}`" in (run / "evaluation.md").read_text()


def test_scoring_every_demonstration_is_a_visible_warning(tmp_path, demo_file, caplog):
    """A file without masks is scored whole: evaluation.md says these are not held-out numbers
    (not only "(split all)"), and so does the log."""
    checkpoint = train_from_file(compose_cfg("train", [f"data.path={demo_file}"]), tmp_path)
    bare = tmp_path / "bare.h5"
    save_demonstrations(bare, load_demonstrations(demo_file))
    run = tmp_path / "evaluate"
    run.mkdir()
    cfg = compose_cfg("evaluate", [f"data.path={bare}", f"checkpoint={checkpoint}"])
    with caplog.at_level(logging.WARNING, logger="cpmp"):
        evaluate_checkpoint(cfg, run)
    text = (run / "evaluation.md").read_text()
    assert "> **Warning:** every demonstration of the file was scored" in text
    assert "not held-out numbers" in text and "not held-out numbers" in caplog.text
    held_out = tmp_path / "held_out"
    held_out.mkdir()
    cfg = compose_cfg("evaluate", [f"data.path={demo_file}", f"checkpoint={checkpoint}"])
    evaluate_checkpoint(cfg, held_out)
    assert "Warning" not in (held_out / "evaluation.md").read_text()


def test_an_empty_split_is_named(tmp_path, demo_file):
    """An empty ``mask/train`` (cpmp-train) or ``mask/test`` (cpmp-evaluate) is named in the
    error, not "needs at least one demonstration, got none"."""
    path = tmp_path / "empty.h5"
    save_demonstrations(path, load_demonstrations(demo_file), splits={"train": [], "test": []})
    data = f"data.path={path}"
    with pytest.raises(DataError, match=r"split 'train' \(mask/train\) is empty: .* 6 demo"):
        train_from_file(compose_cfg("train", [data]), tmp_path)
    checkpoint = train_from_file(compose_cfg("train", [data, "data.split=null"]), tmp_path)
    with pytest.raises(DataError, match=r"split 'test' \(mask/test\) is empty: .* 6 demo"):
        evaluate_checkpoint(compose_cfg("evaluate", [data, f"checkpoint={checkpoint}"]), tmp_path)


def _failing_job(write: bool):
    """A job that raises a user error, after writing a file into its run directory or not."""

    def job(cfg, run_dir: Path) -> Path:
        if write:
            (run_dir / "partial.json").write_text("{}")
        raise DataError("bad file")

    return job


@pytest.mark.parametrize("write", [False, True])
def test_a_failed_job_leaves_no_empty_run_directory(tmp_path, capsys, write):
    run = tmp_path / "run"
    (run / ".hydra").mkdir(parents=True)
    (run / ".hydra" / "config.yaml").write_text("seed: 0\n")
    with pytest.raises(SystemExit) as info:
        run_job(_failing_job(write), {"threads": 1}, run)
    assert info.value.code == 2
    assert capsys.readouterr().err == "error: bad file\n"
    assert run.exists() == write  # kept only with the job's own output in it
    assert tmp_path.exists()


@pytest.mark.slow
def test_a_failed_command_prints_one_line_and_no_run_directory(tmp_path, demo_file, run_script):
    path = tmp_path / "empty.h5"
    save_demonstrations(path, load_demonstrations(demo_file), splits={"train": []})
    run = tmp_path / "run"
    proc = run_script("train.py", f"data.path={path}", f"hydra.run.dir={run}")
    assert proc.returncode == 2, proc.stderr[-2000:]
    assert [line for line in proc.stderr.splitlines() if "rror" in line] == [
        proc.stderr.strip().splitlines()[-1]
    ]
    assert proc.stderr.strip().splitlines()[-1].startswith("error: ")
    assert "mask/train" in proc.stderr and not run.exists()
