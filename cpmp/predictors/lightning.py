"""The ``LightningModule`` of a progress-predictor fit: one bank, every node, one module.

:class:`ProgressModule` wraps a :class:`~cpmp.predictors.ProgressPredictor` (the plain
``nn.Module`` bank of every node's predictor) and trains it on a
:class:`~cpmp.predictors.datamodule.ProgressDataModule`:

- convex banks (``klr``, ``klr_full``, the baselines) by full-batch Newton steps per node,
  in manual optimisation (``automatic_optimization = False``; one epoch solves every node),
  or by torch's LBFGS over all nodes (``solver: lbfgs``);
- the others (``mlp``, ``klr_sparse``'s sparsity phase) by Adam, full batch or mini-batches,
  with a ``ReduceLROnPlateau`` scheduler returned from :meth:`ProgressModule.
  configure_optimizers` (the trainer adds Lightning's ``EarlyStopping``).

Every epoch logs ``train/loss`` (the bank's training loss) and, with validation data,
``val/loss`` and ``val/mae``: the mean absolute difference between the predicted progress φ
and the held-out eq. 1 label over every held-out sample of every node, the offline
evaluation's progress MAE (:mod:`cpmp.evaluation.offline`).
"""

from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass, field
from typing import Literal

import lightning as L
import torch
from lightning.pytorch.utilities.types import OptimizerLRScheduler
from torch.nn import functional as F

from cpmp.config.trainer import TrainerConfig
from cpmp.io import to_builtin
from cpmp.predictors.base import NodeData, ProgressPredictor, nodes_to
from cpmp.predictors.datamodule import NodeRows
from cpmp.predictors.newton import NewtonInfo

log = logging.getLogger(__name__)

Solver = Literal["newton", "lbfgs", "adam"]
"""How a bank's parameters are fitted (see :func:`cpmp.predictors.training.solver_for`)."""


@dataclass
class FitHistory:
    """What each epoch of a fit measured.

    One entry per epoch; the validation lists stay empty without validation data.

    Attributes:
        train_loss: ``train/loss``: the bank's training loss of the epoch (Newton and LBFGS:
            at the epoch's end; Adam: the mean of its steps, each before its update).
        val_loss: ``val/loss``: per node the mean BCE of φ against the held-out labels,
            summed over nodes (log φ clamped at −100, so clipped outputs stay finite).
        val_mae: ``val/mae``: mean |φ − eq. 1 label| over the held-out samples.
        lr: the Adam or LBFGS learning rate of the epoch (empty for Newton).
    """

    train_loss: list[float] = field(default_factory=list)
    val_loss: list[float] = field(default_factory=list)
    val_mae: list[float] = field(default_factory=list)
    lr: list[float] = field(default_factory=list)


@dataclass
class HeldOutSums:
    """Running sums of a validation pass, per node: BCE of φ, |φ − label| and sample count.

    Attributes:
        bce: ``(K,)`` summed BCE of φ against the labels (float64).
        abs: ``(K,)`` summed |φ − label|.
        count: ``(K,)`` samples seen.
    """

    bce: torch.Tensor
    abs: torch.Tensor
    count: torch.Tensor

    @classmethod
    def zeros(cls, n_nodes: int, device: torch.device | str) -> HeldOutSums:
        """Empty sums for ``n_nodes`` heads on ``device``."""
        zeros = torch.zeros(n_nodes, dtype=torch.float64, device=device)
        return cls(zeros.clone(), zeros.clone(), zeros.clone())

    def add(self, predictor: ProgressPredictor, nodes: list[NodeData], batch: NodeRows) -> None:
        """Add the rows ``batch`` (per node ``(b_i,)``, possibly none) of ``nodes``."""
        for i, rows in enumerate(batch):
            if rows.numel() == 0:
                continue
            node = nodes[i]
            phi = torch.sigmoid(predictor.node_logits(node.x[rows], i))
            target = node.target[rows]
            self.bce[i] += F.binary_cross_entropy(phi, target, reduction="sum")
            self.abs[i] += (phi - target).abs().sum()
            self.count[i] += rows.numel()

    def loss(self) -> torch.Tensor:
        """``val/loss``: per node the mean BCE, summed over the nodes with samples."""
        seen = self.count > 0
        return (self.bce[seen] / self.count[seen]).sum()

    def mae(self) -> torch.Tensor:
        """``val/mae``: mean |φ − label| over every node's samples."""
        return self.abs.sum() / self.count.sum()


