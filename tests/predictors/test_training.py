"""Fitting predictors (cpmp.predictors.training, .lightning, .datamodule): the Lightning fit and
its logs, held-out progress MAE per epoch, Lightning's early stopping and rate decay, mini-batches,
devices, loggers, trainer options and the global random state."""

import csv
import dataclasses
import functools
import itertools
import logging
import math
import warnings

import numpy as np
import pytest
import torch
import yaml
from lightning.pytorch.loggers import CSVLogger

from cpmp.errors import ConfigError, DataError
from cpmp.evaluation.offline import evaluate_offline
from cpmp.graph import build_graphs
from cpmp.predictors import make_predictor
from cpmp.predictors.base import nodes_to
from cpmp.predictors.datamodule import TrainBatches, ValBatches, held_out_split
from cpmp.predictors.training import TrainerConfig
from cpmp.sequencer.fit_data import node_training_data
from cpmp.sequencer.sequencer import ConcurrentSequencer


def _metrics(log_dir):
    """The rows of the one ``metrics.csv`` under ``log_dir``."""
    (metrics,) = log_dir.rglob("metrics.csv")
    return list(csv.DictReader(metrics.open()))


def _column(rows, name):
    return [float(r[name]) for r in rows if r.get(name)]


def _as_fitted(summary, value):
    """What the fitted bank's ``value`` is, as the last epoch measured it on the fit's device.

    The fitted bank is evaluated on the CPU: on the CPU that is the last epoch's number
    exactly; on a GPU only the order of the floating-point sums differs.
    """
    return value if summary.device == "cpu" else pytest.approx(value, rel=1e-9)


@pytest.mark.parametrize("solver", ["newton", "lbfgs"])
def test_lightning_csv_logger_records_loss(train_demos, tmp_path, solver):
    seq = ConcurrentSequencer.fit(
        train_demos, "klr", seed=0, logger="csv", log_dir=str(tmp_path), solver=solver
    )
    losses = _column(_metrics(tmp_path), "train/loss")
    assert len(losses) == seq.fit_summary.epochs == {"newton": 1, "lbfgs": 3}[solver]
    # the CSV holds the float64 values the history holds; each epoch logs the loss after its
    # step, so the last one is the fitted model's
    assert losses == list(seq.fit_summary.loss_history)
    assert losses[-1] <= losses[0]
    assert seq.fit_summary.loss == _as_fitted(seq.fit_summary, losses[-1])


def test_newton_reaches_the_convex_optimum(train_demos):
    # KLR's loss is convex: neither more LBFGS steps nor a second Newton epoch find a lower loss
    newton = ConcurrentSequencer.fit(train_demos, "klr", seed=0, logger=None)
    again = ConcurrentSequencer.fit(train_demos, "klr", seed=0, logger=None, max_epochs=2)
    lbfgs = ConcurrentSequencer.fit(
        train_demos, "klr", seed=0, logger=None, solver="lbfgs", max_epochs=8
    )
    assert newton.fit_summary.loss <= lbfgs.fit_summary.loss + 1e-12
    assert again.fit_summary.newton.iterations == 0
    assert again.fit_summary.loss == newton.fit_summary.loss


def test_hyperparameters_are_saved_with_the_logs(train_demos, tmp_path):
    ConcurrentSequencer.fit(train_demos, "klr", seed=0, logger="csv", log_dir=str(tmp_path))
    (hparams,) = tmp_path.rglob("hparams.yaml")
    saved = yaml.safe_load(hparams.read_text())
    assert saved["predictor"] == "klr" and saved["solver"] == "newton"
    assert saved["predictor_options"]["gamma"] == 4.0
    assert saved["trainer"]["newton_tol"] == TrainerConfig().newton_tol


