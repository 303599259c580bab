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
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from cpmp.config import TaskConfig
from cpmp.config.goal_nearest import KIND as GOAL_NEAREST
from cpmp.errors import ConfigError
from cpmp.experiment.config import store_schema
from cpmp.experiment.settings import ExperimentSettings, to_dict

SCHEMA = "schema_compare"
"""The name of the ``compare`` node's schema in Hydra's ConfigStore."""


@dataclass
class SweepSettings:
    """The ``compare.sweep`` node: a support-density sweep of one predictor.

    Attributes:
        predictor: the ``predictor`` option whose ``support_scale`` is swept.
        support_scale: the swept values (support points per unit of L1 path length; empty: no
            sweep).
        train_sizes: the training sizes of the sweep (``None``: the largest D).
    """

    predictor: str = "klr"
    support_scale: list[float] = field(default_factory=list)
    train_sizes: list[int] | None = None


@dataclass
class CompareSettings:
    """The ``compare`` config node.

    Attributes:
        predictors: ``all`` (every ``predictor`` group option and every registered kind) or
            a list of ``predictor`` group option names.
        baselines: ``sequencer`` group options run without a predictor (``goal_nearest``).
        sweep: the support-density sweep.
    """

    predictors: Any = "all"
    baselines: list[str] = field(default_factory=lambda: ["goal_nearest"])
    sweep: SweepSettings = field(default_factory=SweepSettings)

    @classmethod
    def from_cfg(cls, cfg: Any, train_sizes: Sequence[int]) -> CompareSettings:
        """From the ``compare`` node, validated against the experiment's ``train_sizes``.

        ``cfg`` may be a mapping; missing keys take the defaults above. ``sweep.train_sizes``
        ``None`` becomes the largest D.

        Raises:
            ConfigError: an unknown key or a bad value, naming the option to fix.
        """
        options = to_dict(cfg)
        sweep = to_dict(options.pop("sweep", None))
        sweep_keys = [f.name for f in dataclasses.fields(SweepSettings)]
        unknown = sorted(set(options) - {"predictors", "baselines"}) + [
            f"sweep.{k}" for k in sorted(set(sweep) - set(sweep_keys))
        ]
        if unknown:
            raise ConfigError(
                f"unknown compare option(s) {', '.join(unknown)}; valid: predictors, baselines, "
                + ", ".join(f"sweep.{k}" for k in sweep_keys)
            )
        if "baselines" in options:
            options["baselines"] = list(options["baselines"] or [])
        if "predictor" in sweep:
            sweep["predictor"] = str(sweep["predictor"])
        if "support_scale" in sweep:
            sweep["support_scale"] = list(sweep["support_scale"] or [])
        out = cls(**options, sweep=SweepSettings(**sweep))
        if out.predictors != "all" and (not isinstance(out.predictors, list) or not out.predictors):
            raise ConfigError(
                f"compare.predictors must be 'all' or a non-empty list, got {out.predictors!r}"
            )
        scales = out.sweep.support_scale
        for value in scales:
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not value > 0:
                raise ConfigError(f"compare.sweep.support_scale must be numbers > 0, got {scales}")
        if len(set(scales)) != len(scales):
            raise ConfigError(f"compare.sweep.support_scale has duplicates: {scales}")
        sizes = out.sweep.train_sizes
        if sizes is None:
            out.sweep.train_sizes = [max(train_sizes)]
        elif not isinstance(sizes, list) or any(d not in train_sizes for d in sizes):
            raise ConfigError(
                f"compare.sweep.train_sizes must be a list of experiment.train_sizes "
                f"{list(train_sizes)}, got {sizes!r}"
            )
        return out


@dataclass(frozen=True)
class CompareJob:
    """The comparison's composed config, typed (the groups every row shares).

    Attributes:
        settings: the ``experiment`` group (seeds, demonstrations, boxes, workers).
        task: the ``task`` group.
        compare: the ``compare`` node.
    """

    settings: ExperimentSettings
    task: TaskConfig
    compare: CompareSettings

    @classmethod
    def from_cfg(cls, cfg: Any) -> CompareJob:
        """From a composed config (``experiment``, ``task`` and ``compare`` nodes), validated.

        The job's ``sequencer`` must be a learned one: the predictor rows run with it.

        Raises:
            ConfigError: a bad option of any of them, or ``sequencer=goal_nearest``.
        """
        if to_dict(cfg.get("sequencer")).get("kind") == GOAL_NEAREST:
            raise ConfigError(
                "the comparison runs the predictors with the job's sequencer, which must be a "
                "learned one (e.g. sequencer=coupled); goal_nearest is listed in "
                "compare.baselines"
            )
        settings = ExperimentSettings.from_cfg(cfg.experiment)
        task = TaskConfig.from_dict(cfg.task)
        compare = CompareSettings.from_cfg(cfg.get("compare"), settings.train_sizes)
        return cls(settings, task, compare)


def register_compare() -> None:
    """Store the ``compare`` node's schema (:data:`SCHEMA`) in Hydra's ConfigStore (idempotent)."""
    store_schema(SCHEMA, CompareSettings)


register_compare()
