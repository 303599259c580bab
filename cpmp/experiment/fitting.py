"""Fitting a sequencer: the learned one (a progress predictor per node, Lightning) or the
``goal_nearest`` baseline, from typed settings or from config groups.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from cpmp.experiment.config import fit_settings
from cpmp.experiment.settings import FitSettings

if TYPE_CHECKING:
    from cpmp.data.demonstration import Demonstration


def train_sequencer(
    demos: Sequence[Demonstration],
    settings: FitSettings,
    seed: int = 0,
    log_dir: str | Path | None = None,
) -> Any:
    """Fit the sequencer ``settings`` describe on ``demos`` with ``seed`` (Lightning logs into
    ``log_dir`` when set): a :class:`~cpmp.sequencer.ConcurrentSequencer`, or the
    :class:`~cpmp.baselines.GoalNearestSequencer` baseline (no predictor, no trainer).
    """
    if settings.goal_nearest is not None:
        from cpmp.baselines.goal_nearest import GoalNearestSequencer

        options = dataclasses.asdict(settings.goal_nearest)
        return GoalNearestSequencer.fit(list(demos), seed=seed, **options)
    from cpmp.sequencer.sequencer import ConcurrentSequencer

    fit = settings.fit
    trainer = fit.trainer
    if log_dir is not None:
        trainer = dataclasses.replace(trainer, log_dir=str(log_dir))
    config = dataclasses.replace(fit, trainer=trainer, seed=seed)
    return ConcurrentSequencer.fit_config(list(demos), config)


def fit_sequencer(
    demos: Sequence[Demonstration],
    predictor_cfg: Any,
    sequencer_cfg: Any = None,
    trainer_cfg: Any = None,
    seed: int = 0,
    log_dir: str | Path | None = None,
) -> Any:
    """:func:`train_sequencer` from config groups (``predictor``, ``sequencer``, ``trainer``:
    nodes or mappings), converted by :func:`~cpmp.experiment.config.fit_settings`.
    """
    settings = fit_settings(predictor_cfg, sequencer_cfg, trainer_cfg)
    return train_sequencer(demos, settings, seed, log_dir)
