"""The fit of a sequencer: graphs, a progress predictor trained in Lightning, what the fit found.

:func:`fit_parts` is everything :meth:`cpmp.sequencer.ConcurrentSequencer.fit_config` learns
before the sequencer itself is built: label glitches repaired, the training / validation split,
the sequence graphs, the ambient features (left out of eq. 1's paths:
:func:`~cpmp.sequencer.fit_data.node_training_data`), the predictor bank fitted
(:func:`cpmp.predictors.training.fit_predictor`), the checks and warnings, the demonstrated
starts, the coupling and the features' ranges.

This is the only module of :mod:`cpmp.sequencer` that imports the training stack (Lightning):
``fit_config`` imports it when it is called, so that loading a checkpoint and stepping it
(inference, the simulator, the recordings) never pay for Lightning.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from lightning.pytorch.loggers import Logger

from cpmp.config import FitConfig, resolved_dtype
from cpmp.data import Demonstration
from cpmp.errors import DataError
from cpmp.graph import SequenceGraph, build_graphs
from cpmp.predictors import PREDICTORS, ProgressPredictor
from cpmp.predictors.datamodule import held_out_split
from cpmp.predictors.training import check_logger, fit_predictor
from cpmp.records import FitReport
from cpmp.sequencer.fit_data import (
    demo_progress,
    fit_warnings,
    glitch_warnings,
    initial_combinations,
    node_training_data,
    node_validation_data,
    nonfinite_parameters,
)
from cpmp.sequencer.glitches import LabelGlitch, repair_glitches
from cpmp.sequencer.inputs import checked_demonstrations
from cpmp.sequencer.motion import ambient_features, motion_data
from cpmp.sequencer.switching import Coupling, indicator_features

__all__ = ["FitDemos", "FittedParts", "fit_demos", "fit_parts"]


@dataclass(frozen=True)
class FitDemos:
    """The demonstrations a fit trains on and those it validates on.

    Attributes:
        train: the training demonstrations.
        validation: the validation demonstrations (``None``: the fit is not validated).
    """

    train: list[Demonstration]
    validation: list[Demonstration] | None


def fit_demos(
    demos: Sequence[Demonstration],
    validation: Sequence[Demonstration] | None,
    val_fraction: float,
    seed: int,
) -> FitDemos:
    """Split a fit's demonstrations into training and validation ones.

    Args:
        demos: the (checked) training demonstrations.
        validation: demonstrations given for validation (checked here: their features must
            be the training ones), or ``None``.
        val_fraction: without ``validation``, the share of ``demos`` held out for it
            (:func:`cpmp.predictors.datamodule.held_out_split`, drawn with ``seed``); ``0``:
            none.
        seed: the fit's seed.

    Returns:
        The training and the validation demonstrations.

    Raises:
        DataError: validation demonstrations with other features than the training ones.
    """
    demos = list(demos)
    if validation is not None:
        val, names = checked_demonstrations(validation, "validation of ConcurrentSequencer.fit")
        if names != list(demos[0].feature_names):
            raise DataError(
                f"the validation demonstrations have features {names[:4]}... but the training "
                f"ones {list(demos[0].feature_names)[:4]}...; they must match"
            )
        return FitDemos(demos, val)
    if val_fraction <= 0.0:
        return FitDemos(demos, None)
    split = held_out_split(len(demos), val_fraction, seed)
    return FitDemos([demos[i] for i in split.train], [demos[i] for i in split.val])


@dataclass(frozen=True)
class FittedParts:
    """What a fit learned, before the sequencer is built around it.

    Attributes:
        graphs: variable -> its sequence graph.
        predictor: the fitted predictor bank (training mode; the sequencer puts it in eval).
        feature_names: the ``d`` feature names.
        summary: the fit's report (loss, timings, the predictor's own facts, ``n_demos``,
            ``label_glitches``, ``warnings``; the stay choices and entry factors are added
            when the sequencer is built).
        glitches: the label glitches repaired before the graphs were built.
        initial_combinations: the initial MP per variable of each training demonstration
            (distinct).
        coupling: the learned contexts of the demonstrated switches.
        feature_range: ``(d,)`` range of each feature over the training samples (0 for
            indicator features).
        demos: the training demonstrations (glitches repaired, validation ones taken out).
    """

    graphs: dict[str, SequenceGraph]
    predictor: ProgressPredictor
    feature_names: list[str]
    summary: FitReport
    glitches: list[LabelGlitch]
    initial_combinations: list[dict[str, str]]
    coupling: Coupling
    feature_range: np.ndarray
    demos: list[Demonstration]


def fit_parts(
    demos: Sequence[Demonstration],
    config: FitConfig,
    validation: Sequence[Demonstration] | None = None,
    logger: Logger | str | None = None,
) -> FittedParts:
    """Build the sequence graphs and fit every node's progress predictor as ``config`` says.

    Args:
        demos: labelled demonstrations sharing feature names and control variables.
        config: predictor, rule, trainer and seed.
        validation: the fit's held-out demonstrations (``None``: the trainer's
            ``val_fraction`` of ``demos``).
        logger: a Lightning ``Logger``, ``"csv"``, ``"tensorboard"`` or ``None``.

    Returns:
        The graphs, the fitted predictor and what the sequencer is built with.

    Raises:
        DataError: bad demonstrations, or a fit with non-finite parameters.
        ConfigError: a bad option or logger.
    """
    predictor = config.predictor
    demos, feature_names = checked_demonstrations(demos, "ConcurrentSequencer.fit")
    check_logger(logger, config.trainer.log_dir)
    glitches: list[LabelGlitch] = []
    if config.repair_glitches:
        demos, glitches = repair_glitches(demos, config.variables)
    split = fit_demos(demos, validation, config.trainer.val_fraction, config.seed)
    demos = split.train
    graphs = build_graphs(demos, config.variables)
    node_keys = [(v, mp) for v in sorted(graphs) for mp in graphs[v].ordered_nodes()]
    all_x = np.concatenate([d.features for d in demos], axis=0)
    options = config.predictor_config
    dtype = resolved_dtype(options.dtype, len(all_x))
    if dtype != options.dtype:
        options = dataclasses.replace(options, dtype=dtype)
    model = PREDICTORS[predictor](node_keys, len(feature_names), options)
    model.scaler.fit(all_x, model.config.feature_scaling)
    motion = motion_data(demos)
    ambient = ambient_features(motion, sorted(graphs), len(feature_names))
    data = node_training_data(graphs, model, config.subsample, ambient)
    val = None
    if split.validation is not None:
        val = node_validation_data(graphs, model, split.validation)
    summary = fit_predictor(model, data, config.trainer, config.seed, val, logger)
    bad = nonfinite_parameters(model)
    if bad:
        raise DataError(
            f"the {predictor} fit produced non-finite parameters ({', '.join(bad)}); "
            "check the feature magnitudes and the options gamma / l2 / lr"
        )
    summary = dataclasses.replace(
        summary,
        n_demos=len(demos),
        label_glitches=tuple(g.to_dict() for g in glitches),
        warnings=tuple(glitch_warnings(graphs, demos) + fit_warnings(model, data)),
    )
    progress = demo_progress(graphs, data, [d.n_samples for d in demos])
    feature_range = np.where(indicator_features(all_x), 0.0, np.ptp(all_x, axis=0))
    return FittedParts(
        graphs=graphs,
        predictor=model,
        feature_names=feature_names,
        summary=summary,
        glitches=glitches,
        initial_combinations=initial_combinations(demos, sorted(graphs)),
        coupling=Coupling.learn(
            demos,
            sorted(graphs),
            progress=progress,
            feature_range=feature_range,
            motion=motion,
            ambient=ambient,
        ),
        feature_range=feature_range,
        demos=demos,
    )
