"""Fitting a sequencer: the learned one or a baseline (``goal_nearest``, ``bc``).

The learned sequencer fits a progress predictor per node in one Lightning fit; the jobs give
it the held-out demonstrations as validation data and the logger of the ``logger`` group
(``conf/logger/``: any Lightning logger by ``_target_``), built here per fit.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from hydra.errors import InstantiationException
from hydra.utils import instantiate

from cpmp.baselines.bc import BCSequencer
from cpmp.baselines.goal_nearest import GoalNearestSequencer
from cpmp.data.demonstration import Demonstration
from cpmp.errors import ConfigError
from cpmp.experiment.config import fit_settings
from cpmp.experiment.settings import ConfigNode, FitSettings
from cpmp.records import JsonValue
from cpmp.sequencer.sequencer import ConcurrentSequencer

if TYPE_CHECKING:
    from lightning.pytorch.loggers import Logger


def make_logger(spec: Mapping[str, JsonValue] | None, log_dir: str | Path | None) -> Logger | None:
    """The Lightning logger a ``logger`` group entry describes, writing into ``log_dir``.

    Args:
        spec: ``_target_`` (the logger's class, e.g.
            ``lightning.pytorch.loggers.CSVLogger``) and its arguments; ``None``: no logger.
        log_dir: the fit's log folder, passed as ``save_dir`` unless ``spec`` sets one;
            ``None``: no logger.

    Returns:
        The logger (``hydra.utils.instantiate``), or ``None``.

    Raises:
        ConfigError: the logger cannot be built (unknown class, bad argument, or not a
            Lightning ``Logger``).
    """
    if spec is None or log_dir is None:
        return None
    from lightning.pytorch.loggers import Logger  # lazy: Lightning (seconds) for a fit only

    target = spec.get("_target_")
    kwargs = {} if "save_dir" in spec else {"save_dir": str(log_dir)}
    try:
        logger = instantiate(dict(spec), **kwargs)
    except InstantiationException as err:
        raise ConfigError(f"logger {target}: {err}") from err
    if not isinstance(logger, Logger):
        raise ConfigError(f"logger {target} is not a Lightning Logger (logger._target_)")
    return logger


def train_sequencer(
    demos: Sequence[Demonstration],
    settings: FitSettings,
    seed: int = 0,
    log_dir: str | Path | None = None,
    validation: Sequence[Demonstration] | None = None,
) -> ConcurrentSequencer | GoalNearestSequencer | BCSequencer:
    """Fit the sequencer ``settings`` describe on ``demos`` with ``seed``.

    Args:
        demos: the training demonstrations.
        settings: the job's typed ``predictor``, ``sequencer``, ``trainer`` and ``logger``
            groups.
        seed: the fit's seed.
        log_dir: where the fit's logger writes (``None``: no logging).
        validation: held-out demonstrations, whose progress MAE each epoch logs
            (``None``: the trainer's ``val_fraction`` of ``demos``, none by default).

    Returns:
        A :class:`~cpmp.sequencer.ConcurrentSequencer`, or the
        :class:`~cpmp.baselines.GoalNearestSequencer` or :class:`~cpmp.baselines.BCSequencer`
        baseline (no predictor, no trainer).
    """
    if settings.goal_nearest is not None:
        options = dataclasses.asdict(settings.goal_nearest)
        return GoalNearestSequencer.fit(list(demos), seed=seed, **options)
    if settings.bc is not None:
        return BCSequencer.fit(list(demos), seed=seed, **dataclasses.asdict(settings.bc))
    fit = settings.fit
    trainer = fit.trainer
    if log_dir is not None:
        trainer = dataclasses.replace(trainer, log_dir=str(log_dir))
    config = dataclasses.replace(fit, trainer=trainer, seed=seed)
    logger = make_logger(settings.logger, log_dir)
    return ConcurrentSequencer.fit_config(list(demos), config, validation=validation, logger=logger)


def fit_sequencer(
    demos: Sequence[Demonstration],
    predictor_cfg: ConfigNode,
    sequencer_cfg: ConfigNode = None,
    trainer_cfg: ConfigNode = None,
    seed: int = 0,
    log_dir: str | Path | None = None,
) -> ConcurrentSequencer | GoalNearestSequencer | BCSequencer:
    """:func:`train_sequencer` from config groups, without a logger.

    Args:
        demos: the training demonstrations.
        predictor_cfg: the ``predictor`` group (a node or a mapping).
        sequencer_cfg: the ``sequencer`` group (``None``: the defaults).
        trainer_cfg: the ``trainer`` group (``None``: the defaults).
        seed: the fit's seed.
        log_dir: the trainer's ``log_dir``.

    Returns:
        The fitted sequencer (see :func:`train_sequencer`).
    """
    settings = fit_settings(predictor_cfg, sequencer_cfg, trainer_cfg)
    return train_sequencer(demos, settings, seed, log_dir)
