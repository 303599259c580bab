"""What a sequencer is fitted with, typed: predictor kind and options, rule, trainer, seed.

Everything :meth:`cpmp.sequencer.ConcurrentSequencer.fit` takes besides the demonstrations
(and, at run time, the validation demonstrations and the logger).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass, field

from cpmp.config.predictors import (
    REMOVED_OPTIONS,
    PredictorConfig,
    predictor_config,
    predictor_config_class,
    predictor_option_names,
)
from cpmp.config.sequencer import (
    REMOVED_SEQUENCER_OPTIONS,
    SequencerConfig,
    existing_sequencer_options,
)
from cpmp.config.trainer import TrainerConfig
from cpmp.config.validation import OptionValue
from cpmp.errors import ConfigError

FIT_OPTIONS = ("seed", "variables", "subsample", "repair_glitches")
"""Keyword options of ``fit`` that belong to the fit itself (:class:`FitConfig`)."""


@dataclass(frozen=True)
class FitConfig:
    """What a sequencer is fitted with.

    Attributes:
        predictor: the predictor kind (``klr``, ``klr_full``, ``klr_sparse``, ``mlp``, the
            baselines ``sklearn_klr``, ``regression_clip``, ``time_phase``, ``dtw``).
        predictor_config: its options, an instance of that kind's options class
            (:data:`~cpmp.config.PREDICTOR_CONFIGS`; ``None``: the kind's defaults).
        sequencer: the transition rule.
        trainer: the Lightning fit.
        seed: the seed of every random draw of the fit (initial weights).
        variables: the control variables to model (``None``: every labelled one).
        subsample: train on every k-th sample of each activation (its last sample always
            kept; expected progress is computed on the full trajectory first), >= 1.
        repair_glitches: relabel one or two samples of another MP between two samples of
            the same MP with that MP before the graphs are built
            (:func:`cpmp.sequencer.glitches.repair_glitches`; each repair is listed in
            ``fit_summary.label_glitches``); ``False``: keep them as nodes.
    """

    predictor: str = "klr"
    predictor_config: PredictorConfig | None = None
    sequencer: SequencerConfig = field(default_factory=SequencerConfig)
    trainer: TrainerConfig = field(default_factory=TrainerConfig)
    seed: int = 0
    variables: Sequence[str] | None = None
    subsample: int = 1
    repair_glitches: bool = True

    def __post_init__(self) -> None:
        cls = predictor_config_class(self.predictor)
        if self.predictor_config is None:
            object.__setattr__(self, "predictor_config", cls())
        elif type(self.predictor_config) is not cls:
            raise ConfigError(
                f"predictor {self.predictor!r} takes a {cls.__name__}, got a "
                f"{type(self.predictor_config).__name__}"
            )
        object.__setattr__(self, "seed", int(self.seed))
        subsample = self.subsample
        if isinstance(subsample, bool) or not isinstance(subsample, int) or subsample < 1:
            raise ConfigError(f"subsample must be an integer >= 1, got {subsample!r}")
        if self.variables is not None:
            object.__setattr__(self, "variables", tuple(self.variables))
        if not isinstance(self.repair_glitches, bool):
            raise ConfigError(
                f"repair_glitches must be true or false, got {self.repair_glitches!r}"
            )

    @classmethod
    def from_options(cls, predictor: str = "klr", **options: OptionValue) -> FitConfig:
        """The keyword form: ``options`` routed by name to the part that has them.

        Args:
            predictor: the predictor kind.
            **options: options of the predictor, the :class:`SequencerConfig`, the
                :class:`TrainerConfig` and the fit's own (:data:`FIT_OPTIONS`).

        Returns:
            The typed fit configuration.

        Raises:
            ConfigError: an unknown name (the message lists the valid ones) or a bad value.
        """
        names = {
            "predictor": set(predictor_option_names(predictor)),
            "sequencer": {f.name for f in dataclasses.fields(SequencerConfig)},
            "trainer": {f.name for f in dataclasses.fields(TrainerConfig)},
            "fit": set(FIT_OPTIONS),
        }
        routed: dict[str, dict[str, OptionValue]] = {part: {} for part in names}
        for key, value in options.items():
            part = next((p for p, valid in names.items() if key in valid), None)
            if part is None and key in REMOVED_OPTIONS.get(predictor, {}):
                part = "predictor"  # predictor_config names it as removed
            if part is None and key in REMOVED_SEQUENCER_OPTIONS:
                part = "sequencer"  # existing_sequencer_options names it as removed
            if part is None:
                valid = sorted(set().union(*names.values()))
                raise ConfigError(
                    f"unknown option {key!r} for ConcurrentSequencer.fit with predictor "
                    f"{predictor!r}; valid options: {', '.join(valid)}"
                )
            routed[part][key] = value
        return cls(
            predictor,
            predictor_config(predictor, **routed["predictor"]),
            SequencerConfig(**existing_sequencer_options(routed["sequencer"])),
            TrainerConfig(**routed["trainer"]),
            **routed["fit"],
        )
