"""Fitting predictors (cpmp.predictors.training): the Lightning fit and its logs, the loss-plateau
rule and early stopping, trainer options and the global random state."""

import csv
import functools
import itertools
import math
from pathlib import Path

import numpy as np
import pytest
import torch

from cpmp.errors import ConfigError
from cpmp.predictors.training import LossPlateau, TrainerConfig
from cpmp.sequencer.sequencer import ConcurrentSequencer

CONF = Path(__file__).resolve().parents[2] / "conf"


@pytest.mark.parametrize("solver", ["newton", "lbfgs"])
def test_lightning_csv_logger_records_loss(train_demos, tmp_path, solver):
    seq = ConcurrentSequencer.fit(
        train_demos, "klr", seed=0, logger="csv", log_dir=str(tmp_path), solver=solver
    )
    (metrics,) = tmp_path.rglob("metrics.csv")
    rows = list(csv.DictReader(metrics.open()))
    losses = [float(r["train/loss"]) for r in rows if r.get("train/loss")]
    assert len(losses) == seq.fit_summary["epochs"] == {"newton": 1, "lbfgs": 3}[solver]
    assert losses == pytest.approx(seq.fit_summary["loss_history"], rel=1e-12)
    assert losses[-1] <= losses[0]
    assert seq.fit_summary["loss"] == pytest.approx(losses[-1], rel=1e-12)


def test_newton_reaches_the_convex_optimum(train_demos):
    # KLR's loss is convex: neither more LBFGS steps nor a second Newton epoch find a lower loss
    newton = ConcurrentSequencer.fit(train_demos, "klr", seed=0, logger=None)
    again = ConcurrentSequencer.fit(train_demos, "klr", seed=0, logger=None, max_epochs=2)
    lbfgs = ConcurrentSequencer.fit(
        train_demos, "klr", seed=0, logger=None, solver="lbfgs", max_epochs=8
    )
    assert newton.fit_summary["loss"] <= lbfgs.fit_summary["loss"] + 1e-12
    assert again.fit_summary["newton_iterations"] == 0
    assert again.fit_summary["loss"] == newton.fit_summary["loss"]


# ------------------------------------------------------------------------- early stopping
def test_loss_plateau_stops_after_patience_epochs_without_progress():
    rule = LossPlateau(tol=1e-3, patience=3)
    assert rule.update(10.0) == "go"  # the first epoch always improves
    assert rule.update(9.0) == "go"
    # three epochs within tol of the best (9.0 * 1e-3 = 0.009) do not count as progress
    assert [rule.update(loss) for loss in (8.995, 8.992, 8.9915)] == ["go", "go", "stop"]
    assert rule.best == 9.0


def test_loss_plateau_decays_before_it_stops():
    rule = LossPlateau(tol=1e-3, patience=2, decays=2)
    flat = [rule.update(5.0) for _ in range(5)]
    assert flat == ["go", "go", "decay", "go", "decay"]
    # progress after a decay goes on from the same best; the next plateau is the last
    assert [rule.update(loss) for loss in (4.0, 4.0, 4.0)] == ["go", "go", "stop"]


def test_loss_plateau_accumulates_slow_progress():
    # each epoch lowers the loss by 0.4 tol: every third epoch is a new best, never a plateau
    rule = LossPlateau(tol=1e-3, patience=3)
    loss = 10.0
    for _ in range(1000):
        assert rule.update(loss) == "go"
        loss *= 1.0 - 0.4e-3
    assert rule.wait < 3


def test_loss_plateau_stops_at_a_non_finite_loss():
    rule = LossPlateau(tol=1e-4, patience=50, decays=3)
    assert rule.update(3.0) == "go"
    assert rule.update(math.nan) == "stop"


@pytest.mark.parametrize("kind", ["mlp", "klr_sparse"])
def test_early_stopping_ends_an_easy_fit_before_its_budget(train_demos, tmp_path, kind):
    tol, patience, decays = 1e-3, 10, 1
    seq = ConcurrentSequencer.fit(
        train_demos,
        kind,
        seed=0,
        logger="csv",
        log_dir=str(tmp_path),
        epochs=5000,
        early_stopping_tol=tol,
        early_stopping_patience=patience,
        early_stopping_decays=decays,
    )
    summary = seq.fit_summary
    assert summary["stopped_early"] and summary["max_epochs"] == 5000
    assert 2 * patience < summary["epochs"] < 5000
    history = summary["loss_history"]
    assert len(history) == summary["epochs"]
    # the rule asked for one decay, and to stop at the last epoch and at no earlier one
    rule = LossPlateau(tol, patience, decays)
    actions = [rule.update(loss) for loss in history]
    assert actions.count("decay") == decays and actions.count("stop") == 1
    assert actions[-1] == "stop"
    (metrics,) = tmp_path.rglob("metrics.csv")
    logged = [r["train/loss"] for r in csv.DictReader(metrics.open()) if r.get("train/loss")]
    assert len(logged) == summary["epochs"]


