"""Fitting progress predictors through Lightning: all nodes of all graphs in one fit.

The whole training set is one full batch (a few thousand samples). Convex predictors (``klr``,
``klr_full``) are solved exactly: by default per node by damped Newton steps (IRLS, see
:mod:`cpmp.predictors.newton`) inside one manually optimised training step, or, with
``solver: lbfgs``, by LBFGS with a strong-Wolfe line search over all nodes together. The others
use Adam: when the training loss stops improving the learning rate drops, and at the last
such plateau the fit stops (:class:`LossPlateau`); ``klr_sparse`` re-fits its pruned weights
with the convex solver.
"""

from __future__ import annotations

import logging
import math
import time
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import torch

from cpmp.errors import ConfigError
from cpmp.predictors import NodeData, ProgressPredictor
from cpmp.predictors.newton import NEWTON_MAX_ITER, NEWTON_TOL, NewtonInfo, SolverOptions

log = logging.getLogger(__name__)


LBFGS_EPOCHS = 3
"""Default LBFGS optimiser steps (each up to the predictor's ``max_iter`` iterations)."""
EARLY_STOPPING_TOL = 1e-4
"""Default relative loss improvement that counts as progress for early stopping."""
EARLY_STOPPING_PATIENCE = 20
"""Default epochs without such progress before an Adam fit lowers its rate or stops."""
EARLY_STOPPING_DECAYS = 2
"""Default number of plateaus that lower the learning rate before one stops the fit."""
EARLY_STOPPING_LR_FACTOR = 0.1
"""Default learning-rate factor at such a plateau."""


