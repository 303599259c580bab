"""The Hydra side of cpmp's one config schema: registration and conversion.

**Registration** (:func:`register_configs`, run on import): the option dataclasses of
:mod:`cpmp.config` (and :class:`ExperimentSettings`) are stored in Hydra's ConfigStore as
``schema_task``, ``schema_trainer``, ``schema_sequencer``, ``schema_experiment`` and one
``schema_predictor_<kind>`` per predictor kind (its options and ``kind``). Each option of
``conf/`` starts from one of them (``defaults: [/schema_..., _self_]``) and holds only what
differs from the dataclass's defaults; the dataclass's docstring says what each option means.
Hydra then checks the type of every override against the schema.

**Conversion** (:func:`fit_settings`, :func:`experiment_job`): a job turns its composed
``cfg`` into typed configs once, at its start; those validate themselves (``__post_init__``)
and are what the pipeline and :meth:`~cpmp.sequencer.ConcurrentSequencer.fit_config` take.

Importing this module costs Hydra and OmegaConf only (no torch, Lightning or MuJoCo): the
command line is checked before those are loaded (:mod:`cpmp.experiment.cli_checks`).
"""

from __future__ import annotations

import dataclasses
import math
import typing
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from cpmp.config import (
    PREDICTOR_CONFIGS,
    FitConfig,
    PredictorConfig,
    SequencerConfig,
    TaskConfig,
    TrainerConfig,
    predictor_config,
)
from cpmp.errors import ConfigError

RECORD_CHOICES = ("failures", "all", "first", "none")
"""Values of ``experiment.record``."""


@dataclass
class ExperimentSettings:
    """Sizes of the evaluation (``experiment`` config group). The defaults are
    ``experiment=quick``, a small run that finishes in a few minutes on a 2-core laptop.

    Attributes:
        name: label of the settings (``quick``, ``full``, ...).
        seeds: each seed repeats collection, training and reproduction.
        demos_per_strategy: demonstrations collected per strategy (paper: 5, so 15 in all).
        train_per_strategy: of those, used for training (paper: 3, so 9 train / 6 test).
        train_sizes: training-set sizes D to compare (paper: 3, 6, 9), balanced over strategies.
        n_boxes: random boxes reproduced per D and seed (paper: 20).
        box_seed_offset: boxes for reproduction are drawn from ``seed + box_seed_offset``.
        strategy_grid: (widths, depths) cells of the strategy map (Fig. 7).
        record: which reproduction episodes keep an ``.rrd``: ``failures`` (every episode that
            did not complete, plus the first one per training size), ``all``, ``first`` or
            ``none``.
        record_demos: also write the collected demonstrations as ``.rrd``.
        max_time: episode time limit [s] (``None``: the task's ``max_time``).
        feature_noise: std of Gaussian noise added to the training demonstrations' features,
            as a fraction of each feature's range over the training set (0: none); the test
            demonstrations and the closed loop stay noise-free.
        workers: worker processes running the seeds' collection and training sizes in
            parallel (``None``: min(cores, seeds); 1: everything in this process). The report's
            numbers do not depend on it.
    """

    name: str = "quick"
    seeds: list[int] = field(default_factory=lambda: [0])
    demos_per_strategy: int = 3
    train_per_strategy: int = 2
    train_sizes: list[int] = field(default_factory=lambda: [3, 6])
    n_boxes: int = 6
    box_seed_offset: int = 1000
    strategy_grid: list[int] = field(default_factory=lambda: [8, 6])
    record: str = "failures"
    record_demos: bool = False
    max_time: float | None = None
    feature_noise: float = 0.0
    workers: int | None = None

    def __post_init__(self) -> None:
        for name in ("demos_per_strategy", "train_per_strategy", "n_boxes", "box_seed_offset"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int):
                raise ConfigError(f"experiment.{name} must be an integer, got {value!r}")
        for name in ("seeds", "train_sizes", "strategy_grid"):
            values = list(getattr(self, name))
            if any(isinstance(v, bool) or not isinstance(v, int) for v in values):
                raise ConfigError(f"experiment.{name} must be integers, got {values}")
            setattr(self, name, values)
        for name in ("seeds", "train_sizes"):
            values = getattr(self, name)
            if len(set(values)) != len(values):
                raise ConfigError(f"experiment.{name} has duplicates: {values}")
        if not self.seeds or any(s < 0 for s in self.seeds):
            raise ConfigError(f"experiment.seeds must be non-negative integers, got {self.seeds}")
        for name in ("demos_per_strategy", "train_per_strategy", "n_boxes"):
            if getattr(self, name) < 1:
                raise ConfigError(f"experiment.{name} must be >= 1, got {getattr(self, name)}")
        if self.train_per_strategy >= self.demos_per_strategy:
            raise ConfigError(
                f"experiment.train_per_strategy ({self.train_per_strategy}) must be smaller than "
                f"demos_per_strategy ({self.demos_per_strategy}) to leave test demos"
            )
        n_train = 3 * self.train_per_strategy
        if not self.train_sizes or any(d < 1 or d > n_train for d in self.train_sizes):
            raise ConfigError(
                f"experiment.train_sizes must lie in 1..{n_train} (3 strategies x "
                f"train_per_strategy), got {self.train_sizes}"
            )
        if len(self.strategy_grid) != 2 or min(self.strategy_grid) < 2:
            raise ConfigError(
                f"experiment.strategy_grid must be [n_widths, n_depths] >= 2, "
                f"got {self.strategy_grid}"
            )
        if self.record not in RECORD_CHOICES:
            raise ConfigError(
                f"experiment.record must be one of {', '.join(RECORD_CHOICES)}, got {self.record!r}"
            )
        noise = self.feature_noise
        if isinstance(noise, bool) or not isinstance(noise, (int, float)) or not noise >= 0:
            raise ConfigError(f"experiment.feature_noise must be a number >= 0, got {noise!r}")
        if not math.isfinite(noise):
            raise ConfigError(f"experiment.feature_noise must be finite, got {noise}")
        if self.max_time is not None and self.max_time <= 0:
            raise ConfigError(f"experiment.max_time must be > 0, got {self.max_time}")
        workers = self.workers
        if workers is not None and (
            isinstance(workers, bool) or not isinstance(workers, int) or workers < 1
        ):
            raise ConfigError(
                f"experiment.workers must be an integer >= 1 or null (auto), got {workers!r}"
            )

    @classmethod
    def from_cfg(cls, cfg: Any) -> ExperimentSettings:
        """From the ``experiment`` node (or a mapping); unknown keys raise :class:`ConfigError`."""
        options = to_dict(cfg)
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(options) - known)
        if unknown:
            raise ConfigError(
                f"unknown experiment option(s) {', '.join(unknown)}; "
                f"valid: {', '.join(sorted(known))}"
            )
        return cls(**options)


