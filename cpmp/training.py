"""Fitting progress predictors through Lightning: all nodes of all graphs in one fit.

The whole training set is one full batch (a few thousand samples). Convex predictors (``klr``,
``klr_full``) are solved exactly: by default per node by damped Newton steps (IRLS, see
:mod:`cpmp.predictors.newton`) inside one manually optimised training step, or, with
``solver: lbfgs``, by LBFGS with a strong-Wolfe line search over all nodes together. The others
use Adam; ``klr_sparse`` re-fits its pruned weights with the convex solver.
"""

from __future__ import annotations

import logging
import math
import time
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch

from cpmp.errors import ConfigError
from cpmp.predictors import NodeData, ProgressPredictor
from cpmp.predictors.newton import NEWTON_MAX_ITER, NEWTON_TOL, NewtonInfo, SolverOptions

log = logging.getLogger(__name__)


@dataclass
class TrainerConfig:
    """Options of the Lightning trainer used for fitting.

    Attributes:
        max_epochs: full-batch optimiser steps (Newton: each solves every node to ``newton_tol``;
            LBFGS: each runs up to the predictor's ``max_iter`` iterations; ``None`` picks 1 for
            Newton, 3 for LBFGS and the predictor's ``epochs`` for Adam).
        progress_bar: show Lightning's progress bar.
        logger: ``"csv"``, ``"tensorboard"`` or ``None`` (no logging).
        log_dir: where the logger writes (``None``: no logger).
        lr: learning rate override for Adam-trained predictors.
        solver: ``"newton"`` (default) or ``"lbfgs"``: how convex weight fits are solved
            (``klr``, ``klr_full`` and ``klr_sparse``'s re-fit); Adam-trained parts ignore it.
        newton_tol: Newton stops per node when the max-norm of the loss gradient or the Newton
            decrement is at most this (> 0).
        newton_max_iter: Newton iterations per node at most (>= 1).
    """

    max_epochs: int | None = None
    progress_bar: bool = False
    logger: str | None = "csv"
    log_dir: str | None = None
    lr: float | None = None
    solver: str = "newton"
    newton_tol: float = NEWTON_TOL
    newton_max_iter: int = NEWTON_MAX_ITER

    def __post_init__(self) -> None:
        if self.max_epochs is not None and self.max_epochs < 1:
            raise ConfigError(f"trainer max_epochs must be >= 1, got {self.max_epochs}")
        if self.logger not in (None, "csv", "tensorboard"):
            raise ConfigError(
                f"trainer logger must be 'csv', 'tensorboard' or null, got {self.logger!r}"
            )
        if self.solver not in ("newton", "lbfgs"):
            raise ConfigError(f"trainer solver must be 'newton' or 'lbfgs', got {self.solver!r}")
        tol = self.newton_tol
        if isinstance(tol, bool) or not isinstance(tol, (int, float)) or not 0 < tol < math.inf:
            raise ConfigError(f"trainer newton_tol must be a finite number > 0, got {tol!r}")
        self.newton_tol = float(tol)
        count = self.newton_max_iter
        if (
            isinstance(count, bool)
            or not isinstance(count, (int, float))
            or not math.isfinite(count)
            or count != int(count)
            or count < 1
        ):
            raise ConfigError(f"trainer newton_max_iter must be a whole number >= 1, got {count!r}")
        self.newton_max_iter = int(count)

    def solver_options(self) -> SolverOptions:
        """The convex-solver settings handed to the predictor."""
        return SolverOptions(self.solver, self.newton_tol, self.newton_max_iter)


def _lightning_module(predictor: ProgressPredictor, data: list[NodeData], cfg: TrainerConfig):
    import lightning as L

    newton = predictor.convex and cfg.solver == "newton"

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
            value = self.trainer.callback_metrics.get("train/loss")
            if value is not None:
                self.history.append(float(value))

        def configure_optimizers(self) -> torch.optim.Optimizer | None:
            if newton:
                return None
            params = [p for p in self.predictor.parameters() if p.requires_grad]
            if predictor.convex:
                return torch.optim.LBFGS(
                    params,
                    max_iter=int(getattr(predictor.config, "max_iter", 500)),
                    line_search_fn="strong_wolfe",
                    tolerance_grad=1e-9,
                    tolerance_change=1e-12,
                    history_size=50,
                )
            rate = cfg.lr if cfg.lr is not None else float(getattr(predictor.config, "lr", 1e-2))
            return torch.optim.Adam(params, lr=rate)

    return ProgressModule()


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

    Returns a summary: final loss, loss history per epoch, wall time [s], predictor facts.
    """
    import lightning as L
    from torch.utils.data import DataLoader, TensorDataset

    cfg = trainer or TrainerConfig()
    generator = torch.Generator().manual_seed(seed)
    torch.manual_seed(seed)
    start = time.perf_counter()
    predictor.initialize(data, generator)
    module = _lightning_module(predictor, data, cfg)
    solver = cfg.solver if predictor.convex else "adam"
    if cfg.max_epochs is not None:
        epochs = cfg.max_epochs
    elif solver == "newton":
        epochs = 1
    elif solver == "lbfgs":
        epochs = 3
    else:
        epochs = int(getattr(predictor.config, "epochs", 300))
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
    loader = DataLoader(TensorDataset(torch.zeros(1)), batch_size=1)
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
        "fitted %s on %d nodes in %.2f s (loss %.5f)", predictor.kind, len(data), elapsed, final
    )
    out: dict[str, Any] = {
        "loss": final,
        "loss_history": module.history,
        "epochs": epochs,
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