@dataclass
class TrainerConfig:
    """Options of the Lightning trainer used for fitting.

    Attributes:
        max_epochs: full-batch optimiser steps (Newton: each solves every node to ``newton_tol``;
            LBFGS: each runs up to the predictor's ``max_iter`` iterations; Adam: one step);
            ``None`` picks 1 for Newton (a second step finds nothing left to do),
            ``lbfgs_epochs`` for LBFGS and the predictor's ``epochs`` for Adam. Adam fits may
            stop before it (see ``early_stopping``).
        progress_bar: show Lightning's progress bar.
        logger: ``"csv"``, ``"tensorboard"`` or ``None`` (no logging).
        log_dir: where the logger writes (``None``: no logger).
        lr: learning rate override for Adam-trained predictors (> 0; ``None``: the
            predictor's ``lr``).
        solver: ``"newton"`` (default) or ``"lbfgs"``: how convex weight fits are solved
            (``klr``, ``klr_full`` and ``klr_sparse``'s re-fit); Adam-trained parts ignore it.
        newton_tol: Newton stops per node when the max-norm of the loss gradient or the Newton
            decrement is at most this (> 0).
        newton_max_iter: Newton iterations per node at most (>= 1).
        lbfgs_epochs: LBFGS optimiser steps when ``max_epochs`` is ``None`` (>= 1).
        early_stopping: lower the rate of an Adam fit (``mlp``, ``klr_sparse``'s sparsity
            phase) when the training loss stops improving, and stop it at the last such
            plateau (see :class:`LossPlateau`); ``False`` runs every epoch of the budget.
            Convex solvers run their epochs regardless.
        early_stopping_tol: an epoch improves on the best loss so far only if it lowers it by
            more than this fraction of its magnitude (>= 0).
        early_stopping_patience: after this many epochs in a row without such an
            improvement, lower the learning rate or stop (>= 1).
        early_stopping_decays: how many such plateaus multiply the learning rate by
            ``early_stopping_lr_factor`` (and the fit goes on) before one stops it (>= 0): a
            smaller rate lets Adam settle where a large one keeps oscillating.
        early_stopping_lr_factor: the learning-rate factor of a decay (0 < factor < 1).
    """

    max_epochs: int | None = None
    progress_bar: bool = False
    logger: str | None = "csv"
    log_dir: str | None = None
    lr: float | None = None
    solver: str = "newton"
    newton_tol: float = NEWTON_TOL
    newton_max_iter: int = NEWTON_MAX_ITER
    lbfgs_epochs: int = LBFGS_EPOCHS
    early_stopping: bool = True
    early_stopping_tol: float = EARLY_STOPPING_TOL
    early_stopping_patience: int = EARLY_STOPPING_PATIENCE
    early_stopping_decays: int = EARLY_STOPPING_DECAYS
    early_stopping_lr_factor: float = EARLY_STOPPING_LR_FACTOR

    def __post_init__(self) -> None:
        if self.logger not in (None, "csv", "tensorboard"):
            raise ConfigError(
                f"trainer logger must be 'csv', 'tensorboard' or null, got {self.logger!r}"
            )
        if self.solver not in ("newton", "lbfgs"):
            raise ConfigError(f"trainer solver must be 'newton' or 'lbfgs', got {self.solver!r}")
        for name in ("progress_bar", "early_stopping"):
            if not isinstance(getattr(self, name), bool):
                raise ConfigError(
                    f"trainer {name} must be true or false, got {getattr(self, name)!r}"
                )
        if self.max_epochs is not None:
            self.max_epochs = self._whole("max_epochs")
        self.newton_max_iter = self._whole("newton_max_iter")
        self.lbfgs_epochs = self._whole("lbfgs_epochs")
        self.early_stopping_patience = self._whole("early_stopping_patience")
        self.early_stopping_decays = self._whole("early_stopping_decays", minimum=0)
        factor = self._finite("early_stopping_lr_factor", positive=True)
        if factor >= 1.0:
            raise ConfigError(
                f"trainer early_stopping_lr_factor must be < 1 (it lowers the rate), got {factor!r}"
            )
        self.early_stopping_lr_factor = factor
        self.newton_tol = self._finite("newton_tol", positive=True)
        self.early_stopping_tol = self._finite("early_stopping_tol", positive=False)
        if self.lr is not None:
            self.lr = self._finite("lr", positive=True)

    def _whole(self, name: str, minimum: int = 1) -> int:
        """Option ``name`` as a whole number >= ``minimum`` (``2.0`` is accepted as 2)."""
        value = getattr(self, name)
        if (
            isinstance(value, bool)
            or not isinstance(value, (int, float))
            or not math.isfinite(value)
            or value != int(value)
            or value < minimum
        ):
            raise ConfigError(f"trainer {name} must be a whole number >= {minimum}, got {value!r}")
        return int(value)

    def _finite(self, name: str, positive: bool) -> float:
        """Option ``name`` as a finite float, > 0 if ``positive`` else >= 0."""
        value = getattr(self, name)
        bound = "> 0" if positive else ">= 0"
        if (
            isinstance(value, bool)
            or not isinstance(value, (int, float))
            or not math.isfinite(value)
            or (value <= 0 if positive else value < 0)
        ):
            raise ConfigError(f"trainer {name} must be a finite number {bound}, got {value!r}")
        return float(value)

    def solver_options(self) -> SolverOptions:
        """The convex-solver settings handed to the predictor."""
        return SolverOptions(self.solver, self.newton_tol, self.newton_max_iter)


@dataclass
class LossPlateau:
    """Early-stopping rule on the training loss (one value per epoch).

    An epoch improves if its loss is below ``best - tol * |best|`` (``best``: the lowest loss
    of an improving epoch so far; the first epoch always improves). Once ``patience`` epochs
    in a row have not improved, the rule asks to lower the learning rate (``"decay"``) while
    it has done so fewer than ``decays`` times, else to stop; a non-finite loss stops at once.
    Slow progress accumulates: losses that each fall by less than the tolerance still improve
    once their sum exceeds it. The loss is a sum over nodes of soft-label cross-entropies,
    whose minimum is the targets' entropy, not 0, so the relative tolerance measures progress
    against the loss itself, whatever the number of nodes.
    """

    tol: float
    patience: int
    decays: int = 0
    best: float = math.inf
    wait: int = 0
    decayed: int = 0

    def update(self, loss: float) -> Literal["go", "decay", "stop"]:
        """Record one epoch's ``loss``; say whether to go on, lower the rate, or stop."""
        if not math.isfinite(loss):
            return "stop"
        if math.isinf(self.best) or loss < self.best - self.tol * abs(self.best):
            self.best = loss
            self.wait = 0
            return "go"
        self.wait += 1
        if self.wait < self.patience:
            return "go"
        if self.decayed < self.decays:
            self.decayed += 1
            self.wait = 0
            return "decay"
        return "stop"


