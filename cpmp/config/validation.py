"""Checks shared by the option classes' ``__post_init__`` (and the synthetic tasks' options)."""

from __future__ import annotations

import math

from cpmp.errors import ConfigError


def finite_number(value: object, what: str) -> float:
    """``value`` as a float.

    Args:
        value: the option's value; ``bool`` is not a number here.
        what: the option as the message names it (``"sequencer option threshold"``).

    Raises:
        ConfigError: ``value`` is not an ``int``/``float`` or not finite.
    """
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConfigError(f"{what} must be a number, got {value!r}")
    if not math.isfinite(value):
        raise ConfigError(f"{what} must be finite, got {value}")
    return float(value)
