"""The Hydra side of cpmp's one config schema: registration and conversion.

**Registration** (:func:`register_configs`, run on import): the option dataclasses of
:mod:`cpmp.config` (and :class:`~cpmp.experiment.settings.ExperimentSettings`) are stored in
Hydra's ConfigStore as ``schema_task``, ``schema_trainer``, ``schema_sequencer``,
``schema_experiment``, ``schema_executor``, ``schema_sequencer_goal_nearest`` and
``schema_sequencer_bc`` (each baseline's options and its ``kind``) and one
``schema_predictor_<kind>`` per predictor kind (its options and ``kind``);
:func:`store_schema` stores one more (the comparison registers ``schema_compare`` with it,
:mod:`cpmp.compare.settings`). Each option of ``conf/`` starts from one of them
(``defaults: [/schema_..., _self_]``) and holds only what differs from the dataclass's
defaults; the dataclass's docstring says what each option means. Hydra then checks the type of
every override against the schema.

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
from dataclasses import field
from typing import Literal, NamedTuple

from hydra.core.config_store import ConfigStore
from omegaconf import DictConfig

from cpmp.config import (
    PREDICTOR_CONFIGS,
    BCConfig,
    FitConfig,
    GoalNearestConfig,
    PredictorConfig,
    SequencerConfig,
    TaskConfig,
    TrainerConfig,
    bc_options,
    goal_nearest_options,
    predictor_config,
)
from cpmp.config.bc import KIND as BC
from cpmp.config.goal_nearest import KIND as GOAL_NEAREST
from cpmp.errors import ConfigError
from cpmp.experiment.settings import (
    ConfigNode,
    ExecutorSettings,
    ExperimentJob,
    ExperimentSettings,
    FitSettings,
    to_dict,
)
from cpmp.records import JsonValue

__all__ = [
    "PredictorChoice",
    "PredictorOptions",
    "executor_settings",
    "experiment_job",
    "fit_settings",
    "is_stored",
    "job_fit_settings",
    "logger_spec",
    "predictor_from_cfg",
    "predictor_options",
    "register_configs",
    "schema_of",
    "store_schema",
    "to_dict",
    "validate_common",
]


# ----------------------------------------------------------------------------- registration
def schema_of(cls: type, **first: str) -> type:
    """Hydra's schema of the dataclass ``cls``: a plain dataclass with the same fields.

    The fields ``first`` (name -> default string) come first. The schema has no validation of
    its own (``cls`` validates at the job boundary) and is never frozen (Hydra merges into
    it). A field typed with a ``Literal`` of strings
    (:data:`~cpmp.experiment.settings.RecordMode`) is a string in the schema (OmegaConf has no
    ``Literal``): ``cls`` checks the value.

    Args:
        cls: a dataclass of options.
        **first: extra string fields put before ``cls``'s, with their defaults.

    Returns:
        The schema dataclass, named as ``cls``.
    """
    hints = typing.get_type_hints(cls)
    fields: list[tuple[str, object, object]] = [
        (k, str, field(default=v)) for k, v in first.items()
    ]
    for f in dataclasses.fields(cls):
        hint = hints[f.name]
        if typing.get_origin(hint) is Literal:
            hint = str
        if f.default_factory is not dataclasses.MISSING:
            default = field(default_factory=f.default_factory)
        else:
            default = field(default=f.default)
        fields.append((f.name, hint, default))
    return dataclasses.make_dataclass(cls.__name__, fields)


def store_schema(name: str, cls: type, **first: str) -> None:
    """Store :func:`schema_of` ``(cls, **first)`` in Hydra's ConfigStore as ``name``."""
    ConfigStore.instance().store(name=name, node=schema_of(cls, **first))


def is_stored(name: str) -> bool:
    """Whether Hydra's ConfigStore holds a top-level config ``name`` (a schema)."""
    return f"{name}.yaml" in ConfigStore.instance().repo


def _schemas() -> list[tuple[str, type, dict[str, str]]]:
    """Every schema of the main job's config groups: ``(name, dataclass, first fields)``."""
    schemas: list[tuple[str, type, dict[str, str]]] = [
        ("schema_task", TaskConfig, {}),
        ("schema_trainer", TrainerConfig, {}),
        ("schema_sequencer", SequencerConfig, {}),
        ("schema_experiment", ExperimentSettings, {}),
        ("schema_executor", ExecutorSettings, {}),
        (f"schema_sequencer_{GOAL_NEAREST}", GoalNearestConfig, {"kind": GOAL_NEAREST}),
        (f"schema_sequencer_{BC}", BCConfig, {"kind": BC}),
    ]
    schemas += [
        (f"schema_predictor_{kind}", cls, {"kind": kind}) for kind, cls in PREDICTOR_CONFIGS.items()
    ]
    return schemas


def register_configs(*, missing_only: bool = False) -> None:
    """Store the schema of every config group of the main job in Hydra's ConfigStore.

    Idempotent: storing a schema again replaces it with the same one. Run on this module's
    import; storing the schemas costs a structured config each (seconds in all on a busy
    machine), so a caller that only needs them present (:func:`cpmp.cli.compose.compose_config`,
    in case Hydra's ConfigStore was cleared) passes ``missing_only``.

    Args:
        missing_only: store only the schemas the ConfigStore lacks (none after this module's
            import: then nothing is built).
    """
    for name, cls, first in _schemas():
        if not (missing_only and is_stored(name)):
            store_schema(name, cls, **first)