class ProgressModule(L.LightningModule):
    """Trains a predictor bank on a :class:`~cpmp.predictors.datamodule.ProgressDataModule`.

    With Newton (manual optimisation) a training step solves every node's convex problem and
    logs the loss at the solution; with LBFGS the step's closure returns the full-batch loss
    and the loss after the step is logged at the epoch's end; with Adam a step returns the
    loss of its batch of rows.
    """

    def __init__(
        self,
        predictor: ProgressPredictor,
        options: TrainerConfig,
        solver: Solver,
        lr: float | None = None,
        lbfgs_max_iter: int | None = None,
        monitor: str = "train/loss",
    ) -> None:
        """Wrap ``predictor``.

        Args:
            predictor: the bank, initialised (supports placed, weights drawn).
            options: the trainer's options (solver tolerances, rate decay, console lines).
            solver: ``newton``, ``lbfgs`` or ``adam``.
            lr: Adam's learning rate (``adam`` only).
            lbfgs_max_iter: LBFGS iterations per epoch (``lbfgs`` only).
            monitor: the metric the rate decay follows (``val/loss`` or ``train/loss``).
        """
        super().__init__()
        self.predictor = predictor
        self.options = options
        self.solver = solver
        self.lr = lr
        self.lbfgs_max_iter = lbfgs_max_iter
        self.monitor = monitor
        self.automatic_optimization = solver != "newton"
        self.save_hyperparameters(
            {
                "predictor": predictor.kind,
                "predictor_options": to_builtin(dataclasses.asdict(predictor.config)),
                "n_nodes": predictor.n_nodes,
                "solver": solver,
                "lr": lr,
                "lbfgs_max_iter": lbfgs_max_iter,
                "monitor": monitor,
                "trainer": to_builtin(dataclasses.asdict(options)),
            }
        )
        self.history = FitHistory()
        self.newton_info: list[NewtonInfo] = []
        """Per-node outcome of the last Newton solve."""
        self._train: list[NodeData] = []
        self._val: list[NodeData] = []
        self._val_sums = HeldOutSums.zeros(0, "cpu")

    # ------------------------------------------------------------------------------ data
    def on_fit_start(self) -> None:
        """Move the data module's node data to the module's device, once per fit."""
        datamodule = self.trainer.datamodule
        self._train = nodes_to(datamodule.train, self.device)
        self._val = [] if datamodule.val is None else nodes_to(datamodule.val, self.device)

    # -------------------------------------------------------------------------- training
    def training_step(self, batch: NodeRows, batch_idx: int) -> torch.Tensor:
        """One optimisation step on ``batch`` (per node the rows it uses).

        Args:
            batch: per node the rows ``(b_i,)`` of its training data (all of them for Newton
                and LBFGS).
            batch_idx: the batch's index in the epoch.

        Returns:
            The batch's loss (Adam and LBFGS optimise it; Newton returns it for the record).
        """
        if self.solver == "newton":
            self.newton_info = self.predictor.solve_convex(
                self._train, self.options.solver_options()
            )
            with torch.no_grad():
                loss = self.predictor.training_loss(self._train)
            self._log_train_loss(loss, 1)
            return loss
        if self.solver == "lbfgs":
            return self.predictor.training_loss(self._train)
        full = self.trainer.datamodule.batch_size is None
        loss = self.predictor.training_loss(self._train, None if full else batch)
        self._log_train_loss(loss, 1 if full else sum(int(r.numel()) for r in batch))
        return loss

    def _log_train_loss(self, loss: torch.Tensor, weight: int) -> None:
        """Log ``train/loss`` for the epoch (the mean of its steps, weighted by ``weight``)."""
        self.log(
            "train/loss", loss.detach(), prog_bar=True, on_step=False, on_epoch=True,
            batch_size=weight,
        )  # fmt: skip

    def on_train_epoch_end(self) -> None:
        """Record the epoch (LBFGS: log the loss after the step) and write its console line."""
        if self.solver == "lbfgs":
            with torch.no_grad():
                self._log_train_loss(self.predictor.training_loss(self._train), 1)
        self.history.train_loss.append(float(self.trainer.callback_metrics["train/loss"]))
        if self.solver != "newton":
            self.history.lr.append(float(self.trainer.optimizers[0].param_groups[0]["lr"]))
        self._console_line()

    def _console_line(self) -> None:
        """Log one INFO line with the epoch's metrics, unless the progress bar shows them.

        Every ``log_every_n_epochs`` epochs, and after the first and the last one.
        """
        epoch, every = self.current_epoch + 1, self.options.log_every_n_epochs
        last = epoch == self.trainer.max_epochs
        if self.options.progress_bar or not (epoch == 1 or epoch % every == 0 or last):
            return
        h = self.history
        parts = [f"train/loss {h.train_loss[-1]:.6g}"]
        if len(h.val_mae) == epoch:
            parts += [f"val/loss {h.val_loss[-1]:.6g}", f"val/mae {h.val_mae[-1]:.4f}"]
        if h.lr:
            parts.append(f"lr {h.lr[-1]:.3g}")
        log.info(
            "%s epoch %d/%d: %s", self.predictor.kind, epoch, self.trainer.max_epochs,
            ", ".join(parts),
        )  # fmt: skip

    def configure_optimizers(self) -> OptimizerLRScheduler:
        """The optimiser of the solver, and for Adam with early stopping its rate decay.

        Returns:
            Newton: no optimiser (``[]``: the bank's Newton solve is the step, in manual
            optimisation); LBFGS: ``torch.optim.LBFGS`` (strong-Wolfe line search); Adam:
            ``torch.optim.Adam``, with early stopping on together with a
            ``ReduceLROnPlateau`` scheduler on :attr:`monitor` (logged as ``lr``).
        """
        if self.solver == "newton":
            return []
        params = [p for p in self.predictor.parameters() if p.requires_grad]
        o = self.options
        if self.solver == "lbfgs":
            return torch.optim.LBFGS(
                params,
                max_iter=self.lbfgs_max_iter,
                line_search_fn="strong_wolfe",
                tolerance_grad=o.lbfgs_tolerance_grad,
                tolerance_change=o.lbfgs_tolerance_change,
                history_size=o.lbfgs_history_size,
            )
        optimizer = torch.optim.Adam(params, lr=self.lr)
        if not o.early_stopping:
            return optimizer
        # torch's patience counts the epochs without improvement *before* the one that
        # lowers the rate; threshold in "abs" mode is EarlyStopping's min_delta
        scheduler = torch.optim.lr_scheduler.ReduceLROnPlateau(
            optimizer,
            mode="min",
            factor=o.lr_decay_factor,
            patience=o.lr_decay_patience - 1,
            threshold=o.early_stopping_min_delta,
            threshold_mode="abs",
        )
        return {
            "optimizer": optimizer,
            "lr_scheduler": {
                "scheduler": scheduler,
                "monitor": self.monitor,
                "interval": "epoch",
                "name": "lr",
            },
        }

    # ------------------------------------------------------------------------ validation
    def on_validation_epoch_start(self) -> None:
        """Start the epoch's sums."""
        self._val_sums = HeldOutSums.zeros(self.predictor.n_nodes, self.device)

    def validation_step(self, batch: NodeRows, batch_idx: int) -> None:
        """Add one batch of held-out rows to the epoch's sums.

        Args:
            batch: per node the rows ``(b_i,)`` of its validation data (possibly none).
            batch_idx: the batch's index.
        """
        self._val_sums.add(self.predictor, self._val, batch)

    def on_validation_epoch_end(self) -> None:
        """Log ``val/loss`` and ``val/mae`` of the epoch and record them."""
        val_loss = self._val_sums.loss()
        val_mae = self._val_sums.mae()
        self.log("val/loss", val_loss, on_epoch=True, batch_size=1)
        self.log("val/mae", val_mae, prog_bar=True, on_epoch=True, batch_size=1)
        self.history.val_loss.append(float(val_loss))
        self.history.val_mae.append(float(val_mae))
