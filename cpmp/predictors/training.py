"""Fitting progress predictors through Lightning: all nodes of all graphs in one fit.

:func:`fit_predictor` builds the :class:`~cpmp.predictors.lightning.ProgressModule` around the
bank, the :class:`~cpmp.predictors.datamodule.ProgressDataModule` around its training (and
validation) data, Lightning's callbacks and the logger, and runs ``Trainer.fit``. Convex
predictors (``klr``, ``klr_full``, the baselines) are solved exactly: per node by damped Newton
steps (IRLS, see :mod:`cpmp.predictors.newton`) in one manually optimised epoch, or, with
``solver: lbfgs``, by LBFGS with a strong-Wolfe line search over all nodes together. The
others use Adam with Lightning's ``EarlyStopping`` and a ``ReduceLROnPlateau`` rate decay on the
validation loss (the training loss without validation data); ``klr_sparse`` then re-fits its
pruned weights with the convex solver.
"""

from __future__ import annotations

import contextlib
import logging
import time
import warnings
from collections.abc import Iterator
from typing import Literal

import lightning as L
import torch
import torch.utils._pytree as torch_pytree
from lightning.pytorch.callbacks import Callback, EarlyStopping, LearningRateMonitor
from lightning.pytorch.loggers import CSVLogger, Logger, TensorBoardLogger
from lightning.pytorch.utilities import _pytree as lightning_pytree

from cpmp.config.trainer import TrainerConfig
from cpmp.errors import ConfigError
from cpmp.predictors.base import NodeData, ProgressPredictor
from cpmp.predictors.datamodule import ProgressDataModule
from cpmp.predictors.lightning import HeldOutSums, ProgressModule, Solver
from cpmp.predictors.newton import NewtonInfo
from cpmp.records import FitReport, NewtonOutcome

log = logging.getLogger(__name__)

LoggerName = Literal["csv", "tensorboard"]
"""The loggers :func:`lightning_logger` makes from a name."""
LOGGER_NAMES: tuple[LoggerName, ...] = ("csv", "tensorboard")
LOGGER_RUN_NAME = "progress"
"""The run name (subfolder of the log directory) of the loggers made from a name."""

_CONSOLE_LOGGERS = ("lightning.pytorch.utilities.rank_zero", "lightning.pytorch.accelerators.cuda")
"""Where Lightning writes its start-up lines (which accelerator and device it uses)."""


def _lightning_leaf_spec_compat() -> None:
    """Let Lightning build leaf tree specs as torch >= 2.13 asks (one compatibility step).

    Lightning 2.6's ``CombinedLoader`` (which wraps every loader of every fit) flattens the
    loaders with ``LeafSpec()``, a constructor torch 2.13 deprecates with a ``FutureWarning``
    on every call. ``torch.utils._pytree.treespec_leaf()`` returns the same leaf spec without
    it, so Lightning's module is pointed at that; nothing changes where it is missing.
    """
    if hasattr(torch_pytree, "treespec_leaf") and hasattr(lightning_pytree, "LeafSpec"):
        lightning_pytree.LeafSpec = torch_pytree.treespec_leaf


_lightning_leaf_spec_compat()


def solver_for(predictor: ProgressPredictor, cfg: TrainerConfig) -> Solver:
    """How ``predictor``'s parameters are fitted.

    Args:
        predictor: the bank.
        cfg: the trainer's options (``solver`` for convex banks).

    Returns:
        ``adam`` for gradient-trained banks; ``cfg.solver`` for convex ones, except that a
        bank without trainable parameters (e.g. ``dtw``) always uses its own
        :meth:`~cpmp.predictors.ProgressPredictor.solve_convex` (``newton``).
    """
    if not predictor.convex:
        return "adam"
    if not any(p.requires_grad for p in predictor.parameters()):
        return "newton"
    return "lbfgs" if cfg.solver == "lbfgs" else "newton"


def _predictor_option(predictor: ProgressPredictor, name: str) -> float:
    """Option ``name`` of the predictor's config, which its solver needs.

    Args:
        predictor: the bank.
        name: ``epochs`` or ``lr`` (Adam), ``max_iter`` (LBFGS).

    Returns:
        The option's value (a number).

    Raises:
        ConfigError: the predictor's options lack it.
    """
    if not hasattr(predictor.config, name):
        raise ConfigError(
            f"predictor {predictor.kind!r} has no option {name!r}, which its solver needs; "
            f"add {name} to {type(predictor.config).__name__}"
        )
    return getattr(predictor.config, name)


def check_logger(logger: Logger | str | None, log_dir: str | None) -> None:
    """Check a fit's ``logger`` argument before any work.

    Args:
        logger: a Lightning ``Logger``, ``"csv"``, ``"tensorboard"`` or ``None``.
        log_dir: the trainer's ``log_dir``, where a logger given by name writes.

    Raises:
        ConfigError: an unknown name, a name without ``log_dir``, or another type.
    """
    if logger is None or isinstance(logger, Logger):
        return
    if not isinstance(logger, str) or logger not in LOGGER_NAMES:
        raise ConfigError(
            f"logger must be a Lightning Logger, 'csv', 'tensorboard' or None, got {logger!r}"
        )
    if log_dir is None:
        raise ConfigError(f"logger={logger!r} needs the trainer option log_dir (where it writes)")


