"""The rows of the comparison: which configurations ``cpmp-compare`` runs, and its jobs.

Rows (``compare.json``, one per predictor/sequencer/D, support scale for the sweep):

* ``predictors``: every option of the ``predictor`` config group (and any registered predictor
  kind no option uses, with its built-in defaults), each with its default options, run with the
  job's ``sequencer``;
* ``baselines``: each listed ``sequencer`` option that needs no predictor (``goal_nearest``);
* ``support_sweep``: ``compare.sweep.predictor`` at each ``compare.sweep.support_scale``, at the
  training sizes ``compare.sweep.train_sizes`` (default: the largest D).

:func:`row_specs` chooses them (:class:`RowSpec`, from the ``compare`` node,
:class:`~cpmp.compare.settings.CompareSettings`), checked before any long work. Each (seed,
row, D) whose fit no earlier row shares is one :class:`FitJob`.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, NamedTuple

from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra

from cpmp.compare.settings import CompareSettings
from cpmp.config.goal_nearest import KIND, goal_nearest_options
from cpmp.errors import ConfigError
from cpmp.experiment.config import predictor_options
from cpmp.experiment.settings import ExperimentSettings, to_dict
from cpmp.predictors import PREDICTORS

NO_PREDICTOR = "none"
"""The ``predictor`` of a baseline row that uses no progress predictor."""

CONFIG_NAME = "compare"
"""The comparison's top config, ``conf/compare.yaml``."""

_CONF_DIR = Path(__file__).resolve().parents[2] / "conf"


RowGroup = Literal["predictors", "baselines", "support_sweep"]
"""The kind of a compared row (``group`` in ``compare.json``): a ``predictor`` option with the
job's sequencer, a ``sequencer`` option that uses no predictor, or the swept predictor at one
``support_scale``."""


@dataclass(frozen=True)
class RowSpec:
    """One compared configuration.

    Attributes:
        group: which kind of row.
        predictor: ``predictor`` option name (:data:`NO_PREDICTOR` for a baseline).
        sequencer: ``sequencer`` option name.
        predictor_cfg: the predictor options (with ``kind``).
        sequencer_cfg: the sequencer options.
        train_sizes: the training sizes D this row runs at.
        support_scale: the swept value (sweep rows only).
    """

    group: RowGroup
    predictor: str
    sequencer: str
    predictor_cfg: Mapping[str, Any]
    sequencer_cfg: Mapping[str, Any]
    train_sizes: tuple[int, ...]
    support_scale: float | None = None

    def fit_key(self, seed: int, d: int) -> str:
        """The key of the fit and evaluation this row needs at ``(seed, d)``.

        Rows with equal keys (the sweep's point at the default scale) share one job.
        """
        options = {
            "predictor": dict(self.predictor_cfg) if self.predictor != NO_PREDICTOR else None,
            "sequencer": dict(self.sequencer_cfg),
        }
        return json.dumps({"seed": seed, "D": d, **options}, sort_keys=True, default=str)

    def label(self) -> str:
        """``predictor + sequencer`` (and the support scale of a sweep row), for log lines."""
        scale = "" if self.support_scale is None else f" support_scale={self.support_scale:g}"
        return f"{self.predictor} + {self.sequencer}{scale}"


class FitJob(NamedTuple):
    """One fit of the comparison: a row at one seed and training size."""

    spec: RowSpec
    """The (first) row this fit serves."""
    seed: int
    """The seed."""
    d: int
    """The training size D."""


def fit_jobs(specs: list[RowSpec], seeds: list[int]) -> dict[str, FitJob]:
    """Every fit the rows need, by :meth:`RowSpec.fit_key`, in row order (shared fits once)."""
    jobs: dict[str, FitJob] = {}
    for spec in specs:
        for seed in seeds:
            for d in spec.train_sizes:
                jobs.setdefault(spec.fit_key(seed, d), FitJob(spec, seed, d))
    return jobs


# --------------------------------------------------------------------------- config groups
def group_options(group: str) -> dict[str, dict[str, Any]]:
    """Every option of config group ``group`` (``predictor``, ``sequencer``), composed, by name.

    The options come from the running Hydra app's search path (or ``conf/`` outside one),
    each composed with its defaults.
    """

    def compose_all() -> dict[str, dict[str, Any]]:
        loader = GlobalHydra.instance().config_loader()
        names = loader.get_group_options(group)
        return {
            name: to_dict(compose(config_name=CONFIG_NAME, overrides=[f"{group}={name}"])[group])
            for name in names
        }

    if GlobalHydra.instance().is_initialized():
        return compose_all()
    with initialize_config_dir(config_dir=str(_CONF_DIR), version_base="1.3"):
        return compose_all()


def option_name(options: Mapping[str, Any], group: Mapping[str, Mapping[str, Any]]) -> str:
    """The name of the group option equal to ``options`` (``custom`` if none is)."""
    return next((name for name, value in group.items() if dict(value) == dict(options)), "custom")


def row_specs(cfg: Any, settings: ExperimentSettings, compare: CompareSettings) -> list[RowSpec]:
    """The compared configurations, in report order (checked now, before any long work).

    Raises:
        ConfigError: a ``compare`` option names an unknown or unsuitable group option.
    """
    predictors = group_options("predictor")
    sequencers = group_options("sequencer")
    sequencer_cfg = to_dict(cfg.get("sequencer"))  # a learned one (CompareJob checks)
    sequencer = option_name(sequencer_cfg, sequencers)
    sizes = tuple(settings.train_sizes)
    if compare.predictors == "all":
        names = sorted(predictors)
        kinds = {options.get("kind") for options in predictors.values()}
        chosen = {name: predictors[name] for name in names}
        chosen.update({kind: {"kind": kind} for kind in PREDICTORS if kind not in kinds})
    else:
        missing = [n for n in compare.predictors if n not in predictors]
        if missing:
            raise ConfigError(
                f"compare.predictors names unknown predictor option(s) {', '.join(missing)}; "
                f"choose from {', '.join(sorted(predictors))}"
            )
        chosen = {name: predictors[name] for name in compare.predictors}
    specs = []
    for name, options in chosen.items():
        predictor_options(options)
        specs.append(RowSpec("predictors", name, sequencer, options, sequencer_cfg, sizes))
    for name in compare.baselines:
        options = sequencers.get(name)
        if options is None or options.get("kind") != KIND:
            raise ConfigError(
                f"compare.baselines: {name!r} is not a sequencer option of kind {KIND!r}; "
                f"options of that kind: "
                f"{', '.join(n for n, o in sequencers.items() if o.get('kind') == KIND)}"
            )
        goal_nearest_options({k: v for k, v in options.items() if k != "kind"})
        specs.append(RowSpec("baselines", NO_PREDICTOR, name, {}, options, sizes))
    sweep = compare.sweep
    if sweep.support_scale:
        base = predictors.get(sweep.predictor)
        if base is None or "support_scale" not in base:
            raise ConfigError(
                f"compare.sweep.predictor must be a predictor option with support points "
                f"(support_scale), got {sweep.predictor!r}"
            )
        for scale in sweep.support_scale:
            options = {**base, "support_scale": float(scale)}
            predictor_options(options)
            specs.append(
                RowSpec(
                    "support_sweep",
                    sweep.predictor,
                    sequencer,
                    options,
                    sequencer_cfg,
                    tuple(sweep.train_sizes or ()),
                    float(scale),
                )
            )
    return specs
