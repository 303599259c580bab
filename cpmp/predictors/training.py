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

from cpmp.config.trainer import TrainerConfig
from cpmp.errors import ConfigError
from cpmp.predictors import NodeData, ProgressPredictor
from cpmp.predictors.newton import NewtonInfo

log = logging.getLogger(__name__)


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
    every epoch); ``rate``: Adam's learning rate (``None`` for convex predictors).
    """
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
                    tolerance_grad=cfg.lbfgs_tolerance_grad,
                    tolerance_change=cfg.lbfgs_tolerance_change,
                    history_size=cfg.lbfgs_history_size,
                )
            return torch.optim.Adam(params, lr=rate)

    return ProgressModule()


def _solver(predictor: ProgressPredictor, cfg: TrainerConfig) -> str:
    """``adam`` for gradient-trained banks; for convex ones ``cfg.solver``, except that a bank
    without trainable parameters (e.g. ``dtw``) always uses its own :meth:`solve_convex`.
    """
    if not predictor.convex:
        return "adam"
    if not any(p.requires_grad for p in predictor.parameters()):
        return "newton"
    return cfg.solver


def _predictor_option(predictor: ProgressPredictor, name: str) -> Any:
    """Option ``name`` of the predictor's config, which its solver needs (Adam: ``epochs``,
    ``lr``; LBFGS: ``max_iter``).
    """
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
