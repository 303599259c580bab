"""The options of the goal-nearest baseline (``conf/sequencer/goal_nearest.yaml``).

The baseline itself is :mod:`cpmp.baselines.goal_nearest`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass

from cpmp.config.predictors import SCALINGS
from cpmp.config.validation import OptionValue, finite_number
from cpmp.errors import ConfigError

KIND = "goal_nearest"
"""The ``kind`` of the ``sequencer`` config group entry that selects this baseline."""


@dataclass
class GoalNearestConfig:
    """Options of the goal-nearest baseline (``conf/sequencer/goal_nearest.yaml``).

    Attributes:
        speed_threshold: an MP has converged while each of its moving features changes slower
            than this [scaled feature units / s].
        hold_time: the MP must stay converged this long before its variable switches [s].
        motion_share: a feature moves during an MP if its L1 path over the MP's training
            activations is at least this fraction of the largest feature's path, in [0, 1].
        feature_scaling: the scaled feature space of velocities and distances (one of
            ``global``, ``none``, ``minmax``, ``standard``; see
            :class:`~cpmp.predictors.FeatureScaler`).
    """

    speed_threshold: float = 0.02
    hold_time: float = 0.1
    motion_share: float = 0.1
    feature_scaling: str = "global"

    def __post_init__(self) -> None:
        for name in ("speed_threshold", "hold_time", "motion_share"):
            finite_number(getattr(self, name), f"goal_nearest option {name}")
        if self.speed_threshold <= 0:
            raise ConfigError(
                f"goal_nearest speed_threshold must be > 0 [scaled units/s], got "
                f"{self.speed_threshold}"
            )
        if self.hold_time < 0:
            raise ConfigError(f"goal_nearest hold_time must be >= 0 s, got {self.hold_time}")
        if not 0.0 <= self.motion_share <= 1.0:
            raise ConfigError(
                f"goal_nearest motion_share must be in [0, 1], got {self.motion_share}"
            )
        if self.feature_scaling not in SCALINGS:
            raise ConfigError(
                f"goal_nearest feature_scaling must be one of {', '.join(SCALINGS)}, got "
                f"{self.feature_scaling!r}"
            )


def goal_nearest_options(options: Mapping[str, OptionValue]) -> GoalNearestConfig:
    """Validated :class:`GoalNearestConfig` from a mapping.

    Raises:
        ConfigError: an unknown name (the message lists the valid ones) or a bad value.
    """
    valid = [f.name for f in dataclasses.fields(GoalNearestConfig)]
    unknown = sorted(set(options) - set(valid))
    if unknown:
        raise ConfigError(
            f"unknown option(s) {', '.join(unknown)} for sequencer=goal_nearest; valid "
            f"options: {', '.join(valid)}"
        )
    return GoalNearestConfig(**options)
