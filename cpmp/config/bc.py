"""The options of the behaviour-cloning baseline (``conf/sequencer/bc.yaml``).

The baseline itself is :mod:`cpmp.baselines.bc`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass

from cpmp.config.predictors import SCALINGS
from cpmp.config.validation import OptionValue, finite_number
from cpmp.errors import ConfigError

KIND = "bc"
"""The ``kind`` of the ``sequencer`` config group entry that selects this baseline."""

CLASS_WEIGHTS = ("balanced", "none")
"""Values of :attr:`BCConfig.class_weight`."""


@dataclass(frozen=True)
class BCConfig:
    """Options of the behaviour-cloning baseline (``conf/sequencer/bc.yaml``).

    Attributes:
        gamma: RBF kernel parameter γ in ``exp(-γ ||s - x||²)`` on the scaled features
            [1 / scaled units²] (the progress predictors' ``klr`` default, 4.0).
        max_supports: support points of a node's classifier drawn evenly along its training
            activations, at most this many per node; every demonstrated switch tick is a
            support point besides.
        l2: weight of the ``½ l2 ||W||²`` penalty on the kernel weights (not the
            intercepts), added to the class-weighted mean cross-entropy.
        class_weight: ``balanced`` (each class of a node weighs as much in the loss as every
            other: a switch tick per activation against hundreds of stay ticks) or ``none``
            (every tick weighs 1).
        threshold: a variable switches at a tick where its most probable successor's
            probability exceeds this, in (0, 1).
        max_iter: Newton steps per node (the loss is convex; a fit usually converges in
            fewer).
        feature_scaling: the scaled feature space of the kernel and of the start's nearest
            neighbour (one of ``global``, ``none``, ``minmax``, ``standard``; see
            :class:`~cpmp.predictors.FeatureScaler`).
    """

    gamma: float = 4.0
    max_supports: int = 64
    l2: float = 1e-4
    class_weight: str = "balanced"
    threshold: float = 0.5
    max_iter: int = 50
    feature_scaling: str = "global"

    def __post_init__(self) -> None:
        for name in ("gamma", "l2", "threshold"):
            finite_number(getattr(self, name), f"bc option {name}")
        for name in ("max_supports", "max_iter"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ConfigError(f"bc {name} must be an integer >= 1, got {value!r}")
        if self.gamma <= 0:
            raise ConfigError(f"bc gamma must be > 0 [1/scaled units²], got {self.gamma}")
        if self.l2 < 0:
            raise ConfigError(f"bc l2 must be >= 0, got {self.l2}")
        if not 0.0 < self.threshold < 1.0:
            raise ConfigError(f"bc threshold must be in (0, 1), got {self.threshold}")
        if self.class_weight not in CLASS_WEIGHTS:
            raise ConfigError(
                f"bc class_weight must be one of {', '.join(CLASS_WEIGHTS)}, got "
                f"{self.class_weight!r}"
            )
        if self.feature_scaling not in SCALINGS:
            raise ConfigError(
                f"bc feature_scaling must be one of {', '.join(SCALINGS)}, got "
                f"{self.feature_scaling!r}"
            )


def bc_options(options: Mapping[str, OptionValue]) -> BCConfig:
    """Validated :class:`BCConfig` from a mapping.

    Raises:
        ConfigError: an unknown name (the message lists the valid ones) or a bad value.
    """
    valid = [f.name for f in dataclasses.fields(BCConfig)]
    unknown = sorted(set(options) - set(valid))
    if unknown:
        raise ConfigError(
            f"unknown option(s) {', '.join(unknown)} for sequencer=bc; valid options: "
            f"{', '.join(valid)}"
        )
    return BCConfig(**options)
