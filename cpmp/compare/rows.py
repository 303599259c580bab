"""The rows of the comparison: which configurations ``cpmp-compare`` runs, and its jobs.

Rows (``compare.json``, one per world/predictor/sequencer/D, and the support axis's point):
in every world of ``compare.worlds``,

* ``predictors``: the world's ``predictors`` (default ``compare.predictors``: every option of the
  ``predictor`` config group, and any registered predictor kind no option uses, with its
  built-in defaults), each with its default options, run with the job's ``sequencer``;
* ``baselines``: each listed ``sequencer`` option that needs no predictor (``goal_nearest``,
  ``bc``);
* ``support_sweep`` (the worlds of ``compare.sweep.worlds``): ``compare.sweep.predictor`` at
  each ``compare.sweep.support_scale``, and each ``compare.sweep.series`` predictor at each of
  its values and at its own default, at the training sizes ``compare.sweep.train_sizes``
  (default: the world's largest D).

:func:`row_specs` chooses them (:class:`RowSpec`, from the typed
:class:`~cpmp.compare.settings.CompareJob`), checked before any long work. Each (world, seed,
row, D) whose fit no earlier row shares is one :class:`FitJob`.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Literal, NamedTuple

from hydra import compose, initialize_config_module
from hydra.core.global_hydra import GlobalHydra
from omegaconf import DictConfig

from cpmp.compare.settings import CompareJob, CompareSettings
from cpmp.compare.worlds import World
from cpmp.config.bc import KIND as BC
from cpmp.config.bc import bc_options
from cpmp.config.goal_nearest import KIND, goal_nearest_options
from cpmp.config.paths import CONF_PACKAGE
from cpmp.errors import ConfigError
from cpmp.experiment.config import predictor_options
from cpmp.experiment.settings import to_dict
from cpmp.predictors import PREDICTORS
from cpmp.records import JsonValue

NO_PREDICTOR = "none"
"""The ``predictor`` of a baseline row that uses no progress predictor."""


RowGroup = Literal["predictors", "baselines", "support_sweep"]
"""The kind of a compared row (``group`` in ``compare.json``): a ``predictor`` option with the
job's sequencer, a ``sequencer`` option that uses no predictor, or a point of the support axis
(a predictor at one value of the option that sets its support count)."""


@dataclass(frozen=True)
class RowSpec:
    """One compared configuration in one world.

    Attributes:
        world: the world's name (``compare.worlds``).
        group: which kind of row.
        predictor: ``predictor`` option name (:data:`NO_PREDICTOR` for a baseline).
        sequencer: ``sequencer`` option name.
        predictor_cfg: the predictor options (with ``kind``).
        sequencer_cfg: the sequencer options.
        train_sizes: the training sizes D this row runs at.
        option: a support-axis row's option (``support_scale``, a sparsity level), else
            ``None``.
        value: its value (``None``: the predictor's own default of ``option``).
    """

    world: str
    group: RowGroup
    predictor: str
    sequencer: str
    predictor_cfg: Mapping[str, JsonValue]
    sequencer_cfg: Mapping[str, JsonValue]
    train_sizes: tuple[int, ...]
    option: str | None = None
    value: float | None = None

    def fit_key(self, seed: int, d: int) -> str:
        """The key of the fit and evaluation this row needs at ``(seed, d)``.

        Rows with equal keys (the sweep's point at the predictor's own value) share one job.
        """
        options = {
            "predictor": dict(self.predictor_cfg) if self.predictor != NO_PREDICTOR else None,
            "sequencer": dict(self.sequencer_cfg),
        }
        key = {"world": self.world, "seed": seed, "D": d, **options}
        return json.dumps(key, sort_keys=True, default=str)

    def point(self) -> str:
        """A support-axis row's ``option=value`` (``option=default``), else ``""``."""
        if self.option is None:
            return ""
        return f"{self.option}={'default' if self.value is None else f'{self.value:g}'}"

    def label(self) -> str:
        """``world: predictor + sequencer`` (and a support-axis row's point), for log lines."""
        point = f" {self.point()}" if self.option else ""
        return f"{self.world}: {self.predictor} + {self.sequencer}{point}"


class FitJob(NamedTuple):
    """One fit of the comparison: a row at one seed and training size."""

    spec: RowSpec
    """The (first) row this fit serves."""
    seed: int
    """The seed."""
    d: int
    """The training size D."""


def fit_jobs(specs: list[RowSpec], worlds: Mapping[str, World]) -> dict[str, FitJob]:
    """Every fit the rows need, by :meth:`RowSpec.fit_key`, in row order (shared fits once)."""
    jobs: dict[str, FitJob] = {}
    for spec in specs:
        for seed in worlds[spec.world].seeds:
            for d in spec.train_sizes:
                jobs.setdefault(spec.fit_key(seed, d), FitJob(spec, seed, d))
    return jobs


# --------------------------------------------------------------------------- config groups
def group_options(group: str) -> dict[str, dict[str, JsonValue]]:
    """Every option of config group ``group`` (``predictor``, ``sequencer``), composed, by name.

    The options come from the running Hydra app's search path (or ``conf/`` outside one),
    each composed with its defaults on its own (no primary config: a full job config per
    option would compose every other group too).
    """

    def compose_all() -> dict[str, dict[str, JsonValue]]:
        loader = GlobalHydra.instance().config_loader()
        names = loader.get_group_options(group)
        return {
            name: to_dict(compose(config_name=None, overrides=[f"+{group}={name}"])[group])
            for name in names
        }

    if GlobalHydra.instance().is_initialized():
        return compose_all()
    with initialize_config_module(config_module=CONF_PACKAGE, version_base="1.3"):
        return compose_all()


def option_name(
    options: Mapping[str, JsonValue], group: Mapping[str, Mapping[str, JsonValue]]
) -> str:
    """The name of the group option equal to ``options`` (``custom`` if none is)."""
    return next((name for name, value in group.items() if dict(value) == dict(options)), "custom")


def _chosen_predictors(
    names: str | Sequence[str], predictors: Mapping[str, dict[str, JsonValue]], path: str
) -> dict[str, dict[str, JsonValue]]:
    """The predictor options a world's rows run (``all``: every option and unused kind)."""
    if names == "all":
        kinds = {options.get("kind") for options in predictors.values()}
        chosen = {name: predictors[name] for name in sorted(predictors)}
        chosen.update({kind: {"kind": kind} for kind in PREDICTORS if kind not in kinds})
        return chosen
    missing = [n for n in names if n not in predictors]
    if missing:
        raise ConfigError(
            f"{path} names unknown predictor option(s) {', '.join(missing)}; "
            f"choose from {', '.join(sorted(predictors))}"
        )
    return {name: predictors[name] for name in names}


def _sweep_specs(
    world: World,
    compare: CompareSettings,
    predictors: Mapping[str, dict[str, JsonValue]],
    sequencer: str,
    sequencer_cfg: Mapping[str, JsonValue],
) -> list[RowSpec]:
    """The support axis's rows in ``world``: the swept ``support_scale`` and every series."""
    sweep = compare.sweep
    sizes = tuple(sweep.train_sizes or (max(world.train_sizes),))
    series = [("support_scale", sweep.predictor, sweep.support_scale, False)] * bool(
        sweep.support_scale
    ) + [(s.option, s.predictor, s.values, True) for s in sweep.series]
    specs = []
    for option, name, values, own in series:
        base = predictors.get(name)
        if base is None or option not in base:
            path = "compare.sweep.predictor" if not own else "compare.sweep.series"
            raise ConfigError(
                f"{path}: the support axis needs a predictor option with the option {option!r} "
                f"(support points: support_scale), got {name!r}"
            )
        points: list[float | None] = list(values)
        if own:
            points.append(None)  # the predictor's own choice (its default)
        for value in points:
            options = dict(base) if value is None else {**base, option: float(value)}
            predictor_options(options)
            specs.append(
                RowSpec(
                    world.name,
                    "support_sweep",
                    name,
                    sequencer,
                    options,
                    sequencer_cfg,
                    sizes,
                    option,
                    None if value is None else float(value),
                )
            )
    return specs


def row_specs(cfg: DictConfig, job: CompareJob) -> list[RowSpec]:
    """The compared configurations of every world, in report order (checked before any work).

    Raises:
        ConfigError: a ``compare`` option names an unknown or unsuitable group option.
    """
    compare = job.compare
    predictors = group_options("predictor")
    sequencers = group_options("sequencer")
    sequencer_cfg = to_dict(cfg.get("sequencer"))  # a learned one (CompareJob checks)
    sequencer = option_name(sequencer_cfg, sequencers)
    for claim in compare.claims:
        missing = [n for n in (claim.a, claim.b) if n not in predictors]
        if missing:
            raise ConfigError(
                f"compare.claims: {claim.name!r} names unknown predictor option(s) "
                f"{', '.join(missing)}; choose from {', '.join(sorted(predictors))}"
            )
    specs = []
    for world in job.worlds:
        sizes = world.train_sizes
        path = (
            "compare.predictors"
            if world.predictors is compare.predictors
            else (f"compare.worlds.{world.name}.predictors")
        )
        for name, options in _chosen_predictors(world.predictors, predictors, path).items():
            predictor_options(options)
            specs.append(
                RowSpec(world.name, "predictors", name, sequencer, options, sequencer_cfg, sizes)
            )
        for name in world.baselines:
            options = sequencers.get(name)
            kinds = (KIND, BC)
            if options is None or options.get("kind") not in kinds:
                raise ConfigError(
                    f"compare.baselines: {name!r} is not a sequencer option of kind {KIND!r} "
                    f"or {BC!r}; options of those kinds: "
                    f"{', '.join(n for n, o in sequencers.items() if o.get('kind') in kinds)}"
                )
            check = goal_nearest_options if options["kind"] == KIND else bc_options
            check({k: v for k, v in options.items() if k != "kind"})
            specs.append(RowSpec(world.name, "baselines", NO_PREDICTOR, name, {}, options, sizes))
        if world.name in compare.sweep.worlds:
            specs += _sweep_specs(world, compare, predictors, sequencer, sequencer_cfg)
    return specs
