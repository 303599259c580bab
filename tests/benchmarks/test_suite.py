"""The benchmarks (``cpmp.benchmarks.suite*``) and their command lines (``scripts/bench*.py``):
report structure and the behaviour behind the numbers, never a speed."""

import json

import numpy as np
import pytest

from cpmp.benchmarks.cli import (
    bench_main,
    bench_sequencer_main,
    bench_sim_main,
)
from cpmp.benchmarks.fit import (
    newton_solve_all,
    node_kernels,
    pad_features,
    problem_loss,
    sklearn_peer,
)
from cpmp.benchmarks.sequencer import bench_sequencer, bench_ticks
from cpmp.benchmarks.settings import SECTIONS, BenchSettings
from cpmp.errors import ConfigError
from cpmp.sequencer.sequencer import ConcurrentSequencer
from cpmp.worlds.relay.demonstrator import make_demonstrations as relay_demonstrations

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def test_bench_sequencer_prints_json(capsys):
    assert bench_sequencer_main(["--predictors", "klr", "--ticks", "20"]) == 0
    out = json.loads(capsys.readouterr().out)
    row = out["predictors"]["klr"]
    assert out["n_features"] == 3 and row["n_nodes"] == 6
    # 6 synthetic demos, stated support rule: 108 for the 6 nodes
    assert row["n_support_total"] == 108
    assert row["step_ms_mean"] > 0 and row["state_bytes"] > 0


def test_bench_sequencer_bad_file_is_a_clear_error(tmp_path, capsys):
    assert bench_sequencer_main(["--data", str(tmp_path / "missing.h5")]) == 2
    assert "error:" in capsys.readouterr().err


@pytest.mark.parametrize("bad", ["svm"])
def test_bench_sequencer_unknown_predictor(bad, capsys):
    assert bench_sequencer_main(["--predictors", bad, "--ticks", "5"]) == 2
    assert "unknown predictor" in capsys.readouterr().err


@pytest.mark.slow
def test_bench_sim_prints_json(capsys):
    assert bench_sim_main(["--width", "0.15", "--depth", "0.12", "--demos", "0"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["replay"]["outcome"] == "complete"


def test_bench_sim_rejects_a_bad_box(capsys):
    assert bench_sim_main(["--width", "-0.1", "--demos", "0"]) == 2
    assert "bench_sim: error: Box.width must be a positive length" in capsys.readouterr().err


# ------------------------------------------------------------------------ scripts/bench.py


def test_sklearn_peer_reaches_klrs_loss(fitted_klr, train_demos):
    """The peer minimises cpmp's loss exactly (C matched to l2, soft labels as two weighted
    copies): both optima agree to 1e-5 relative (both solvers stop at a gradient of 1e-10)."""
    problems = node_kernels(fitted_klr, train_demos)
    assert len(problems.kernels) == len(fitted_klr.predictor.node_keys)
    peer = sklearn_peer(problems)
    assert peer.converged and peer.iterations >= 1
    klr_loss = fitted_klr.fit_summary.loss
    assert problem_loss(problems, peer.solutions) == pytest.approx(klr_loss, rel=1e-5)
    solutions, _ = newton_solve_all(problems)
    assert problem_loss(problems, solutions) == pytest.approx(klr_loss, rel=1e-9)
    # a worse point has a larger loss: the comparison can fail
    zeros = [(np.zeros_like(w), 0.0) for w, _ in solutions]
    assert problem_loss(problems, zeros) > klr_loss * (1 + 1e-3)


def test_node_kernels_needs_a_kernel_predictor(train_demos):

    seq = ConcurrentSequencer.fit(train_demos, "mlp", seed=0, logger=None, epochs=2)
    with pytest.raises(ConfigError, match="has no kernel"):
        node_kernels(seq, train_demos)


def test_padding_features_keeps_the_supports():
    demos = relay_demonstrations(3, seed=0)
    padded = pad_features(demos, 10)
    assert padded[0].n_features == 10 and padded[0].feature_names[6:] == [
        f"pad_{j}" for j in range(4)
    ]
    np.testing.assert_array_equal(padded[0].features[:, :6], demos[0].features)
    assert not padded[0].features[:, 6:].any()

    counts = [
        ConcurrentSequencer.fit(d, "klr", seed=0, logger=None).fit_summary.n_support_total
        for d in (demos, padded)
    ]
    assert counts[0] == counts[1]
    with pytest.raises(ConfigError, match="cannot pad"):
        pad_features(demos, 3)


def test_batched_ticks_decide_as_single_ones(fitted_klr, test_demos):
    streams = [d.features for d in test_demos[:3]]
    ticks = max(len(s) for s in streams)  # the whole streams: every episode switches MPs
    result = bench_ticks(fitted_klr, streams, ticks=ticks)
    assert result["n_episodes"] == 3 and result["ticks"] == ticks
    assert result["same_decisions"]
    assert result["transitions"] >= 3
    assert result["single_ms"] > 0 and result["batched_ms"] > 0


def test_gradient_fit_reports_epochs_run(train_demos):
    out = bench_sequencer(train_demos[:4], ["mlp"], n_ticks=5, options={"mlp": {"epochs": 7}})
    row = out["predictors"]["mlp"]
    assert row["max_epochs"] == 7
    assert 1 <= row["epochs"] <= 7
    assert row["loss"] > 0


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"sections": ["fit", "gpu"]}, "unknown or no bench sections"),
        ({"batch": 0}, "batch must be a whole number >= 1"),
        ({"scaling_features": [4, 24]}, "scaling_features must be >= 6"),
        ({"scaling_demos": []}, "scaling_demos needs at least one value"),
        ({"max_time": -1.0}, "max_time must be > 0"),
    ],
)
def test_bench_settings_reject_bad_values(options, message):
    with pytest.raises(ConfigError, match=message):
        BenchSettings(**options)


