"""``cpmp-evaluate`` reads every checkpoint kind ``cpmp-train`` and the main job write (every
predictor option with the learned sequencer, and the ``goal_nearest`` baseline) through one
loader, :func:`cpmp.evaluation.checkpoints.load_sequencer`."""

from __future__ import annotations

import json

import pytest
from hydra import compose, initialize_config_dir

from cpmp.baselines.goal_nearest import GoalNearestSequencer
from cpmp.cli.main import CONF_DIR
from cpmp.data.datafile import load_demonstrations
from cpmp.evaluation.checkpoints import load_sequencer
from cpmp.evaluation.offline import activation_progress, progress_errors, replay_demonstrations
from cpmp.experiment.checkpoint_jobs import evaluate_checkpoint, train_from_file
from cpmp.sequencer.sequencer import ConcurrentSequencer

PREDICTORS = sorted(p.stem for p in (CONF_DIR / "predictor").glob("*.yaml"))
FAST = {"mlp": ["predictor.epochs=20"], "klr_sparse": ["predictor.epochs=20"]}
"""Gradient fits cut short: the test is about loading and evaluating, not about their fit."""
KINDS = [(name, [f"predictor={name}", *FAST.get(name, [])]) for name in PREDICTORS] + [
    ("goal_nearest", ["sequencer=goal_nearest"])
]


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
    goal_nearest = name == "goal_nearest"
    assert isinstance(seq, GoalNearestSequencer if goal_nearest else ConcurrentSequencer)

    cfg = compose_cfg("evaluate", [data, f"checkpoint={checkpoint}"])
    out = json.loads(evaluate_checkpoint(cfg, eval_dir).read_text())
    assert out["n_demos"] == 2 and out["split"] == "test"
    if goal_nearest:
        assert out["model"]["sequencer"] == "goal_nearest"
        assert out["model"]["predictor"] == "none"
        assert out["model"]["used_to_switch"] is False
    else:
        assert out["model"] == {"sequencer": "learned", "predictor": seq.predictor.kind}
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
    if goal_nearest:
        assert "nearest-training-sample lookup" in markdown and "never uses to switch" in markdown
    else:
        assert f"predictor `{seq.predictor.kind}`" in markdown
    assert (eval_dir / "fig6_progress.png").stat().st_size > 0
