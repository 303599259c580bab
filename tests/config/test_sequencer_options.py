"""Sequencer options (:class:`cpmp.config.SequencerConfig`): non-finite values, unknown rules
and couplings, and out-of-range margins are refused with the option's name."""

from __future__ import annotations

import math

import pytest

from cpmp.config import SequencerConfig
from cpmp.errors import ConfigError


@pytest.mark.parametrize(
    "option",
    ["threshold", "patience", "min_improvement", "stall_time", "rest_speed", "recovery_threshold"],
)
@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf])
def test_non_finite_sequencer_options_are_refused(option, value):
    with pytest.raises(ConfigError, match=option):
        SequencerConfig(**{option: value})


def test_unknown_rule_and_coupling_are_refused():
    with pytest.raises(ConfigError, match="switch_rule"):
        SequencerConfig(switch_rule="eager")
    with pytest.raises(ConfigError, match="coupling"):
        SequencerConfig(coupling="strong")


@pytest.mark.parametrize("margin", [-0.1, 1.5, float("nan"), "0.2", True])
def test_progress_margin_is_validated(margin):
    with pytest.raises(ConfigError, match="progress_margin"):
        SequencerConfig(progress_margin=margin)