def lightning_logger(logger: Logger | str | None, log_dir: str | None) -> Logger | None:
    """The Lightning logger of a fit.

    Args:
        logger: a Lightning ``Logger`` (used as it is), ``"csv"`` (``CSVLogger``),
            ``"tensorboard"`` (``TensorBoardLogger``) or ``None`` (no logging).
        log_dir: where a logger given by name writes (run name ``progress``).

    Returns:
        The logger, or ``None``.

    Raises:
        ConfigError: see :func:`check_logger`.
    """
    check_logger(logger, log_dir)
    if logger is None or isinstance(logger, Logger):
        return logger
    if logger == "csv":
        return CSVLogger(log_dir, name=LOGGER_RUN_NAME)
    return TensorBoardLogger(log_dir, name=LOGGER_RUN_NAME)


@contextlib.contextmanager
def _lightning_console(show: bool) -> Iterator[None]:
    """Keep Lightning's start-up INFO lines (accelerator, devices) off the console.

    Unless ``show``, for the length of one fit; the levels are restored afterwards. Lightning's
    "GPU available but not used" warning is dropped either way: the accelerator is the user's
    choice (``trainer.accelerator``), and the fit's log line and report name its device.
    """
    loggers = [logging.getLogger(name) for name in _CONSOLE_LOGGERS]
    levels = [lg.level for lg in loggers]
    if not show:
        for lg in loggers:
            lg.setLevel(logging.WARNING)
    try:
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message="GPU available but not used")
            yield
    finally:
        for lg, level in zip(loggers, levels, strict=True):
            lg.setLevel(level)


def _callbacks(solver: Solver, cfg: TrainerConfig, monitor: str, logged: bool) -> list[Callback]:
    """Lightning's callbacks of a fit: early stopping and the learning-rate monitor (Adam)."""
    if solver != "adam":
        return []
    callbacks: list[Callback] = []
    if cfg.early_stopping:
        callbacks.append(
            EarlyStopping(
                monitor=monitor,
                min_delta=cfg.early_stopping_min_delta,
                patience=cfg.early_stopping_patience,
                mode="min",
            )
        )
    if logged:
        callbacks.append(LearningRateMonitor(logging_interval="epoch"))
    return callbacks