# ---------------------------------------------------------------------- held-out progress
def test_a_fit_logs_and_prints_held_out_progress_mae_per_epoch(
    train_demos, test_demos, tmp_path, caplog
):
    with caplog.at_level(logging.INFO, logger="cpmp.predictors.lightning"):
        seq = ConcurrentSequencer.fit(
            train_demos, "mlp", seed=0, validation=test_demos, logger="csv",
            log_dir=str(tmp_path), epochs=12, early_stopping=False,
        )  # fmt: skip
    summary = seq.fit_summary
    rows = _metrics(tmp_path)
    assert _column(rows, "val/mae") == list(summary.val_mae)
    assert _column(rows, "val/loss") == list(summary.val_loss)
    assert _column(rows, "train/loss") == list(summary.loss_history)
    assert len(summary.val_mae) == summary.epochs == 12
    lines = [r.getMessage() for r in caplog.records if "val/mae" in r.getMessage()]
    assert [line.split(":")[0] for line in lines] == [f"mlp epoch {e}/12" for e in range(1, 13)]
    assert f"val/mae {summary.val_mae[-1]:.4f}" in lines[-1]
    # the last epoch's val/mae is the fitted model's held-out progress MAE, as the offline
    # evaluation measures it (same samples and labels; the two differ only in rounding)
    offline = evaluate_offline(seq, test_demos)["progress"]["mae"]
    assert summary.val_mae_final == _as_fitted(summary, summary.val_mae[-1])
    assert summary.val_mae_final == pytest.approx(offline, rel=1e-9)
    assert summary.monitor == "val/loss"


def test_validation_changes_nothing_in_a_newton_fit(train_demos, test_demos):
    plain = ConcurrentSequencer.fit(train_demos, "klr", seed=0, logger=None)
    validated = ConcurrentSequencer.fit(
        train_demos, "klr", seed=0, logger=None, validation=test_demos
    )
    _assert_same_parameters(plain, validated)
    assert plain.fit_summary.loss == validated.fit_summary.loss
    assert plain.fit_summary.val_mae == () and plain.fit_summary.val_mae_final is None
    assert len(validated.fit_summary.val_mae) == 1
    offline = evaluate_offline(validated, test_demos)["progress"]["mae"]
    assert validated.fit_summary.val_mae[0] == pytest.approx(offline, rel=1e-9)


def test_val_fraction_holds_out_seeded_demonstrations(train_demos):
    default = ConcurrentSequencer.fit(train_demos, "klr", seed=0, logger=None)
    assert default.fit_summary.n_demos == 6 and default.fit_summary.val_mae == ()
    a = ConcurrentSequencer.fit(train_demos, "klr", seed=3, logger=None, val_fraction=0.34)
    b = ConcurrentSequencer.fit(train_demos, "klr", seed=3, logger=None, val_fraction=0.34)
    assert a.fit_summary.n_demos == 4  # round(0.34 * 6) = 2 held out
    assert len(a.fit_summary.val_mae) == 1
    _assert_same_parameters(a, b)
    split = held_out_split(6, 0.34, 3)
    fitted = ConcurrentSequencer.fit(
        [train_demos[i] for i in split.train], "klr", seed=3, logger=None,
        validation=[train_demos[i] for i in split.val],
    )  # fmt: skip
    _assert_same_parameters(a, fitted)
    assert fitted.fit_summary.val_mae == a.fit_summary.val_mae


def test_held_out_split():
    split = held_out_split(10, 0.25, seed=1)
    assert len(split.val) == 2 and sorted(split.train + split.val) == list(range(10))
    assert split == held_out_split(10, 0.25, seed=1)
    assert len(held_out_split(3, 0.01, seed=0).val) == 1  # at least one
    with pytest.raises(ConfigError, match="leaving none to train on"):
        held_out_split(2, 0.9, seed=0)


def test_validation_demonstrations_need_the_training_features(train_demos):
    demo = train_demos[0]
    other = dataclasses.replace(demo, feature_names=["u", "v", "w"])
    with pytest.raises(DataError, match="validation demonstrations have features"):
        ConcurrentSequencer.fit(train_demos, "klr", seed=0, logger=None, validation=[other])


# ------------------------------------------------------------------------- early stopping
def _stop_epoch(history, min_delta, patience):
    """The epoch (1-based) at which Lightning's EarlyStopping stops on ``history``, or None."""
    best, wait = math.inf, 0
    for epoch, loss in enumerate(history, 1):
        if loss + min_delta < best:
            best, wait = loss, 0
        else:
            wait += 1
            if wait >= patience:
                return epoch
    return None


def _decay_epochs(history, min_delta, patience):
    """Epochs (1-based) after which ReduceLROnPlateau (abs threshold) lowers the rate."""
    best, bad, out = math.inf, 0, []
    for epoch, loss in enumerate(history, 1):
        if loss < best - min_delta:
            best, bad = loss, 0
        else:
            bad += 1
        if bad >= patience:
            out.append(epoch)
            bad = 0
    return out


def _rate_drops(lr):
    """Epochs (1-based) after which the recorded rate is lower than before."""
    return [e for e in range(1, len(lr)) if lr[e] < lr[e - 1]]