# ------------------------------------------------------------------------------- conversion
class PredictorChoice(NamedTuple):
    """A ``predictor`` group entry, validated: its kind and typed options."""

    kind: str
    """The predictor kind (a key of :data:`~cpmp.config.PREDICTOR_CONFIGS`)."""
    config: PredictorConfig
    """The kind's options."""


class PredictorOptions(NamedTuple):
    """A ``predictor`` group entry, validated: its kind and every option as a dict."""

    kind: str
    """The predictor kind."""
    options: dict[str, object]
    """Every option of the kind (defaults filled in; numbers, strings, tuples)."""


def predictor_from_cfg(cfg: ConfigNode) -> PredictorChoice:
    """The kind and typed options of a ``predictor`` group entry (``kind`` plus its options).

    Raises:
        ConfigError: an unknown kind or a bad option.
    """
    options = to_dict(cfg)
    kind = options.pop("kind", None)
    if kind not in PREDICTOR_CONFIGS:
        raise ConfigError(
            f"predictor.kind must be one of {', '.join(PREDICTOR_CONFIGS)}, got {kind!r} "
            f"(choose with predictor=<name>)"
        )
    return PredictorChoice(kind, predictor_config(kind, **options))


def predictor_options(cfg: ConfigNode) -> PredictorOptions:
    """The kind and every option of a ``predictor`` group entry, validated.

    Raises:
        ConfigError: as :func:`predictor_from_cfg`.
    """
    kind, config = predictor_from_cfg(cfg)
    return PredictorOptions(kind, dataclasses.asdict(config))


def fit_settings(
    predictor_cfg: ConfigNode,
    sequencer_cfg: ConfigNode = None,
    trainer_cfg: ConfigNode = None,
    logger_cfg: ConfigNode = None,
) -> FitSettings:
    """Typed :class:`FitSettings` from the ``predictor``, ``sequencer``, ``trainer`` groups.

    The groups are nodes or mappings (``None``: the defaults), validated; the ``goal_nearest``
    and ``bc`` baselines need no ``predictor``. A set ``trainer.lr`` replaces the ``lr`` of a
    predictor that has one (the Adam-trained ones), so that the saved model says which rate it was
    trained with. ``logger_cfg`` (the ``logger`` group) is checked by :func:`logger_spec`.

    Raises:
        ConfigError: a bad option of any group.
    """
    sequencer = to_dict(sequencer_cfg)
    goal_nearest = bc = None
    if sequencer.get("kind") is not None:
        baseline = sequencer.pop("kind")
        if baseline == GOAL_NEAREST:
            goal_nearest = goal_nearest_options(sequencer)
        elif baseline == BC:
            bc = bc_options(sequencer)
        else:
            raise ConfigError(
                f"sequencer.kind must be {GOAL_NEAREST!r}, {BC!r} or absent (the learned "
                f"sequencer), got {baseline!r}"
            )
        sequencer = {}
    if (goal_nearest is not None or bc is not None) and not to_dict(predictor_cfg):
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
        FitConfig(kind, predictor, rule, trainer), goal_nearest, logger_spec(logger_cfg), bc
    )


def logger_spec(cfg: ConfigNode) -> dict[str, JsonValue] | None:
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


def job_fit_settings(cfg: DictConfig) -> FitSettings:
    """:func:`fit_settings` of a job's composed config."""
    return fit_settings(cfg.predictor, cfg.get("sequencer"), cfg.get("trainer"), cfg.get("logger"))


def validate_common(cfg: DictConfig) -> PredictorOptions:
    """Check the predictor, sequencer and trainer groups of a composed config.

    Returns:
        The predictor's kind and all its options (:func:`job_fit_settings`).
    """
    settings = job_fit_settings(cfg)
    return PredictorOptions(settings.predictor, dataclasses.asdict(settings.fit.predictor_config))


def executor_settings(settings: ExperimentSettings, cfg: ConfigNode) -> ExecutorSettings:
    """The ``executor`` node (``None``: its defaults), checked for ``experiment.executor``.

    Args:
        settings: the job's ``experiment`` group (its ``executor`` names the backend).
        cfg: the composed config's ``executor`` node, or ``None``.

    Raises:
        ConfigError: an unknown key or a bad value; the ``submitit`` executor without
            ``executor.folder``.
    """
    executor = ExecutorSettings.from_cfg(cfg)
    executor.check(settings.executor)
    return executor


def experiment_job(cfg: DictConfig | ExperimentJob) -> ExperimentJob:
    """The main job's composed config as an :class:`ExperimentJob`, every group validated.

    The settings are validated first; an :class:`ExperimentJob` is returned as it is.
    """
    if isinstance(cfg, ExperimentJob):
        return cfg
    settings = ExperimentSettings.from_cfg(cfg.experiment)
    executor = executor_settings(settings, cfg.get("executor"))
    fit = job_fit_settings(cfg)
    return ExperimentJob(settings, TaskConfig.from_dict(cfg.task), fit, executor)


register_configs()
