"""The options of the Lightning fit of the progress predictors (``conf/trainer/``); every
solver tolerance and epoch default is written here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from cpmp.errors import ConfigError

LOGGERS = ("csv", "tensorboard")
"""Values of :attr:`TrainerConfig.logger` besides ``None``."""
SOLVERS = ("newton", "lbfgs")
"""Values of :attr:`TrainerConfig.solver`."""


@dataclass
class TrainerConfig:
    """Options of the Lightning trainer used for fitting (full batch, CPU).

    Attributes:
        max_epochs: full-batch optimiser steps (Newton: each solves every node to ``newton_tol``;
            LBFGS: each runs up to the predictor's ``max_iter`` iterations; Adam: one step);
            ``None`` picks 1 for Newton (a second step finds nothing left to do),
            ``lbfgs_epochs`` for LBFGS and the predictor's ``epochs`` for Adam. Adam fits may
            stop before it (see ``early_stopping``).
        progress_bar: show Lightning's progress bar.
        logger: ``"csv"``, ``"tensorboard"`` or ``None`` (no logging).
        log_dir: where the logger writes (``None``: no logger; the jobs set it to their run
            directory).
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
        early_stopping: lower the rate of an Adam fit (``mlp``, ``klr_sparse``'s sparsity
            phase) when the training loss stops improving, and stop it at the last such
            plateau (see :class:`cpmp.predictors.training.LossPlateau`); ``False`` runs every epoch
            of the budget. Convex solvers run their epochs regardless.
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
    newton_tol: float = 1e-10
    newton_max_iter: int = 100
    lbfgs_epochs: int = 3
    lbfgs_tolerance_grad: float = 1e-9
    lbfgs_tolerance_change: float = 1e-12
    lbfgs_history_size: int = 50
    early_stopping: bool = True
    early_stopping_tol: float = 1e-4
    early_stopping_patience: int = 20
    early_stopping_decays: int = 2
    early_stopping_lr_factor: float = 0.1

    def __post_init__(self) -> None:
        if self.logger is not None and self.logger not in LOGGERS:
            raise ConfigError(
                f"trainer logger must be 'csv', 'tensorboard' or null, got {self.logger!r}"
            )
        if self.solver not in SOLVERS:
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
        self.lbfgs_history_size = self._whole("lbfgs_history_size")
        self.early_stopping_patience = self._whole("early_stopping_patience")
        self.early_stopping_decays = self._whole("early_stopping_decays", minimum=0)
        factor = self._finite("early_stopping_lr_factor", positive=True)
        if factor >= 1.0:
            raise ConfigError(
                f"trainer early_stopping_lr_factor must be < 1 (it lowers the rate), got {factor!r}"
            )
        self.early_stopping_lr_factor = factor
        self.newton_tol = self._finite("newton_tol", positive=True)
        self.lbfgs_tolerance_grad = self._finite("lbfgs_tolerance_grad", positive=True)
        self.lbfgs_tolerance_change = self._finite("lbfgs_tolerance_change", positive=True)
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