def test_early_stopping_ends_an_easy_fit_before_its_budget(train_demos, tmp_path):
    delta, patience, decay = 1e-3, 12, 5
    seq = ConcurrentSequencer.fit(
        train_demos, "mlp", seed=0, logger="csv", log_dir=str(tmp_path), epochs=5000,
        early_stopping_min_delta=delta, early_stopping_patience=patience,
        lr_decay_patience=decay,
    )  # fmt: skip
    summary = seq.fit_summary
    assert summary.stopped_early and summary.max_epochs == 5000
    assert summary.monitor == "train/loss"
    history = summary.loss_history
    assert patience < summary.epochs == len(history) < 5000
    # Lightning's EarlyStopping stopped where its rule says, and the scheduler lowered the
    # rate (x 0.1) where its rule says
    assert _stop_epoch(history, delta, patience) == summary.epochs
    drops = _decay_epochs(history, delta, decay)
    assert drops and _rate_drops(summary.lr_history) == [e for e in drops if e < len(history)]
    rows = _metrics(tmp_path)
    assert _column(rows, "train/loss") == list(history)
    assert _column(rows, "lr") == list(summary.lr_history)  # Lightning's LearningRateMonitor


def test_early_stopping_follows_the_validation_loss(train_demos, test_demos):
    delta, patience, decay = 1e-3, 12, 4
    seq = ConcurrentSequencer.fit(
        train_demos, "mlp", seed=0, logger=None, validation=test_demos, epochs=5000,
        early_stopping_min_delta=delta, early_stopping_patience=patience,
        lr_decay_patience=decay,
    )  # fmt: skip
    summary = seq.fit_summary
    epochs = summary.epochs
    assert summary.monitor == "val/loss" and summary.stopped_early
    assert _stop_epoch(summary.val_loss, delta, patience) == epochs
    drops = [e for e in _decay_epochs(summary.val_loss, delta, decay) if e < epochs]
    assert drops and _rate_drops(summary.lr_history) == drops
    # the training loss would have lowered the rate at other epochs
    assert drops != [e for e in _decay_epochs(summary.loss_history, delta, decay) if e < epochs]


def test_early_stopping_changes_nothing_but_the_epoch_count(train_demos):
    # with the rate decay slower than the stop, no decay happens before the fit stops
    options = {"seed": 2, "logger": None, "early_stopping_min_delta": 3e-3}
    options |= {"early_stopping_patience": 5, "lr_decay_patience": 6}
    stopped = ConcurrentSequencer.fit(train_demos, "mlp", epochs=5000, **options)
    epochs = stopped.fit_summary.epochs
    assert stopped.fit_summary.stopped_early
    assert len(set(stopped.fit_summary.lr_history)) == 1
    plain = ConcurrentSequencer.fit(
        train_demos, "mlp", epochs=epochs, early_stopping=False, **options
    )
    assert not plain.fit_summary.stopped_early and plain.fit_summary.epochs == epochs
    assert plain.fit_summary.loss_history == stopped.fit_summary.loss_history
    _assert_same_parameters(plain, stopped)


def test_a_plateau_lowers_the_rate_and_the_fit_goes_on(train_demos):
    options = {"seed": 0, "epochs": 5000, "early_stopping_min_delta": 3e-3}
    options |= {"early_stopping_patience": 15, "lr_decay_patience": 5, "logger": None}
    fit = functools.partial(ConcurrentSequencer.fit, train_demos, "mlp", **options)
    a, b = fit().fit_summary, fit(lr_decay_factor=0.5).fit_summary
    tenth, half = a.loss_history, b.loss_history
    lr_tenth, lr_half = a.lr_history, b.lr_history
    first = _rate_drops(lr_tenth)[0]
    # the same steps up to the first plateau, then training goes on at another rate
    assert _rate_drops(lr_half)[0] == first and tenth[:first] == half[:first]
    assert lr_tenth[first] == pytest.approx(0.1 * lr_tenth[0], rel=1e-12)
    assert lr_half[first] == pytest.approx(0.5 * lr_half[0], rel=1e-12)
    assert len(tenth) > first + 1 and tenth[first + 1] != half[first + 1]


