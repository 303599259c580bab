"""Trainer options (:class:`cpmp.config.TrainerConfig`): each bad value is refused with the
option's name and what it must be; whole-number floats are accepted as counts."""

from __future__ import annotations

import math

import pytest

from cpmp.config import TrainerConfig
from cpmp.errors import ConfigError


@pytest.mark.parametrize(
    ("options", "match"),
    [
        ({"early_stopping_tol": -1e-3}, "early_stopping_tol must be a finite number >= 0"),
        ({"early_stopping_tol": math.inf}, "early_stopping_tol"),
        ({"early_stopping_tol": math.nan}, "early_stopping_tol"),
        ({"early_stopping_tol": "1e-3"}, "early_stopping_tol"),
        ({"early_stopping_patience": 0}, "early_stopping_patience must be a whole number >= 1"),
        ({"early_stopping_patience": 2.5}, "early_stopping_patience"),
        ({"early_stopping_patience": True}, "early_stopping_patience"),
        ({"early_stopping": "yes"}, "early_stopping must be true or false"),
        ({"progress_bar": 1}, "progress_bar must be true or false"),
        ({"early_stopping_decays": -1}, "early_stopping_decays must be a whole number >= 0"),
        ({"early_stopping_decays": 1.5}, "early_stopping_decays"),
        ({"early_stopping_lr_factor": 1.0}, "early_stopping_lr_factor must be < 1"),
        ({"early_stopping_lr_factor": 0.0}, "early_stopping_lr_factor must be a finite number > 0"),
        ({"early_stopping_lr_factor": math.nan}, "early_stopping_lr_factor"),
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