def fit_predictor(
    predictor: ProgressPredictor,
    data: list[NodeData],
    trainer: TrainerConfig | None = None,
    seed: int = 0,
    validation: list[NodeData] | None = None,
    logger: Logger | str | None = None,
) -> FitReport:
    """Initialise and fit ``predictor`` on every node's data in one Lightning fit.

    The randomness (initial weights, mini-batch shuffles) comes from a local generator seeded
    by ``seed``: the same seed gives the same fit, and the caller's global torch and NumPy
    random states are left as they were. The fit runs on ``trainer.accelerator`` (one
    device); the fitted bank is brought back to the CPU.

    Args:
        predictor: the untrained bank (its feature scaler fitted).
        data: every node's training data, in the bank's node order.
        trainer: the trainer's options (``None``: the defaults).
        seed: the fit's seed.
        validation: every node's held-out data in the same order (a node may have none), or
            ``None``; a stateful bank (``dtw``) is not validated per epoch.
        logger: a Lightning ``Logger``, ``"csv"``, ``"tensorboard"`` (both write into
            ``trainer.log_dir``) or ``None``.

    Returns:
        The fit's report: final ``loss``, ``loss_history`` per epoch, ``val_loss`` and
        ``val_mae`` per epoch (empty without validation data), ``lr_history`` (Adam and
        LBFGS: the rate of each epoch) and ``val_mae_final`` (the fitted bank's, after
        :meth:`~cpmp.predictors.ProgressPredictor.finalize`; ``None`` without validation),
        ``epochs`` actually run, ``max_epochs`` (the budget), ``stopped_early`` (early
        stopping ended an Adam fit before the budget), ``monitor``, ``device``, wall time
        ``seconds``, ``solver``, the predictor's facts and Newton's outcome; the sequencer's
        fields (``n_demos``, ``warnings``, ...) at their defaults.

    Raises:
        ConfigError: a bad logger, or more than one device.
    """
    cfg = trainer or TrainerConfig()
    check_logger(logger, cfg.log_dir)
    generator = torch.Generator().manual_seed(seed)
    start = time.perf_counter()
    predictor.set_validation(None if predictor.stateful else validation)
    predictor.initialize(data, generator)
    solver = solver_for(predictor, cfg)
    lr = None
    if solver == "adam":
        lr = cfg.lr if cfg.lr is not None else float(_predictor_option(predictor, "lr"))
    if cfg.max_epochs is not None:
        epochs = cfg.max_epochs
    elif solver == "newton":
        epochs = 1
    elif solver == "lbfgs":
        epochs = cfg.lbfgs_epochs
    else:
        epochs = int(_predictor_option(predictor, "epochs"))
    datamodule = ProgressDataModule(
        data,
        None if predictor.stateful else validation,
        cfg.batch_size if solver == "adam" else None,
        generator,
    )
    monitor = "train/loss" if datamodule.val is None else "val/loss"
    max_iter = int(_predictor_option(predictor, "max_iter")) if solver == "lbfgs" else None
    module = ProgressModule(predictor, cfg, solver, lr, max_iter, monitor)
    pl_logger = lightning_logger(logger, cfg.log_dir)
    with _lightning_console(cfg.progress_bar):
        pl_trainer = L.Trainer(
            max_epochs=epochs,
            accelerator=cfg.accelerator,
            devices=cfg.devices,
            logger=pl_logger if pl_logger is not None else False,
            callbacks=_callbacks(solver, cfg, monitor, pl_logger is not None),
            enable_checkpointing=False,
            enable_progress_bar=cfg.progress_bar,
            enable_model_summary=False,
            log_every_n_steps=1,
            num_sanity_val_steps=0,
            limit_val_batches=0 if datamodule.val is None else 1.0,
            inference_mode=False,
            default_root_dir=cfg.log_dir,
        )
        if pl_trainer.num_devices != 1:
            raise ConfigError(
                f"a fit runs on one device, trainer.devices={cfg.devices!r} gives "
                f"{pl_trainer.num_devices}: set trainer.devices=1 (or [index])"
            )
        device = str(pl_trainer.strategy.root_device)
        pl_trainer.fit(module, datamodule=datamodule)
    predictor.to(torch.device("cpu"))  # the fitted bank is saved and used on the CPU
    predictor.finalize(data, cfg.solver_options())
    with torch.no_grad():
        final = float(predictor.training_loss(data))
    val_final = _held_out_mae(predictor, datamodule)
    elapsed = time.perf_counter() - start
    history = module.history
    stopped_early = solver == "adam" and len(history.train_loss) < epochs
    log.info(
        "fitted %s on %s in %.2f s on %s, %d epochs%s (loss %.5f%s)",
        _predictor_name(predictor),
        _node_count(data),
        elapsed,
        device,
        len(history.train_loss),
        " (stopped early)" if stopped_early else "",
        final,
        "" if val_final is None else f", held-out progress MAE {val_final:.4f}",
    )
    facts = dict(predictor.summary())
    counts, total = facts.pop("support_counts", None), facts.pop("n_support_total", None)
    newton = _newton_outcome(module.newton_info) if module.newton_info else None
    report = FitReport(
        loss=final,
        loss_history=tuple(history.train_loss),
        val_loss=tuple(history.val_loss),
        val_mae=tuple(history.val_mae),
        val_mae_final=val_final,
        lr_history=tuple(history.lr),
        epochs=len(history.train_loss),
        max_epochs=epochs,
        stopped_early=stopped_early,
        monitor=monitor,
        device=device,
        seconds=elapsed,
        solver=solver,
        kind=facts.pop("kind"),
        n_nodes=facts.pop("n_nodes"),
        n_parameters=facts.pop("n_parameters"),
        support_counts=counts,
        n_support_total=total,
        predictor_facts=facts,
        newton=newton,
    )
    if newton is not None and not newton.converged:
        log.warning(
            "Newton stopped before newton_tol=%g on some nodes (largest gradient %.3g after "
            "%d iterations); raise newton_max_iter",
            cfg.newton_tol,
            newton.grad_max,
            newton.iterations,
        )
    return report


def _predictor_name(predictor: ProgressPredictor) -> str:
    """The predictor's kind and, where it has one, its feature weighting (``klr (path weighting)``).

    ``predictor=klr`` and the paper's ``predictor=paper`` are both kind ``klr``; the
    weighting tells them apart.
    """
    weighting = getattr(predictor.config, "feature_weighting", None)
    return predictor.kind if weighting is None else f"{predictor.kind} ({weighting} weighting)"


def _node_count(data: list[NodeData]) -> str:
    """``"6 nodes"`` (``"1 node"``)."""
    return f"{len(data)} node{'s' if len(data) != 1 else ''}"


def _held_out_mae(predictor: ProgressPredictor, datamodule: ProgressDataModule) -> float | None:
    """``val/mae`` of the fitted bank (after ``finalize``), as a validation epoch computes it.

    Args:
        predictor: the fitted bank (on the CPU).
        datamodule: the fit's data (its validation batches).

    Returns:
        The held-out progress MAE, or ``None`` without validation data.
    """
    if datamodule.val is None:
        return None
    sums = HeldOutSums.zeros(predictor.n_nodes, "cpu")
    with torch.no_grad():
        for batch in datamodule.val_dataloader():
            sums.add(predictor, datamodule.val, batch)
    return float(sums.mae())


def _newton_outcome(infos: list[NewtonInfo]) -> NewtonOutcome:
    """The worst node's Newton outcome: iterations, final gradient max-norm, convergence."""
    return NewtonOutcome(
        iterations=max(i.iterations for i in infos),
        grad_max=max(i.grad_max for i in infos),
        converged=all(i.converged for i in infos),
    )