def _lightning_module(
    predictor: ProgressPredictor,
    data: list[NodeData],
    cfg: TrainerConfig,
    plateau: LossPlateau | None,
    rate: float | None,
):
    """The Lightning module of one fit; ``plateau``: the early-stopping rule (``None``: run
    every epoch); ``rate``: Adam's learning rate (``None`` for convex predictors)."""
    import lightning as L

    newton = _solver(predictor, cfg) == "newton"

    class ProgressModule(L.LightningModule):
        """Wraps a predictor bank; one training step = the full-batch loss over all nodes.

        With Newton (manual optimisation) a step solves every node's convex problem and logs
        the loss at the solution; otherwise it returns the loss to LBFGS or Adam.
        """

        def __init__(self) -> None:
            super().__init__()
            self.automatic_optimization = not newton
            self.predictor = predictor
            self.data = data
            self.save_hyperparameters({"predictor": predictor.spec()["config"]})
            self.history: list[float] = []
            self.newton_info: list[NewtonInfo] = []
            self.stopped_early = False

        def training_step(self, batch: Any, batch_idx: int) -> torch.Tensor:
            if newton:
                self.newton_info = self.predictor.solve_convex(self.data, cfg.solver_options())
                with torch.no_grad():
                    loss = self.predictor.training_loss(self.data)
            else:
                loss = self.predictor.training_loss(self.data)
            self.log("train/loss", loss.detach(), prog_bar=True, on_epoch=True, on_step=False)
            return loss

        def on_train_epoch_end(self) -> None:
            loss = float(self.trainer.callback_metrics["train/loss"])
            self.history.append(loss)
            action = "go" if plateau is None else plateau.update(loss)
            if action == "decay":
                for group in self.trainer.optimizers[0].param_groups:
                    group["lr"] *= cfg.early_stopping_lr_factor
            elif action == "stop":
                self.stopped_early = len(self.history) < self.trainer.max_epochs
                self.trainer.should_stop = True

        def configure_optimizers(self) -> torch.optim.Optimizer | None:
            if newton:
                return None
            params = [p for p in self.predictor.parameters() if p.requires_grad]
            if rate is None:
                return torch.optim.LBFGS(
                    params,
                    max_iter=int(_predictor_option(predictor, "max_iter")),
                    line_search_fn="strong_wolfe",
                    tolerance_grad=1e-9,
                    tolerance_change=1e-12,
                    history_size=50,
                )
            return torch.optim.Adam(params, lr=rate)

    return ProgressModule()


def _solver(predictor: ProgressPredictor, cfg: TrainerConfig) -> str:
    """``adam`` for gradient-trained banks; for convex ones ``cfg.solver``, except that a bank
    without trainable parameters (e.g. ``dtw``) always uses its own :meth:`solve_convex`."""
    if not predictor.convex:
        return "adam"
    if not any(p.requires_grad for p in predictor.parameters()):
        return "newton"
    return cfg.solver


def _predictor_option(predictor: ProgressPredictor, name: str) -> Any:
    """Option ``name`` of the predictor's config, which its solver needs (Adam: ``epochs``,
    ``lr``; LBFGS: ``max_iter``)."""
    if not hasattr(predictor.config, name):
        raise ConfigError(
            f"predictor {predictor.kind!r} has no option {name!r}, which its solver needs; "
            f"add {name} to {type(predictor.config).__name__}"
        )
    return getattr(predictor.config, name)


def _quiet_lightning() -> None:
    """Silence Lightning's start-up banners (accelerator lines, tips) for quiet fits."""
    for name in ("lightning.pytorch.utilities.rank_zero", "lightning.pytorch.accelerators.cuda"):
        logging.getLogger(name).setLevel(logging.WARNING)