def test_early_stopping_waits_while_the_loss_improves(train_demos):
    delta = 1e-4
    seq = ConcurrentSequencer.fit(
        train_demos, "mlp", seed=0, logger=None, epochs=40, lr=0.003,
        early_stopping_min_delta=delta, early_stopping_patience=2, lr_decay_patience=1,
    )  # fmt: skip
    history = seq.fit_summary.loss_history
    # with a small rate the first Adam steps of a fresh MLP each lower the loss by more than
    # min_delta: neither rule fires
    assert all(b + delta < a for a, b in itertools.pairwise(history))
    assert seq.fit_summary.epochs == 40 and not seq.fit_summary.stopped_early


def test_convex_fits_ignore_early_stopping(train_demos):
    seq = ConcurrentSequencer.fit(
        train_demos, "klr", seed=0, logger=None, solver="lbfgs", early_stopping_patience=1
    )
    assert seq.fit_summary.epochs == TrainerConfig().lbfgs_epochs
    assert not seq.fit_summary.stopped_early


# ---------------------------------------------------------------------------- mini-batches
def test_train_batches_cover_every_node_in_every_batch():
    generator = torch.Generator().manual_seed(0)
    batches = TrainBatches([10, 3, 25], batch_size=4, generator=generator)
    assert len(batches) == 7  # ceil(25 / 4)
    epoch = list(batches)
    assert len(epoch) == 7
    for i, n in enumerate([10, 3, 25]):
        rows = torch.cat([batch[i] for batch in epoch])
        assert all(1 <= len(batch[i]) <= 4 for batch in epoch)
        assert set(rows.tolist()) == set(range(n))  # every row at least once
    # each epoch draws a new order, from the generator only
    again = list(batches)
    assert any(not torch.equal(a[2], b[2]) for a, b in zip(epoch, again, strict=True))
    full = list(TrainBatches([10, 3], batch_size=None))
    assert len(full) == 1 and [r.tolist() for r in full[0]] == [list(range(10)), [0, 1, 2]]


def test_validation_batches_hold_every_row_once():
    batches = ValBatches([7, 0, 2], batch_size=3)
    assert len(batches) == 3
    for i, n in enumerate([7, 0, 2]):
        assert torch.cat([batch[i] for batch in batches]).tolist() == list(range(n))
    assert len(ValBatches([0, 0])) == 0


def test_mini_batches_train_an_adam_predictor(train_demos, tmp_path):
    options = {"seed": 1, "epochs": 5, "early_stopping": False}
    full = ConcurrentSequencer.fit(train_demos, "mlp", logger=None, **options)
    mini = ConcurrentSequencer.fit(
        train_demos, "mlp", logger="csv", log_dir=str(tmp_path), batch_size=64, **options
    )
    again = ConcurrentSequencer.fit(train_demos, "mlp", logger=None, batch_size=64, **options)
    _assert_same_parameters(mini, again)  # the shuffles come from the seed
    assert mini.fit_summary.epochs == 5
    # several Adam steps per epoch get further than one full-batch step per epoch
    assert mini.fit_summary.loss < full.fit_summary.loss
    steps = {int(r["step"]) for r in _metrics(tmp_path) if r.get("train/loss")}
    largest = max(int(n.x.shape[0]) for n in _node_data(train_demos))
    assert max(steps) + 1 == 5 * math.ceil(largest / 64)


def _node_data(demos):
    """The per-node training data ``mlp`` fits on ``demos``."""
    graphs = build_graphs(demos)
    keys = [(v, mp) for v in sorted(graphs) for mp in graphs[v].ordered_nodes()]
    bank = make_predictor("mlp", keys, demos[0].features.shape[1])
    bank.scaler.fit(np.concatenate([d.features for d in demos]), bank.config.feature_scaling)
    return node_training_data(graphs, bank)


