"""Fitting from the command line's configs (cpmp.experiment.fitting, checkpoint_jobs): the logger
chosen with ``logger=...``, and ``cpmp-train`` logging the held-out progress MAE per epoch."""

from __future__ import annotations

import csv
import json

import pytest
from hydra import compose, initialize_config_dir
from lightning.pytorch.loggers import CSVLogger, TensorBoardLogger

from cpmp.cli.compose import CONF_DIR
from cpmp.errors import ConfigError
from cpmp.experiment.checkpoint_jobs import train_from_file
from cpmp.experiment.config import job_fit_settings
from cpmp.experiment.fitting import make_logger, train_sequencer


def compose_train(*overrides: str):
    """The real ``conf/train.yaml`` with ``overrides``, as ``cpmp-train`` composes it."""
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        return compose("train", overrides=list(overrides))


def test_logger_group_picks_the_lightning_logger(tmp_path):
    assert isinstance(make_logger(job_fit_settings(compose_train()).logger, tmp_path), CSVLogger)
    tensorboard = job_fit_settings(compose_train("logger=tensorboard")).logger
    assert isinstance(make_logger(tensorboard, tmp_path), TensorBoardLogger)
    assert job_fit_settings(compose_train("logger=none")).logger is None
    assert make_logger(tensorboard, None) is None  # no log folder, no logger
    # any Lightning logger by _target_, its arguments as overrides
    custom = compose_train(
        "logger._target_=lightning.pytorch.loggers.CSVLogger", "+logger.version=v7"
    )
    logger = make_logger(job_fit_settings(custom).logger, tmp_path)
    assert isinstance(logger, CSVLogger) and logger.version == "v7"


@pytest.mark.parametrize(
    ("overrides", "match"),
    [
        (["logger._target_=builtins.dict"], "not a Lightning Logger"),
        (["logger._target_=lightning.pytorch.loggers.NoSuchLogger"], "NoSuchLogger"),
        (["~logger._target_"], "logger needs _target_"),
    ],
)
def test_bad_logger_configs_raise_config_error(tmp_path, overrides, match):
    with pytest.raises(ConfigError, match=match):
        make_logger(job_fit_settings(compose_train(*overrides)).logger, tmp_path)


def test_tensorboard_from_the_command_line_writes_event_files(demo_file, tmp_path):
    cfg = compose_train(f"data.path={demo_file}", "logger=tensorboard", "predictor=klr")
    train_from_file(cfg, tmp_path)
    events = list((tmp_path / "lightning").rglob("events.out.tfevents.*"))
    assert len(events) == 1 and events[0].stat().st_size > 0
    assert not list(tmp_path.rglob("metrics.csv"))


def test_no_logger_writes_no_logs(demo_file, tmp_path):
    cfg = compose_train(f"data.path={demo_file}", "logger=none", "predictor=klr")
    train_from_file(cfg, tmp_path)
    assert (tmp_path / "model.pt").is_file() and not (tmp_path / "lightning").exists()


@pytest.mark.slow
def test_cpmp_train_logs_held_out_progress_mae_per_epoch(demo_file, tmp_path, run_script):
    # demo_file: demo_0..3 train, demo_4..5 test; the test split validates the fit
    run_dir = tmp_path / "run"
    args = [f"data.path={demo_file}", "predictor=mlp", "trainer.max_epochs=4"]
    proc = run_script("train.py", *args, f"hydra.run.dir={run_dir}")
    assert proc.returncode == 0, proc.stderr[-3000:]
    (metrics,) = (run_dir / "lightning").rglob("metrics.csv")
    rows = list(csv.DictReader(metrics.open()))
    val_mae = [float(r["val/mae"]) for r in rows if r.get("val/mae")]
    summary = json.loads((run_dir / "train_summary.json").read_text())
    assert len(val_mae) == summary["epochs"] == 4
    assert val_mae == summary["val_mae"]
    assert [int(r["epoch"]) for r in rows if r.get("val/mae")] == [0, 1, 2, 3]
    # and prints it: one line per epoch on the console (Hydra's job log)
    printed = proc.stderr.splitlines() + proc.stdout.splitlines()
    assert sum("val/mae" in line and "mlp epoch" in line for line in printed) == 4


def test_train_sequencer_validates_on_the_given_demonstrations(train_demos, test_demos):
    settings = job_fit_settings(compose_train("logger=none"))
    seq = train_sequencer(train_demos, settings, seed=0, validation=test_demos)
    assert len(seq.fit_summary.val_mae) == 1 and seq.fit_summary.monitor == "val/loss"
    plain = train_sequencer(train_demos, settings, seed=0)
    assert plain.fit_summary.val_mae == () and plain.fit_summary.loss == seq.fit_summary.loss
