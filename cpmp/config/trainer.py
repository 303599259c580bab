"""The options of the Lightning fit of the progress predictors (``conf/trainer/``).

Every solver tolerance, epoch default, early-stopping and learning-rate-decay setting is
written here once. The logger is not a trainer option: the jobs pick it from the ``logger``
group (``conf/logger/``) and :meth:`cpmp.sequencer.ConcurrentSequencer.fit` takes it as an
argument.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from cpmp.errors import ConfigError

SOLVERS = ("newton", "lbfgs")
"""Values of :attr:`TrainerConfig.solver`."""


@dataclass
class TrainerConfig:
    """Options of the Lightning trainer used for fitting.

    Attributes:
        max_epochs: optimiser epochs (Newton: each solves every node to ``newton_tol``;
            LBFGS: each runs up to the predictor's ``max_iter`` iterations; Adam: one pass
            over the training samples); ``None`` picks 1 for Newton (a second epoch finds
            nothing left to do), ``lbfgs_epochs`` for LBFGS and the predictor's ``epochs``
            for Adam. Adam fits may stop before it (see ``early_stopping``).
        progress_bar: show Lightning's progress bar (else one log line per epoch, see
            ``log_every_n_epochs``).
        log_every_n_epochs: without the progress bar, log the epoch's training loss and
            held-out progress MAE at INFO level every this many epochs, and always after the
            first and the last one (>= 1).
        log_dir: where a logger named by a string (``"csv"``, ``"tensorboard"``) writes
            (``None``: such a logger writes nothing; the jobs set it to their run directory).
        accelerator: Lightning's ``accelerator`` (``"auto"``: a GPU when there is one, else
            the CPU; ``"cpu"``, ``"gpu"``, ...). Results are brought back to the CPU.
        devices: Lightning's ``devices`` (``"auto"``, a count >= 1, or a list of device
            indices); the fit runs on one device (several make no sense for one full batch).
        batch_size: Adam steps on at most this many samples of every node at a time (a
            node's samples are shuffled each epoch, a small node's reused), ``None``: every
            sample in one step per epoch (full batch, the default). Convex solvers always
            take the full batch.
        val_fraction: when no validation demonstrations are given, hold out this fraction
            of the demonstrations (at least one, drawn with the fit's seed) as validation
            data, in [0, 1); ``0`` (default): no held-out split, every demonstration trains.
        lr: learning rate of every Adam-trained predictor (> 0; ``None``: the predictor's
            ``lr``).
        solver: ``"newton"`` (default) or ``"lbfgs"``: how convex weight fits are solved
            (``klr``, ``klr_full`` and ``klr_sparse``'s re-fit); Adam-trained parts ignore it.
        newton_tol: Newton stops per node when the max-norm of the loss gradient or the Newton
            decrement is at most this (> 0).
        newton_max_iter: Newton iterations per node at most (>= 1).
        lbfgs_epochs: LBFGS optimiser steps when ``max_epochs`` is ``None`` (>= 1).
        lbfgs_tolerance_grad: LBFGS stops a step when the gradient's max-norm is at most this
            (torch's ``tolerance_grad``, > 0).
        lbfgs_tolerance_change: LBFGS stops a step when the loss or the parameters change by
            at most this (torch's ``tolerance_change``, > 0).
        lbfgs_history_size: LBFGS memory: the number of past updates kept (>= 1).
        early_stopping: for Adam fits (``mlp``, ``klr_sparse``'s sparsity phase), lower the
            learning rate after ``lr_decay_patience`` epochs without improvement of the
            monitored loss (torch's ``ReduceLROnPlateau``, returned by the module's
            ``configure_optimizers``) and stop after ``early_stopping_patience`` such epochs
            (Lightning's ``EarlyStopping``). The monitored loss is ``val/loss`` when the fit
            has validation data, else ``train/loss``; an epoch improves on the best so far
            when it lowers it by more than ``early_stopping_min_delta``, for both rules.
            With the defaults a plateau lowers the rate twice (after 20 and 40 epochs) and
            stops the fit at the third (60). ``False`` runs every epoch of the budget at a
            constant rate. Convex solvers run their epochs regardless.
        early_stopping_patience: stop after this many epochs in a row without improvement
            (>= 1).
        early_stopping_min_delta: the decrease of the monitored loss (a sum over nodes of
            mean cross-entropies, so it grows with the node count) that counts as an
            improvement, absolute (>= 0).
        lr_decay_factor: the learning rate is multiplied by this on a plateau (0 < f < 1).
        lr_decay_patience: the rate drops after this many epochs in a row without
            improvement (>= 1; the count starts again after each drop).
    """

    max_epochs: int | None = None
    progress_bar: bool = False
    log_every_n_epochs: int = 1
    log_dir: str | None = None
    accelerator: str = "auto"
    devices: Any = "auto"
    batch_size: int | None = None
    val_fraction: float = 0.0
    lr: float | None = None
    solver: str = "newton"
    newton_tol: float = 1e-10
    newton_max_iter: int = 100
    lbfgs_epochs: int = 3
    lbfgs_tolerance_grad: float = 1e-9
    lbfgs_tolerance_change: float = 1e-12
    lbfgs_history_size: int = 50
    early_stopping: bool = True
    early_stopping_patience: int = 60
    early_stopping_min_delta: float = 1e-3
    lr_decay_factor: float = 0.1
    lr_decay_patience: int = 20

    def __post_init__(self) -> None:
        if self.solver not in SOLVERS:
            raise ConfigError(f"trainer solver must be 'newton' or 'lbfgs', got {self.solver!r}")
        for name in ("progress_bar", "early_stopping"):
            if not isinstance(getattr(self, name), bool):
                raise ConfigError(
                    f"trainer {name} must be true or false, got {getattr(self, name)!r}"
                )
        if not isinstance(self.accelerator, str) or not self.accelerator:
            raise ConfigError(
                f"trainer accelerator must be a name such as 'auto', 'cpu' or 'gpu', got "
                f"{self.accelerator!r}"
            )
        self.devices = _devices(self.devices)
        if self.max_epochs is not None:
            self.max_epochs = self._whole("max_epochs")
        if self.batch_size is not None:
            self.batch_size = self._whole("batch_size")
        self.log_every_n_epochs = self._whole("log_every_n_epochs")
        self.newton_max_iter = self._whole("newton_max_iter")
        self.lbfgs_epochs = self._whole("lbfgs_epochs")
        self.lbfgs_history_size = self._whole("lbfgs_history_size")
        self.early_stopping_patience = self._whole("early_stopping_patience")
        self.lr_decay_patience = self._whole("lr_decay_patience")
        factor = self._finite("lr_decay_factor", positive=True)
        if factor >= 1.0:
            raise ConfigError(
                f"trainer lr_decay_factor must be < 1 (it lowers the rate), got {factor!r}"
            )
        self.lr_decay_factor = factor
        fraction = self._finite("val_fraction", positive=False)
        if fraction >= 1.0:
            raise ConfigError(
                f"trainer val_fraction must be < 1 (some demonstrations must train), got "
                f"{fraction!r}"
            )
        self.val_fraction = fraction
        self.newton_tol = self._finite("newton_tol", positive=True)
        self.lbfgs_tolerance_grad = self._finite("lbfgs_tolerance_grad", positive=True)
        self.lbfgs_tolerance_change = self._finite("lbfgs_tolerance_change", positive=True)
        self.early_stopping_min_delta = self._finite("early_stopping_min_delta", positive=False)
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


@dataclass(frozen=True)
class SolverOptions:
    """How convex weight fits are solved (what a bank's ``solve_convex`` is told).

    Attributes:
        method: ``newton`` (:mod:`cpmp.predictors.newton`) or ``lbfgs`` (torch's LBFGS, strong
            Wolfe line search).
        tol: Newton stops when the gradient's max-norm or the Newton decrement
            ``λ = sqrt(gᵀ H⁻¹ g)`` is at most ``tol``.
        max_iter: Newton iterations per node at most.
    """

    method: str = "newton"
    tol: float = TrainerConfig.newton_tol
    max_iter: int = TrainerConfig.newton_max_iter


def _devices(value: object) -> int | str | list[int]:
    """``devices`` checked: ``"auto"``, a count >= 1 (``-1``: all), or a list of indices >= 0.

    Raises:
        ConfigError: any other value.
    """
    if value == "auto":
        return "auto"
    if isinstance(value, (list, tuple)) and value:
        if all(isinstance(v, int) and not isinstance(v, bool) and v >= 0 for v in value):
            return [int(v) for v in value]
    elif isinstance(value, (int, float)) and not isinstance(value, bool):
        if math.isfinite(value) and value == int(value) and (value >= 1 or value == -1):
            return int(value)
    raise ConfigError(
        "trainer devices must be 'auto', a count >= 1 (-1: all) or a list of device indices, "
        f"got {value!r}"
    )