def test_early_stopping_changes_nothing_but_the_epoch_count(train_demos):
    options = {"seed": 2, "logger": None, "early_stopping_tol": 1e-3, "early_stopping_patience": 5}
    options["early_stopping_decays"] = 0
    stopped = ConcurrentSequencer.fit(train_demos, "mlp", epochs=5000, **options)
    epochs = stopped.fit_summary["epochs"]
    assert stopped.fit_summary["stopped_early"]
    plain = ConcurrentSequencer.fit(
        train_demos, "mlp", epochs=epochs, early_stopping=False, **options
    )
    assert not plain.fit_summary["stopped_early"] and plain.fit_summary["epochs"] == epochs
    assert plain.fit_summary["loss_history"] == stopped.fit_summary["loss_history"]
    _assert_same_parameters(plain, stopped)


def test_a_plateau_lowers_the_rate_and_the_fit_goes_on(train_demos):
    options = {"seed": 0, "logger": None, "epochs": 5000, "early_stopping_tol": 1e-3}
    options["early_stopping_patience"] = 5
    fit = functools.partial(ConcurrentSequencer.fit, train_demos, "mlp", **options)
    stopped = fit(early_stopping_decays=0).fit_summary["loss_history"]
    tenth = fit(early_stopping_decays=1).fit_summary["loss_history"]
    half = fit(early_stopping_decays=1, early_stopping_lr_factor=0.5).fit_summary["loss_history"]
    plateau = len(stopped)
    # the same steps up to the first plateau, then training goes on at another rate
    assert tenth[:plateau] == half[:plateau] == stopped
    assert len(tenth) > plateau and len(half) > plateau
    assert tenth[plateau + 1] != half[plateau + 1]


def test_early_stopping_waits_while_the_loss_improves(train_demos):
    tol = 1e-4
    seq = ConcurrentSequencer.fit(
        train_demos,
        "mlp",
        seed=0,
        logger=None,
        epochs=40,
        lr=0.003,
        early_stopping_tol=tol,
        early_stopping_patience=2,
    )
    history = seq.fit_summary["loss_history"]
    # with a small rate the first Adam steps of a fresh MLP each lower the loss by more than tol
    assert all(b < a * (1.0 - tol) for a, b in itertools.pairwise(history))
    assert seq.fit_summary["epochs"] == 40 and not seq.fit_summary["stopped_early"]


def test_convex_fits_ignore_early_stopping(train_demos):
    seq = ConcurrentSequencer.fit(
        train_demos, "klr", seed=0, logger=None, solver="lbfgs", early_stopping_patience=1
    )
    assert seq.fit_summary["epochs"] == TrainerConfig().lbfgs_epochs
    assert not seq.fit_summary["stopped_early"]


# ------------------------------------------------------------------------- configuration
def test_bad_early_stopping_option_stops_a_fit_before_training(train_demos):
    with pytest.raises(ConfigError, match="early_stopping_patience"):
        ConcurrentSequencer.fit(train_demos, "mlp", logger=None, early_stopping_patience=-1)


# ------------------------------------------------------------------------- random state
@pytest.mark.parametrize(
    ("kind", "options"), [("mlp", {"epochs": 5}), ("klr_sparse", {"epochs": 5}), ("klr", {})]
)
def test_fit_leaves_the_global_random_state_alone(train_demos, kind, options):
    # the legacy global NumPy generator is what a caller's unseeded np.random.* calls draw from
    torch.manual_seed(1234)
    np.random.seed(99)  # noqa: NPY002
    torch_state, numpy_state = torch.get_rng_state(), np.random.get_state()  # noqa: NPY002
    first = ConcurrentSequencer.fit(train_demos, kind, seed=5, logger=None, **options)
    assert torch.equal(torch.get_rng_state(), torch_state)
    after = np.random.get_state()  # noqa: NPY002
    assert after[0] == numpy_state[0] and np.array_equal(after[1], numpy_state[1])
    assert after[2:] == numpy_state[2:]
    # another global state, the same seed: the same model
    torch.manual_seed(4321)
    second = ConcurrentSequencer.fit(train_demos, kind, seed=5, logger=None, **options)
    _assert_same_parameters(first, second)


def _assert_same_parameters(a: ConcurrentSequencer, b: ConcurrentSequencer) -> None:
    sa, sb = a.predictor.state_dict(), b.predictor.state_dict()
    assert list(sa) == list(sb)
    for name in sa:
        assert torch.equal(sa[name], sb[name]), name