def fit_predictor(
    predictor: ProgressPredictor,
    data: list[NodeData],
    trainer: TrainerConfig | None = None,
    seed: int = 0,
) -> dict[str, Any]:
    """Initialise and fit ``predictor`` on every node's data in one Lightning fit.

    The randomness (initial weights) comes from a local generator seeded by ``seed``: the same
    seed gives the same fit, and the caller's global torch and NumPy random states are left
    as they were.

    Returns a summary: final loss, loss history per epoch, ``epochs`` actually run,
    ``max_epochs`` (the budget), ``stopped_early`` (the early-stopping rule ended an Adam fit
    before the budget), wall time [s], solver and predictor facts.
    """
    import lightning as L
    from torch.utils.data import DataLoader, TensorDataset

    cfg = trainer or TrainerConfig()
    generator = torch.Generator().manual_seed(seed)
    start = time.perf_counter()
    predictor.initialize(data, generator)
    solver = _solver(predictor, cfg)
    rate: float | None = None
    if solver == "adam":
        rate = cfg.lr if cfg.lr is not None else float(_predictor_option(predictor, "lr"))
    if cfg.max_epochs is not None:
        epochs = cfg.max_epochs
    elif solver == "newton":
        epochs = 1
    elif solver == "lbfgs":
        epochs = cfg.lbfgs_epochs
    else:
        epochs = int(_predictor_option(predictor, "epochs"))
    plateau = None
    if solver == "adam" and cfg.early_stopping:
        plateau = LossPlateau(
            cfg.early_stopping_tol, cfg.early_stopping_patience, cfg.early_stopping_decays
        )
    module = _lightning_module(predictor, data, cfg, plateau, rate)
    logger: Any = False
    if cfg.logger is not None and cfg.log_dir is not None:
        Path(cfg.log_dir).mkdir(parents=True, exist_ok=True)
        if cfg.logger == "csv":
            logger = L.pytorch.loggers.CSVLogger(cfg.log_dir, name="progress")
        else:
            logger = L.pytorch.loggers.TensorBoardLogger(cfg.log_dir, name="progress")
    if not cfg.progress_bar:
        _quiet_lightning()
    pl_trainer = L.Trainer(
        max_epochs=epochs,
        accelerator="cpu",
        devices=1,
        logger=logger,
        enable_checkpointing=False,
        enable_progress_bar=cfg.progress_bar,
        enable_model_summary=False,
        log_every_n_steps=1,
        num_sanity_val_steps=0,
        default_root_dir=cfg.log_dir,
    )
    # the loader draws a base seed per epoch: from its own generator, not the global one
    loader = DataLoader(
        TensorDataset(torch.zeros(1)), batch_size=1, generator=torch.Generator().manual_seed(seed)
    )
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*does not have many workers.*")
        warnings.filterwarnings("ignore", message=".*number of training batches.*")
        warnings.filterwarnings("ignore", message=".*LeafSpec.*")
        warnings.filterwarnings("ignore", message=".*returned `None`.*no optimizer.*")
        pl_trainer.fit(module, loader)
    predictor.finalize(data, cfg.solver_options())
    with torch.no_grad():
        final = float(predictor.training_loss(data))
    elapsed = time.perf_counter() - start
    log.info(
        "fitted %s on %d nodes in %.2f s, %d epochs%s (loss %.5f)",
        predictor.kind,
        len(data),
        elapsed,
        len(module.history),
        " (stopped early)" if module.stopped_early else "",
        final,
    )
    out: dict[str, Any] = {
        "loss": final,
        "loss_history": module.history,
        "epochs": len(module.history),
        "max_epochs": epochs,
        "stopped_early": module.stopped_early,
        "seconds": elapsed,
        "solver": solver,
        **predictor.summary(),
    }
    if module.newton_info:
        out.update(_newton_summary(module.newton_info))
        if not out["newton_converged"]:
            log.warning(
                "Newton stopped before newton_tol=%g on some nodes (largest gradient %.3g after "
                "%d iterations); raise newton_max_iter",
                cfg.newton_tol,
                out["newton_grad_max"],
                out["newton_iterations"],
            )
    return out


def _newton_summary(infos: list[NewtonInfo]) -> dict[str, Any]:
    """The worst node's Newton outcome: iterations, final gradient max-norm, convergence."""
    return {
        "newton_iterations": max(i.iterations for i in infos),
        "newton_grad_max": max(i.grad_max for i in infos),
        "newton_converged": all(i.converged for i in infos),
    }