# ----------------------------------------------------------------------------- registration
def _schema(cls: type, **first: Any) -> type:
    """A plain dataclass with the fields (types, defaults) of ``cls``, after the fields
    ``first`` (name -> default string), as Hydra's schema of ``cls``: no validation of its own
    (``cls`` validates at the job boundary) and never frozen (Hydra merges into it)."""
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
    ):
        store.store(name=name, node=_schema(cls))
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
    validated."""
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
    (:func:`predictor_from_cfg`)."""
    kind, config = predictor_from_cfg(cfg)
    return kind, dataclasses.asdict(config)


@dataclass(frozen=True)
class FitSettings:
    """The typed ``predictor``, ``sequencer`` and ``trainer`` groups of a job.

    Attributes:
        fit: the learned sequencer's :class:`~cpmp.config.FitConfig` (seed 0; the jobs set
            the seed and the trainer's ``log_dir`` per fit).
        goal_nearest: the options of the ``goal_nearest`` baseline when the ``sequencer``
            group selects it (``kind: goal_nearest``; the predictor and trainer are then not
            used), else ``None``.
    """

    fit: FitConfig
    goal_nearest: Any | None = None

    @property
    def predictor(self) -> str:
        """The predictor kind."""
        return self.fit.predictor


def fit_settings(
    predictor_cfg: Any, sequencer_cfg: Any = None, trainer_cfg: Any = None
) -> FitSettings:
    """Typed :class:`FitSettings` from the ``predictor``, ``sequencer`` and ``trainer`` groups
    (nodes or mappings; ``None``: the defaults), validated; the ``goal_nearest`` baseline
    needs no ``predictor``. A set ``trainer.lr`` replaces the ``lr`` of a predictor that has
    one (the Adam-trained ones), so that the saved model says which rate it was trained
    with."""
    sequencer = to_dict(sequencer_cfg)
    goal_nearest = None
    if sequencer.get("kind") is not None:
        from cpmp.goal_nearest import KIND, goal_nearest_options

        if sequencer.pop("kind") != KIND:
            raise ConfigError(f"sequencer.kind must be {KIND!r} or absent (the learned sequencer)")
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
    return FitSettings(FitConfig(kind, predictor, rule, trainer), goal_nearest)


def job_fit_settings(cfg: Any) -> FitSettings:
    """:func:`fit_settings` of a job's composed config."""
    return fit_settings(cfg.predictor, cfg.get("sequencer"), cfg.get("trainer"))


@dataclass(frozen=True)
class ExperimentJob:
    """The main job's config, typed: what ``run_experiment`` and its workers take.

    Attributes:
        settings: the ``experiment`` group.
        task: the ``task`` group.
        fit: the ``predictor``, ``sequencer`` and ``trainer`` groups.
    """

    settings: ExperimentSettings
    task: TaskConfig
    fit: FitSettings


def experiment_job(cfg: Any) -> ExperimentJob:
    """The main job's composed config as an :class:`ExperimentJob` (an :class:`ExperimentJob`
    is returned as it is); every group validated, the settings first."""
    if isinstance(cfg, ExperimentJob):
        return cfg
    settings = ExperimentSettings.from_cfg(cfg.experiment)
    fit = job_fit_settings(cfg)
    return ExperimentJob(settings, TaskConfig.from_dict(cfg.task), fit)


register_configs()
