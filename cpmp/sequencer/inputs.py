"""Checks on what the sequencers are given: times, stamps, feature vectors, demonstrations.

Shared by :class:`~cpmp.sequencer.ConcurrentSequencer`, the batches of
:mod:`cpmp.sequencer.episode` and :class:`~cpmp.baselines.GoalNearestSequencer`, so that the same
mistake gives the same message whichever is used; each raises :class:`~cpmp.errors.DataError`
saying what is wrong.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import torch

from cpmp.data import Demonstration
from cpmp.errors import DataError


def checked_time(t: float) -> float:
    """``t`` [s] as a float; :class:`~cpmp.errors.DataError` unless it is finite."""
    t = float(t)
    if not math.isfinite(t):
        raise DataError(f"time must be finite, got t={t}")
    return t


def checked_stamp(stamp: float | None, t: float) -> float | None:
    """A measurement time ``stamp`` [s] of features given at time ``t`` [s], checked.

    Args:
        stamp: when the features were measured, on the caller's clock; ``None``: unknown.
        t: the tick's time [s] (checked).

    Returns:
        ``stamp`` as a float, or ``None``.

    Raises:
        DataError: ``stamp`` is not finite or is later than ``t``.
    """
    if stamp is None:
        return None
    stamp = float(stamp)
    if not math.isfinite(stamp):
        raise DataError(f"a measurement stamp must be finite, got stamp={stamp}")
    if stamp > t + 1e-9:
        raise DataError(
            f"features measured at stamp={stamp} are given at t={t}: a stamp is the time the "
            "features were measured, on the same clock as t, at or before t"
        )
    return stamp


def checked_features(
    x: np.ndarray | torch.Tensor, feature_names: Sequence[str], finite: bool = True
) -> np.ndarray:
    """Features ``x (..., d)`` as a float64 array, checked.

    Args:
        x: the features, NumPy or torch.
        feature_names: the ``d`` names the features must match in number.
        finite: whether every feature must be finite.

    Returns:
        ``x`` as float64 ``(..., d)``.

    Raises:
        DataError: the last axis is not ``d`` long, or (with ``finite``) a feature is not
            finite.
    """
    if isinstance(x, torch.Tensor):
        x = x.detach().cpu().numpy()
    xn = np.asarray(x, dtype=np.float64)
    if xn.ndim == 0 or xn.shape[-1] != len(feature_names):
        raise DataError(
            f"expected features with {len(feature_names)} entries "
            f"({', '.join(list(feature_names)[:4])}, ...), got shape {tuple(xn.shape)}"
        )
    if finite and not np.isfinite(xn).all():
        raise DataError("features contain NaN or inf; the sequencer needs finite features")
    return xn


def checked_demonstrations(
    demos: Sequence[Demonstration], fitter: str
) -> tuple[list[Demonstration], list[str]]:
    """The demonstrations as a list and their shared feature names.

    Args:
        demos: the demonstrations.
        fitter: names the caller in the message when there are none (e.g.
            ``"ConcurrentSequencer.fit"``).

    Returns:
        The demonstrations and their feature names.

    Raises:
        DataError: no demonstrations, or two with different feature names.
    """
    demos = list(demos)
    if not demos:
        raise DataError(f"{fitter} needs at least one demonstration, got none")
    feature_names = list(demos[0].feature_names)
    for m, demo in enumerate(demos):
        if list(demo.feature_names) != feature_names:
            raise DataError(
                f"{demo.name or f'demonstration {m}'} has features {list(demo.feature_names)}"
                f" but the first demonstration has {feature_names}; all must match"
            )
    return demos, feature_names
