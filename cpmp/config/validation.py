"""Checks shared by the option classes' ``__post_init__`` (and the synthetic tasks' options)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import TypeAlias

from cpmp.errors import ConfigError

OptionValue: TypeAlias = (
    "str | int | float | bool | Sequence[str] | Sequence[float] | Mapping[str, float] | None"
)
"""A value an option of these classes takes, given by name (``fit(**options)``, a mapping).

A number, a string, a flag, ``None``, a list (a range, levels, hidden sizes, device indices,
variables) or a mapping of numbers (the task's ``finger_goals``); the classes check it.
"""


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
