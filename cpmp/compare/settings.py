"""The ``compare`` config node of ``cpmp-compare``, typed.

:class:`CompareSettings` with its ``sweep`` (:class:`SweepSettings`). The dataclasses are the
node's schema (``schema_compare``, stored in Hydra's ConfigStore by :func:`register_compare`,
run on import) and hold its only defaults; the ``conf/experiment/compare*.yaml`` options hold
what differs from them.

Importing this module costs Hydra and OmegaConf only (the command line imports it before
Hydra composes anything).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

from omegaconf import DictConfig

from cpmp.compare.stats import BootstrapOptions
from cpmp.compare.worlds import SYNTHETIC_WORLDS, WORLD_KINDS, World, synthetic_run
from cpmp.config import TaskConfig
from cpmp.config.bc import KIND as BC
from cpmp.config.goal_nearest import KIND as GOAL_NEAREST
from cpmp.errors import ConfigError
from cpmp.experiment.config import executor_settings, is_stored, store_schema
from cpmp.experiment.settings import ConfigNode, ExecutorSettings, ExperimentSettings, to_dict

SCHEMA = "schema_compare"
"""The name of the ``compare`` node's schema in Hydra's ConfigStore."""


@dataclass
class SeriesSettings:
    """One more series of the support axis (``compare.sweep.series``).

    A predictor whose support count another option than ``support_scale`` sets.

    Attributes:
        predictor: the ``predictor`` option.
        option: its option that sets the support count (``support_scale``, a sparsity level).
        values: the values run (each one point of the axis); the option's default is run
            anyway, as the predictor's own point.
    """

    predictor: str = "klr_sparse"
    option: str = "support_scale"
    values: list[float] = field(default_factory=list)


@dataclass
class SweepSettings:
    """The ``compare.sweep`` node: the support-count axis.

    Attributes:
        predictor: the ``predictor`` option whose ``support_scale`` is swept.
        support_scale: the swept values (support points per unit of L1 path length; empty: no
            sweep).
        train_sizes: the training sizes of the sweep (``None``: each world's largest D).
        worlds: the ``compare.worlds`` it runs on.
        series: further series (another predictor's support count, e.g. ``klr_sparse``'s
            sparsity levels), each point one fit.
    """

    predictor: str = "klr"
    support_scale: list[float] = field(default_factory=list)
    train_sizes: list[int] | None = None
    worlds: list[str] = field(default_factory=lambda: ["sim"])
    series: list[SeriesSettings] = field(default_factory=list)


@dataclass
class WorldSettings:
    """One entry of ``compare.worlds``: a world the rows run on (:mod:`cpmp.compare.worlds`).

    ``None`` takes the ``experiment`` group's value (``compare.predictors`` and
    ``compare.baselines`` for the rows).

    Attributes:
        kind: ``sim`` (the simulator, ``task`` over the job's task group) or ``synthetic``.
        world: a synthetic world's name (:data:`cpmp.compare.worlds.SYNTHETIC_WORLDS`).
        task: ``sim``: task options (``settle_time: 0``); ``synthetic``: the world's options.
        feature_noise: noise on the training demonstrations (fraction of each feature's
            range; ``None``: ``experiment.feature_noise`` for ``sim``, 0 for ``synthetic``).
        seeds: seeds (``None``: ``experiment.seeds``).
        train_sizes: training sizes D (``None``: ``experiment.train_sizes``).
        episodes: closed-loop episodes per D and seed (``sim``: boxes; ``None``:
            ``experiment.n_boxes``).
        test_demos: held-out demonstrations per seed of a synthetic world (the MAE's).
        predictors: the rows' ``predictor`` options (``None``: ``compare.predictors``).
        baselines: the rows' ``sequencer`` baselines (``None``: ``compare.baselines``).
    """

    kind: str = "sim"
    world: str | None = None
    task: dict[str, Any] = field(default_factory=dict)  # OmegaConf's schema: Any
    feature_noise: float | None = None
    seeds: list[int] | None = None
    train_sizes: list[int] | None = None
    episodes: int | None = None
    test_demos: int = 6
    predictors: list[str] | None = None
    baselines: list[str] | None = None


@dataclass
class ClaimSettings:
    """One claim the report tests (``compare.claims``): row ``a`` against row ``b``.

    Attributes:
        name: what the pair tests, in words.
        a: a ``predictor`` option (the claim's side).
        b: the ``predictor`` option it is tested against.
    """

    name: str = ""
    a: str = ""
    b: str = ""


@dataclass
class StatsSettings:
    """The ``compare.stats`` node: the bootstrap (:mod:`cpmp.compare.stats`).

    Attributes:
        samples: bootstrap replicates per interval.
        level: the intervals' coverage.
        seed: seeds the replicates.
    """

    samples: int = 2000
    level: float = 0.95
    seed: int = 0


def _claims() -> list[ClaimSettings]:
    """The paper's two claims, each a pair of rows that differ in that one respect."""
    return [
        ClaimSettings("soft-label BCE vs clipped regression", "klr", "regression_clip"),
        ClaimSettings("path-length progress (eq. 1) vs elapsed time", "klr", "time_phase"),
    ]


@dataclass
class CompareSettings:
    """The ``compare`` config node.

    Attributes:
        predictors: ``all`` (every ``predictor`` group option and every registered kind) or
            a list of ``predictor`` group option names: the rows of every world that does not
            name its own.
        baselines: ``sequencer`` group options run without a predictor (``goal_nearest``,
            ``bc``).
        sweep: the support-count axis.
        worlds: the worlds the rows run on, by name (``sim``: the job's own task).
        claims: pairs of rows whose differences the report tests in every world.
        stats: the bootstrap.
    """

    predictors: Any = "all"  # OmegaConf's schema: a string or a list, no union of the two
    baselines: list[str] = field(default_factory=lambda: ["goal_nearest"])
    sweep: SweepSettings = field(default_factory=SweepSettings)
    worlds: dict[str, WorldSettings] = field(default_factory=lambda: {"sim": WorldSettings()})
    claims: list[ClaimSettings] = field(default_factory=_claims)
    stats: StatsSettings = field(default_factory=StatsSettings)


def _node(cls: type, cfg: object, path: str) -> dict[str, Any]:
    """The options of a node of dataclass ``cls`` at ``path`` as a dict, unknown keys refused.

    Raises:
        ConfigError: a key ``cls`` does not have, naming the valid ones.
    """
    options = to_dict(cfg)
    keys = [f.name for f in dataclasses.fields(cls)]
    unknown = sorted(set(options) - set(keys))
    if unknown:
        raise ConfigError(
            f"unknown compare option(s) {', '.join(f'compare.{path}{k}' for k in unknown)}; "
            "valid: " + ", ".join(f"compare.{path}{k}" for k in keys)
        )
    return options


def _names(value: object, path: str) -> list[str] | None:
    """A list of option names (``None`` stays ``None``), or a :class:`ConfigError`."""
    if value is None:
        return None
    if isinstance(value, str) or not isinstance(value, (list, tuple)):
        raise ConfigError(f"{path} must be a list of option names, got {value!r}")
    return [str(v) for v in value]


def _numbers(values: Iterable[object] | None, path: str) -> list[float]:
    """Positive, distinct numbers, or a :class:`ConfigError` naming ``path``."""
    values = list(values or [])
    for value in values:
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not value > 0:
            raise ConfigError(f"{path} must be numbers > 0, got {values}")
    if len(set(values)) != len(values):
        raise ConfigError(f"{path} has duplicates: {values}")
    return [float(v) for v in values]


def _sweep(cfg: ConfigNode) -> SweepSettings:
    """The ``compare.sweep`` node, its keys and values checked."""
    options = _node(SweepSettings, cfg, "sweep.")
    if "predictor" in options:
        options["predictor"] = str(options["predictor"])
    options["support_scale"] = _numbers(options.get("support_scale"), "compare.sweep.support_scale")
    if "worlds" in options:
        options["worlds"] = _names(options["worlds"], "compare.sweep.worlds") or []
    series = []
    for i, entry in enumerate(options.pop("series", None) or []):
        one = _node(SeriesSettings, entry, f"sweep.series[{i}].")
        values = _numbers(one.pop("values", None), f"compare.sweep.series[{i}].values")
        series.append(SeriesSettings(**{k: str(v) for k, v in one.items()}, values=values))
    return SweepSettings(**options, series=series)


def _world(name: str, cfg: ConfigNode) -> WorldSettings:
    """One ``compare.worlds`` entry, its keys and kind checked."""
    out = WorldSettings(**_node(WorldSettings, cfg, f"worlds.{name}."))
    if out.kind not in WORLD_KINDS:
        raise ConfigError(
            f"compare.worlds.{name}.kind must be one of {', '.join(WORLD_KINDS)}, got {out.kind!r}"
        )
    if out.kind == "synthetic" and not out.world:
        raise ConfigError(
            f"compare.worlds.{name}: a synthetic world names its world (world: "
            f"{' | '.join(SYNTHETIC_WORLDS)})"
        )
    if out.kind == "sim" and out.world is not None:
        raise ConfigError(
            f"compare.worlds.{name}: a sim world takes task options, not world={out.world!r}"
        )
    out.task = to_dict(out.task)
    out.predictors = _names(out.predictors, f"compare.worlds.{name}.predictors")
    out.baselines = _names(out.baselines, f"compare.worlds.{name}.baselines")
    return out


def _stats(cfg: ConfigNode) -> StatsSettings:
    """The ``compare.stats`` node, checked by :class:`~cpmp.compare.stats.BootstrapOptions`."""
    out = StatsSettings(**_node(StatsSettings, cfg, "stats."))
    try:
        BootstrapOptions(out.samples, out.level, out.seed)
    except ConfigError as err:
        raise ConfigError(f"compare.stats: {err}") from err
    return out


def compare_settings(cfg: ConfigNode) -> CompareSettings:
    """The ``compare`` node (or a mapping; missing keys take the defaults), keys checked.

    Raises:
        ConfigError: an unknown key or a bad value, naming the option to fix.
    """
    options = _node(CompareSettings, cfg, "")
    if "baselines" in options:
        options["baselines"] = _names(options["baselines"], "compare.baselines") or []
    options["sweep"] = _sweep(options.get("sweep"))
    if "worlds" in options:
        worlds = to_dict(options["worlds"])
        if not worlds:
            raise ConfigError("compare.worlds is empty: name at least one world (sim: the task)")
        options["worlds"] = {str(k): _world(str(k), v) for k, v in worlds.items()}
    if "claims" in options:
        options["claims"] = [
            ClaimSettings(**{k: str(v) for k, v in _node(ClaimSettings, c, "claims.").items()})
            for c in options["claims"] or []
        ]
    options["stats"] = _stats(options.get("stats"))
    out = CompareSettings(**options)
    if out.predictors != "all" and (not isinstance(out.predictors, list) or not out.predictors):
        raise ConfigError(
            f"compare.predictors must be 'all' or a non-empty list, got {out.predictors!r}"
        )
    return out


def _integers(values: Iterable[object], path: str, low: int) -> tuple[int, ...]:
    """Distinct integers ``>= low``, or a :class:`ConfigError` naming ``path``."""
    out = list(values)
    if not out or any(isinstance(v, bool) or not isinstance(v, int) or v < low for v in out):
        raise ConfigError(f"{path} must be a non-empty list of integers >= {low}, got {out}")
    if len(set(out)) != len(out):
        raise ConfigError(f"{path} has duplicates: {out}")
    return tuple(out)


def resolve_world(
    name: str,
    entry: WorldSettings,
    compare: CompareSettings,
    settings: ExperimentSettings,
    task: TaskConfig,
) -> World:
    """One ``compare.worlds`` entry resolved against the job's ``experiment`` and ``task``.

    Raises:
        ConfigError: a bad value (a task option, a world's option, a count), naming it.
    """
    path = f"compare.worlds.{name}"
    seeds = _integers(settings.seeds if entry.seeds is None else entry.seeds, f"{path}.seeds", 0)
    sizes = settings.train_sizes if entry.train_sizes is None else entry.train_sizes
    sizes = _integers(sizes, f"{path}.train_sizes", 1)
    episodes = settings.n_boxes if entry.episodes is None else entry.episodes
    _integers([episodes], f"{path}.episodes", 1)
    _integers([entry.test_demos], f"{path}.test_demos", 1)
    noise = entry.feature_noise
    if noise is None:
        noise = settings.feature_noise if entry.kind == "sim" else 0.0
    if isinstance(noise, bool) or not isinstance(noise, (int, float)) or not 0 <= noise < 1:
        raise ConfigError(f"{path}.feature_noise must be a number in [0, 1), got {noise!r}")
    if entry.kind == "sim":
        try:
            TaskConfig.from_dict({**dataclasses.asdict(task), **entry.task})
            dataclasses.replace(
                settings,
                seeds=list(seeds),
                train_sizes=list(sizes),
                n_boxes=episodes,
                feature_noise=float(noise),
            )
        except ConfigError as err:
            raise ConfigError(f"{path}: {err}") from err
    else:
        try:
            synthetic_run(str(entry.world), entry.task, seeds[0], 1)  # its options, checked
        except ConfigError as err:
            raise ConfigError(f"{path}: {err}") from err
    baselines = compare.baselines if entry.baselines is None else entry.baselines
    return World(
        name=name,
        kind="sim" if entry.kind == "sim" else "synthetic",
        world=entry.world,
        options=dict(entry.task),
        feature_noise=float(noise),
        seeds=seeds,
        train_sizes=sizes,
        episodes=int(episodes),
        test_demos=int(entry.test_demos),
        predictors=compare.predictors if entry.predictors is None else entry.predictors,
        baselines=tuple(baselines),
    )


def _check_sweep(sweep: SweepSettings, worlds: Sequence[World]) -> None:
    """The sweep's worlds exist and its training sizes are each world's."""
    if not (sweep.support_scale or sweep.series):
        return
    by_name = {w.name: w for w in worlds}
    missing = [w for w in sweep.worlds if w not in by_name]
    if missing or not sweep.worlds:
        raise ConfigError(
            f"compare.sweep.worlds must name worlds of compare.worlds ({', '.join(by_name)}), "
            f"got {sweep.worlds}"
        )
    sizes = sweep.train_sizes
    if sizes is None:
        return
    for name in sweep.worlds:
        own = list(by_name[name].train_sizes)
        if not isinstance(sizes, list) or any(d not in own for d in sizes):
            raise ConfigError(
                f"compare.sweep.train_sizes must be a list of the training sizes {own} of "
                f"world {name} (experiment.train_sizes or its own), got {sizes!r}"
            )


@dataclass(frozen=True)
class CompareJob:
    """The comparison's composed config, typed (the groups every row shares).

    Attributes:
        settings: the ``experiment`` group (seeds, demonstrations, boxes, workers).
        task: the ``task`` group.
        compare: the ``compare`` node.
        worlds: ``compare.worlds`` resolved, in their order.
        executor: the ``executor`` node (used by ``experiment.executor=submitit``).
    """

    settings: ExperimentSettings
    task: TaskConfig
    compare: CompareSettings
    worlds: tuple[World, ...]
    executor: ExecutorSettings = field(default_factory=ExecutorSettings)

    @classmethod
    def from_cfg(cls, cfg: DictConfig) -> CompareJob:
        """From a composed config (``experiment``, ``task`` and ``compare`` nodes), validated.

        The job's ``sequencer`` must be a learned one: the predictor rows run with it.

        Raises:
            ConfigError: a bad option of any of them, or a baseline as the job's sequencer
                (``sequencer=goal_nearest`` or ``bc``).
        """
        kind = to_dict(cfg.get("sequencer")).get("kind")
        if kind in (GOAL_NEAREST, BC):
            raise ConfigError(
                "the comparison runs the predictors with the job's sequencer, which must be a "
                f"learned one (e.g. sequencer=coupled); list {kind} in compare.baselines"
            )
        settings = ExperimentSettings.from_cfg(cfg.experiment)
        executor = executor_settings(settings, cfg.get("executor"))
        task = TaskConfig.from_dict(cfg.task)
        compare = compare_settings(cfg.get("compare"))
        worlds = tuple(
            resolve_world(name, entry, compare, settings, task)
            for name, entry in compare.worlds.items()
        )
        _check_sweep(compare.sweep, worlds)
        return cls(settings, task, compare, worlds, executor)


def register_compare(*, missing_only: bool = False) -> None:
    """Store the ``compare`` node's schema (:data:`SCHEMA`) in Hydra's ConfigStore (idempotent).

    Args:
        missing_only: store it only if the ConfigStore lacks it (it holds it after this
            module's import), as :func:`~cpmp.experiment.config.register_configs`.
    """
    if not (missing_only and is_stored(SCHEMA)):
        store_schema(SCHEMA, CompareSettings)


register_compare()