# --------------------------------------------------------------------- devices and warnings
@pytest.mark.parametrize(
    ("kind", "options"),
    [("klr", {}), ("klr", {"solver": "lbfgs"}), ("mlp", {"epochs": 3, "batch_size": 100})],
)
def test_a_fit_on_auto_accelerator_emits_no_warning(
    train_demos, test_demos, tmp_path, monkeypatch, kind, options
):
    # as on a machine with many cores, where Lightning asks DataLoaders for more workers
    monkeypatch.setattr(
        "lightning.pytorch.trainer.connectors.data_connector.suggested_max_num_workers",
        lambda local_world_size: 8,
    )
    assert TrainerConfig().accelerator == "auto"
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        seq = ConcurrentSequencer.fit(
            train_demos, kind, seed=0, logger="csv", log_dir=str(tmp_path),
            validation=test_demos, **options,
        )  # fmt: skip
    assert [str(w.message) for w in caught] == []
    # "auto" takes the GPU where there is one; the fitted bank comes back to the CPU either way
    assert seq.fit_summary.device == ("cuda:0" if torch.cuda.is_available() else "cpu")
    assert all(p.device.type == "cpu" for p in seq.predictor.parameters())


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
@pytest.mark.parametrize(
    ("kind", "options"), [("klr", {}), ("klr", {"solver": "lbfgs"}), ("klr_sparse", {})]
)
def test_a_fit_on_a_gpu_gives_the_cpu_fit(train_demos, test_demos, kind, options):
    fits = {
        accelerator: ConcurrentSequencer.fit(
            train_demos, kind, seed=0, logger=None, accelerator=accelerator, **options
        )
        for accelerator in ("cpu", "gpu")
    }
    assert fits["gpu"].fit_summary.device == "cuda:0"
    assert fits["cpu"].fit_summary.device == "cpu"
    assert all(p.device.type == "cpu" for p in fits["gpu"].predictor.parameters())
    x = torch.cat([torch.as_tensor(d.features) for d in test_demos])
    with torch.no_grad():
        cpu, gpu = (fits[a].predictor(x) for a in ("cpu", "gpu"))
    # the same solver on the same data: only the order of floating-point sums differs
    assert (gpu - cpu).abs().max() < 1e-6
    assert fits["gpu"].fit_summary.n_support_total == fits["cpu"].fit_summary.n_support_total


def test_a_cpu_fit_on_a_gpu_machine_emits_no_warning(train_demos, monkeypatch):
    # the accelerator is the user's choice: Lightning's "GPU available but not used" is dropped
    monkeypatch.setattr(
        "lightning.pytorch.trainer.setup.CUDAAccelerator.is_available", staticmethod(lambda: True)
    )
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        seq = ConcurrentSequencer.fit(train_demos, "klr", seed=0, logger=None, accelerator="cpu")
    assert [str(w.message) for w in caught] == []
    assert seq.fit_summary.device == "cpu"


def test_a_fit_runs_on_one_device(train_demos):
    with pytest.raises(ConfigError, match="runs on one device"):
        ConcurrentSequencer.fit(train_demos, "klr", logger=None, accelerator="cpu", devices=2)


def test_node_data_moves_only_when_it_must(train_demos):
    data = _node_data(train_demos)
    assert nodes_to(data, "cpu") is data
    moved = data[0].to(torch.device("meta"))
    assert moved.x.device.type == "meta" and moved.activations is data[0].activations


# --------------------------------------------------------------------------------- loggers
def test_a_logger_instance_is_used_as_it_is(train_demos, tmp_path):
    logger = CSVLogger(tmp_path, name="mine", version="v")
    ConcurrentSequencer.fit(train_demos, "klr", seed=0, logger=logger)
    assert (tmp_path / "mine" / "v" / "metrics.csv").is_file()


def test_tensorboard_logger_writes_event_files(train_demos, tmp_path):
    ConcurrentSequencer.fit(
        train_demos, "klr", seed=0, logger="tensorboard", log_dir=str(tmp_path),
        validation=train_demos[:2],
    )  # fmt: skip
    assert list(tmp_path.rglob("events.out.tfevents.*"))


@pytest.mark.parametrize(
    ("logger", "log_dir", "match"),
    [("wandb", "x", "logger must be a Lightning Logger"), ("csv", None, "needs the trainer")],
)
def test_bad_logger_fails_before_training(train_demos, tmp_path, logger, log_dir, match):
    with pytest.raises(ConfigError, match=match):
        ConcurrentSequencer.fit(train_demos, "klr", logger=logger, log_dir=log_dir)


# ------------------------------------------------------------------------- configuration
def test_bad_early_stopping_option_stops_a_fit_before_training(train_demos):
    with pytest.raises(ConfigError, match="early_stopping_patience"):
        ConcurrentSequencer.fit(train_demos, "mlp", logger=None, early_stopping_patience=-1)


# ------------------------------------------------------------------------- random state
@pytest.mark.parametrize(
    ("kind", "options"),
    [
        ("mlp", {"epochs": 5}),
        ("mlp", {"epochs": 2, "batch_size": 50}),
        ("klr_sparse", {"refine_iter": 2}),
        ("klr", {}),
    ],
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
