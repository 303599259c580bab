"""The Hydra side of cpmp's one config schema: registration and conversion.

**Registration** (:func:`register_configs`, run on import): the option dataclasses of
:mod:`cpmp.config` (and :class:`~cpmp.experiment.settings.ExperimentSettings`,
:class:`~cpmp.compare.settings.CompareSettings`) are stored in Hydra's ConfigStore
as ``schema_task``, ``schema_trainer``, ``schema_sequencer``, ``schema_experiment``,
``schema_compare``, ``schema_sequencer_goal_nearest`` (the baseline's options and its ``kind``)
and one ``schema_predictor_<kind>`` per predictor kind (its options and ``kind``). Each option
of ``conf/`` starts from one of them (``defaults: [/schema_..., _self_]``) and holds only what
differs from the dataclass's defaults; the dataclass's docstring says what each option means.
Hydra then checks the type of every override against the schema.

**Conversion** (:func:`fit_settings`, :func:`experiment_job`): a job turns its composed
``cfg`` into the typed configs of :mod:`cpmp.experiment.settings` once, at its start; those
validate themselves (``__post_init__``) and are what the stages and
:meth:`~cpmp.sequencer.ConcurrentSequencer.fit_config` take.

Importing this module costs Hydra and OmegaConf only (no torch, Lightning or MuJoCo): the
command line is checked before those are loaded (:mod:`cpmp.cli.checks`).
"""

from __future__ import annotations

import dataclasses
import typing
from collections.abc import Mapping
from dataclasses import field
from typing import Any

from cpmp.compare.settings import CompareSettings
from cpmp.config import (
    PREDICTOR_CONFIGS,
    FitConfig,
    GoalNearestConfig,
    PredictorConfig,
    SequencerConfig,
    TaskConfig,
    TrainerConfig,
    goal_nearest_options,
    predictor_config,
)
from cpmp.config.goal_nearest import KIND as GOAL_NEAREST
from cpmp.errors import ConfigError
from cpmp.experiment.settings import ExperimentJob, ExperimentSettings, FitSettings


# ----------------------------------------------------------------------------- registration
def _schema(cls: type, **first: Any) -> type:
    """A plain dataclass with the fields (types, defaults) of ``cls``, after the fields
    ``first`` (name -> default string), as Hydra's schema of ``cls``: no validation of its own
    (``cls`` validates at the job boundary) and never frozen (Hydra merges into it).
    """
    hints = typing.get_type_hints(cls)
    fields: list[tuple[str, Any, Any]] = [(k, str, field(default=v)) for k, v in first.items()]
    for f in dataclasses.fields(cls):
        if f.default_factory is not dataclasses.MISSING:
            default = field(default_factory=f.default_factory)
        else:
            default = field(default=f.default)
        fields.append((f.name, hints[f.name], default))
    return dataclasses.make_dataclass(cls.__name__, fields)


def register_configs() -> None:
    """Store the schema of every config group in Hydra's ConfigStore (idempotent)."""
    from hydra.core.config_store import ConfigStore

    store = ConfigStore.instance()
    for name, cls in (
        ("schema_task", TaskConfig),
        ("schema_trainer", TrainerConfig),
        ("schema_sequencer", SequencerConfig),
        ("schema_experiment", ExperimentSettings),
        ("schema_compare", CompareSettings),
    ):
        store.store(name=name, node=_schema(cls))
    store.store(
        name=f"schema_sequencer_{GOAL_NEAREST}", node=_schema(GoalNearestConfig, kind=GOAL_NEAREST)
    )
    for kind, cls in PREDICTOR_CONFIGS.items():
        store.store(name=f"schema_predictor_{kind}", node=_schema(cls, kind=kind))


# ------------------------------------------------------------------------------- conversion
def to_dict(cfg: Any) -> dict[str, Any]:
    """A plain dict from an OmegaConf node or mapping (``None`` -> ``{}``)."""
    if cfg is None:
        return {}
    from omegaconf import DictConfig, OmegaConf

    if isinstance(cfg, DictConfig):
        return OmegaConf.to_container(cfg, resolve=True)  # type: ignore[return-value]
    if isinstance(cfg, Mapping):
        return dict(cfg)
    raise ConfigError(f"expected a mapping of options, got {type(cfg).__name__}")


