"""Fitting progress predictors through Lightning: all nodes of all graphs in one fit.

The whole training set is one full batch (a few thousand samples); convex predictors
(``klr``, ``klr_full``) use LBFGS with a strong-Wolfe line search, which reaches the optimum in
a few steps, the others Adam.
"""

from __future__ import annotations

import logging
import time
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch

from cpmp.errors import ConfigError
from cpmp.predictors import NodeData, ProgressPredictor

log = logging.getLogger(__name__)


@dataclass
class TrainerConfig:
    """Options of the Lightning trainer used for fitting.

    Attributes:
        max_epochs: full-batch optimiser steps (LBFGS: each runs up to ``max_iter`` iterations;
            ``None`` picks 3 for LBFGS and the predictor's ``epochs`` for Adam).
        progress_bar: show Lightning's progress bar.
        logger: ``"csv"``, ``"tensorboard"`` or ``None`` (no logging).
        log_dir: where the logger writes (``None``: no logger).
        lr: learning rate override for Adam-trained predictors.
    """

    max_epochs: int | None = None
    progress_bar: bool = False
    logger: str | None = "csv"
    log_dir: str | None = None
    lr: float | None = None

    def __post_init__(self) -> None:
        if self.max_epochs is not None and self.max_epochs < 1:
            raise ConfigError(f"trainer max_epochs must be >= 1, got {self.max_epochs}")
        if self.logger not in (None, "csv", "tensorboard"):
            raise ConfigError(
                f"trainer logger must be 'csv', 'tensorboard' or null, got {self.logger!r}"
            )


def _lightning_module(predictor: ProgressPredictor, data: list[NodeData], lr: float | None):
    import lightning as L

    class ProgressModule(L.LightningModule):
        """Wraps a predictor bank; one training step = the full-batch loss over all nodes."""

        def __init__(self) -> None:
            super().__init__()
            self.predictor = predictor
            self.data = data
            self.save_hyperparameters({"predictor": predictor.spec()["config"]})
            self.history: list[float] = []

        def training_step(self, batch: Any, batch_idx: int) -> torch.Tensor:
            loss = self.predictor.training_loss(self.data)
            self.log("train/loss", loss.detach(), prog_bar=True, on_epoch=True, on_step=False)
            return loss

        def on_train_epoch_end(self) -> None:
            value = self.trainer.callback_metrics.get("train/loss")
            if value is not None:
                self.history.append(float(value))

        def configure_optimizers(self) -> torch.optim.Optimizer:
            params = [p for p in self.predictor.parameters() if p.requires_grad]
            if predictor.optimizer == "lbfgs":
                return torch.optim.LBFGS(
                    params,
                    max_iter=int(getattr(predictor.config, "max_iter", 500)),
                    line_search_fn="strong_wolfe",
                    tolerance_grad=1e-9,
                    tolerance_change=1e-12,
                    history_size=50,
                )
            rate = lr if lr is not None else float(getattr(predictor.config, "lr", 1e-2))
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
    module = _lightning_module(predictor, data, cfg.lr)
    if cfg.max_epochs is not None:
        epochs = cfg.max_epochs
    elif predictor.optimizer == "lbfgs":
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
        pl_trainer.fit(module, loader)
    predictor.finalize(data)
    with torch.no_grad():
        final = float(predictor.training_loss(data))
    elapsed = time.perf_counter() - start
    log.info(
        "fitted %s on %d nodes in %.2f s (loss %.5f)", predictor.kind, len(data), elapsed, final
    )
    return {
        "loss": final,
        "loss_history": module.history,
        "epochs": epochs,
        "seconds": elapsed,
        **predictor.summary(),
    }
