"""Trainer options (:class:`cpmp.config.TrainerConfig`): each bad value is refused with the
option's name and what it must be; whole-number floats are accepted as counts."""

from __future__ import annotations

import math

import pytest

from cpmp.config import SolverOptions, TrainerConfig
from cpmp.errors import ConfigError


@pytest.mark.parametrize(
    ("options", "match"),
    [
        (
            {"early_stopping_min_delta": -1e-3},
            "early_stopping_min_delta must be a finite number >= 0",
        ),
        ({"early_stopping_min_delta": math.inf}, "early_stopping_min_delta"),
        ({"early_stopping_min_delta": math.nan}, "early_stopping_min_delta"),
        ({"early_stopping_min_delta": "1e-3"}, "early_stopping_min_delta"),
        ({"early_stopping_patience": 0}, "early_stopping_patience must be a whole number >= 1"),
        ({"early_stopping_patience": 2.5}, "early_stopping_patience"),
        ({"early_stopping_patience": True}, "early_stopping_patience"),
        ({"early_stopping": "yes"}, "early_stopping must be true or false"),
        ({"progress_bar": 1}, "progress_bar must be true or false"),
        ({"lr_decay_patience": 0}, "lr_decay_patience must be a whole number >= 1"),
        ({"lr_decay_patience": 1.5}, "lr_decay_patience"),
        ({"lr_decay_factor": 1.0}, "lr_decay_factor must be < 1"),
        ({"lr_decay_factor": 0.0}, "lr_decay_factor must be a finite number > 0"),
        ({"lr_decay_factor": math.nan}, "lr_decay_factor"),
        ({"log_every_n_epochs": 0}, "log_every_n_epochs must be a whole number >= 1"),
        ({"batch_size": 0}, "batch_size must be a whole number >= 1"),
        ({"batch_size": 2.5}, "batch_size"),
        ({"val_fraction": 1.0}, "val_fraction must be < 1"),
        ({"val_fraction": -0.1}, "val_fraction must be a finite number >= 0"),
        ({"val_fraction": math.nan}, "val_fraction"),
        ({"accelerator": ""}, "accelerator must be a name"),
        ({"accelerator": None}, "accelerator must be a name"),
        ({"devices": 0}, "devices must be 'auto', a count >= 1"),
        ({"devices": "two"}, "devices"),
        ({"devices": []}, "devices"),
        ({"devices": [0, -1]}, "devices"),
        ({"devices": True}, "devices"),
        ({"lbfgs_epochs": 0}, "lbfgs_epochs must be a whole number >= 1"),
        ({"max_epochs": 1.5}, "max_epochs must be a whole number >= 1"),
        ({"max_epochs": 0}, "max_epochs"),
        ({"lr": 0.0}, "lr must be a finite number > 0"),
        ({"lr": math.nan}, "lr"),
    ],
)
def test_bad_trainer_options(options, match):
    with pytest.raises(ConfigError, match=match):
        TrainerConfig(**options)


@pytest.mark.parametrize(
    ("options", "match"),
    [
        ({"solver": "adam"}, "solver must be 'newton' or 'lbfgs'"),
        ({"newton_tol": 0.0}, "newton_tol must be a finite number > 0"),
        ({"newton_tol": -1e-8}, "newton_tol"),
        ({"newton_tol": float("nan")}, "newton_tol"),
        ({"newton_tol": "1e-8"}, "newton_tol"),
        ({"newton_tol": True}, "newton_tol"),
        ({"newton_max_iter": 0}, "newton_max_iter must be a whole number >= 1"),
        ({"newton_max_iter": 2.5}, "newton_max_iter"),
    ],
)
def test_bad_solver_options(options, match):
    with pytest.raises(ConfigError, match=match):
        TrainerConfig(**options)


def test_whole_number_options_accept_integral_floats():
    cfg = TrainerConfig(max_epochs=7.0, lbfgs_epochs=2.0, early_stopping_patience=4.0)
    assert (cfg.max_epochs, cfg.lbfgs_epochs, cfg.early_stopping_patience) == (7, 2, 4)
    assert all(type(v) is int for v in (cfg.max_epochs, cfg.lbfgs_epochs))


def test_device_options_take_lightning_forms():
    assert TrainerConfig().accelerator == "auto" and TrainerConfig().devices == "auto"
    assert TrainerConfig(devices=1.0).devices == 1
    assert TrainerConfig(devices=-1).devices == -1
    assert TrainerConfig(devices=(0,)).devices == [0]
    assert TrainerConfig(accelerator="cpu").accelerator == "cpu"


def test_solver_options_come_from_the_trainer():
    options = TrainerConfig(solver="lbfgs", newton_tol=1e-8, newton_max_iter=7).solver_options()
    assert options == SolverOptions("lbfgs", 1e-8, 7)
    assert SolverOptions() == TrainerConfig().solver_options()