def predictor_from_cfg(cfg: Any) -> tuple[str, PredictorConfig]:
    """``(kind, options)`` of a ``predictor`` group entry (``kind`` plus the kind's options),
    validated.
    """
    options = to_dict(cfg)
    kind = options.pop("kind", None)
    if kind not in PREDICTOR_CONFIGS:
        raise ConfigError(
            f"predictor.kind must be one of {', '.join(PREDICTOR_CONFIGS)}, got {kind!r} "
            f"(choose with predictor=<name>)"
        )
    return kind, predictor_config(kind, **options)


def predictor_options(cfg: Any) -> tuple[str, dict[str, Any]]:
    """``(kind, options)`` of a ``predictor`` group entry as a dict of every option, validated
    (:func:`predictor_from_cfg`).
    """
    kind, config = predictor_from_cfg(cfg)
    return kind, dataclasses.asdict(config)


def fit_settings(
    predictor_cfg: Any, sequencer_cfg: Any = None, trainer_cfg: Any = None, logger_cfg: Any = None
) -> FitSettings:
    """Typed :class:`FitSettings` from the ``predictor``, ``sequencer``, ``trainer`` groups.

    The groups are nodes or mappings (``None``: the defaults), validated; the ``goal_nearest``
    baseline needs no ``predictor``. A set ``trainer.lr`` replaces the ``lr`` of a predictor
    that has one (the Adam-trained ones), so that the saved model says which rate it was
    trained with. ``logger_cfg`` (the ``logger`` group) is checked by :func:`logger_spec`.
    """
    sequencer = to_dict(sequencer_cfg)
    goal_nearest = None
    if sequencer.get("kind") is not None:
        if sequencer.pop("kind") != GOAL_NEAREST:
            raise ConfigError(
                f"sequencer.kind must be {GOAL_NEAREST!r} or absent (the learned sequencer)"
            )
        goal_nearest = goal_nearest_options(sequencer)
        sequencer = {}
    if goal_nearest is not None and not to_dict(predictor_cfg):
        kind, predictor = FitConfig.predictor, None  # the baseline uses no predictor
    else:
        kind, predictor = predictor_from_cfg(predictor_cfg)
    trainer_options = to_dict(trainer_cfg)
    try:
        rule = SequencerConfig(**sequencer)
        trainer = TrainerConfig(**trainer_options)
    except TypeError as err:
        raise ConfigError(f"bad sequencer/trainer option: {err}") from err
    if trainer.lr is not None and hasattr(predictor, "lr"):
        predictor = dataclasses.replace(predictor, lr=trainer.lr)
    return FitSettings(
        FitConfig(kind, predictor, rule, trainer), goal_nearest, logger_spec(logger_cfg)
    )


def logger_spec(cfg: Any) -> dict[str, Any] | None:
    """The ``logger`` group as a plain mapping, or ``None`` for no logger.

    Args:
        cfg: the group's node or mapping: a Lightning logger's ``_target_`` and arguments
            (``conf/logger/csv.yaml``, ``tensorboard.yaml``, or any logger a user names);
            ``None`` or empty (``conf/logger/none.yaml``): no logger.

    Raises:
        ConfigError: options without a ``_target_`` naming the logger's class.
    """
    spec = to_dict(cfg)
    if not spec:
        return None
    target = spec.get("_target_")
    if not isinstance(target, str) or not target:
        raise ConfigError(
            "logger needs _target_: the class of a Lightning logger (e.g. "
            "lightning.pytorch.loggers.CSVLogger); choose logger=csv, tensorboard or none"
        )
    return spec


def job_fit_settings(cfg: Any) -> FitSettings:
    """:func:`fit_settings` of a job's composed config."""
    return fit_settings(
        cfg.predictor, cfg.get("sequencer"), cfg.get("trainer"), cfg.get("logger")
    )


def validate_common(cfg: Any) -> tuple[str, dict[str, Any]]:
    """Check the predictor, sequencer and trainer groups of a composed config
    (:func:`job_fit_settings`); returns the predictor's kind and all its options.
    """
    settings = job_fit_settings(cfg)
    return settings.predictor, dataclasses.asdict(settings.fit.predictor_config)


def experiment_job(cfg: Any) -> ExperimentJob:
    """The main job's composed config as an :class:`ExperimentJob` (an :class:`ExperimentJob`
    is returned as it is); every group validated, the settings first.
    """
    if isinstance(cfg, ExperimentJob):
        return cfg
    settings = ExperimentSettings.from_cfg(cfg.experiment)
    fit = job_fit_settings(cfg)
    return ExperimentJob(settings, TaskConfig.from_dict(cfg.task), fit)


register_configs()