def test_bench_script_bad_option_is_a_clear_error(tmp_path, capsys):
    assert bench_main(["--sections", "fit,gpu", "--out", str(tmp_path / "b")]) == 2
    assert "error: unknown or no bench sections" in capsys.readouterr().err
    assert not (tmp_path / "b" / "bench.json").exists()


@pytest.mark.slow
def test_bench_smallest_form_writes_every_section(tmp_path, capsys):
    """``scripts/bench.py`` at its smallest writes every section, the Markdown and the plot;
    each section's numbers are consistent with what it measured (the fit's losses against
    scikit-learn's, batched ticks deciding as single ones, the main job's stages within its
    wall time, padding adding no supports)."""
    out = tmp_path / "bench"
    args = ["--quick", "--out", str(out), "--fit-demos", "3", "--batch", "2", "--ticks", "20"]
    args += ["--max-time", "3", "--scaling-demos", "2,3", "--scaling-features", "6,8"]
    args += ["--gradient-epochs", "3", "--experiment", "tiny"]
    args += ["--experiment-override", "experiment.n_boxes=1"]
    args += ["--experiment-override", "experiment.max_time=3"]
    # the main job's process with the eager arm Jacobian: compiling it would cost more CPU
    # than the 1-box job's few ticks (the stages are still timed, kinematics set-up included)
    args += ["--experiment-override", "task.compile_kinematics=false"]
    assert bench_main(args) == 0
    assert capsys.readouterr().out.strip().splitlines()[-1] == str(out / "bench.json")
    result = json.loads((out / "bench.json").read_text())
    assert list(result["sections"]) == list(SECTIONS)
    assert (out / "bench_scaling.png").read_bytes()[:8] == PNG_SIGNATURE
    markdown = (out / "bench.md").read_text()
    for heading in ("Convex fit", "Sequencer cost", "Real-time factor", "Main job", "Scaling"):
        assert f"## {heading}" in markdown

    fit = result["sections"]["fit"]
    assert fit["n_demos"] == 3
    for key in ("fit_seconds", "sequencer_fit_seconds", "solve_seconds"):
        assert fit["klr"][key]["min"] <= fit["klr"][key]["median"]
    assert fit["klr"]["solve_loss"] == pytest.approx(fit["klr"]["loss"], rel=1e-9)
    assert fit["loss_rel_diff"] < 1e-5
    assert fit["ratio"]["fit_over_sklearn"] == pytest.approx(
        fit["klr"]["fit_seconds"]["min"] / fit["sklearn"]["seconds"]["min"]
    )

    ticks = result["sections"]["sequencer"]
    assert (ticks["n_episodes"], ticks["ticks"]) == (2, 20)
    assert ticks["same_decisions"] and ticks["n_heads"] == fit["n_heads"]

    realtime = result["sections"]["realtime"]
    single, batched = realtime["single"], realtime["batched"]
    assert realtime["same_outcomes"] and len(single["outcomes"]) == 2
    assert single["sim_time_s"] == pytest.approx(batched["sim_time_s"])
    for mode in (single, batched):
        assert sum(mode["share"].values()) == pytest.approx(1.0)
        assert mode["real_time_factor"] == pytest.approx(mode["sim_time_s"] / mode["wall_time_s"])

    stages = result["sections"]["stages"]
    assert stages["workers"] == 1
    assert {"kinematics", "collect", "expected", "train", "evaluate", "reproduce"} <= set(
        stages["stages"]
    )
    # one worker: the stages run one after the other inside the job
    assert sum(stages["stages"].values()) <= stages["job_seconds"]
    assert stages["job_seconds"] <= stages["process_wall_s"]
    w, i, c = (stages["reproduction"]["3"][k] for k in ("W", "I", "C"))
    assert w + i + c == 1

    scaling = result["sections"]["scaling"]
    assert [row["n_demos"] for row in scaling["demos"]] == [2, 3]
    assert [row["n_features"] for row in scaling["features"]] == [6, 8]
    supports = {row["n_support_total"] for row in scaling["features"]}
    assert len(supports) == 1  # padding adds no support points
    assert scaling["demos"][0]["n_support_total"] < scaling["demos"][1]["n_support_total"]

    gradient = result["sections"]["gradient"]["predictors"]
    assert set(gradient) == {"mlp"}
    assert all(1 <= row["epochs"] <= row["max_epochs"] == 3 for row in gradient.values())
