"""Expected progress along an activation (paper eq. 1) and support-point placement.

The expected progress of sample ``i`` is the L1 line integral of the feature trajectory up to
``i``, normalised so that the last sample of the activation has progress 1. It grows with the
distance travelled in feature space, not with time.
"""

from __future__ import annotations

import math

import numpy as np

from cpmp.errors import ConfigError, DataError


def _as_trajectory(features: np.ndarray) -> np.ndarray:
    x = np.asarray(features, dtype=np.float64)
    if x.ndim != 2:
        raise DataError(f"features must have shape (n, d), got shape {x.shape}")
    if x.shape[0] == 0:
        raise DataError("features must hold at least one sample, got 0")
    if not np.all(np.isfinite(x)):
        raise DataError("features contain NaN or inf; clean or drop those samples")
    return x


def cumulative_path_length(features: np.ndarray) -> np.ndarray:
    """Unnormalised eq. 1: ``(n,)`` running L1 path length, starting at 0."""
    x = _as_trajectory(features)
    steps = np.abs(np.diff(x, axis=0)).sum(axis=1)
    return np.concatenate([[0.0], np.cumsum(steps)])


def path_length(features: np.ndarray) -> float:
    """Total L1 path length of a trajectory ``(n, d)`` (the final ϕ before normalising)."""
    return float(cumulative_path_length(features)[-1])


def expected_progress(features: np.ndarray, time: np.ndarray | None = None) -> np.ndarray:
    """Expected progress ``(n,)`` in [0, 1] of one activation ``(n, d)`` (paper eq. 1).

    Monotone non-decreasing, first value 0 and last value 1 (for ``n >= 2``).

    Zero path length (features constant while the MP was active) carries no information about
    progress in feature space. Rather than dividing by zero, progress then falls back to
    normalised time (``time`` given) or normalised sample index, so it still runs from 0 to 1.
    A single-sample activation has progress ``[1.0]``: it is entered and left at once.
    """
    cum = cumulative_path_length(features)
    n = cum.shape[0]
    if n == 1:
        return np.ones(1)
    total = cum[-1]
    if total > 0.0:
        phi = cum / total
        phi[-1] = 1.0
        return phi
    if time is not None:
        t = np.asarray(time, dtype=np.float64)
        if t.shape != (n,):
            raise DataError(f"time must have shape ({n},) to match features, got {t.shape}")
        span = t[-1] - t[0]
        if span > 0.0:
            return (t - t[0]) / span
    return np.linspace(0.0, 1.0, n)


def support_count(length: float, scale: float, min_support: int, max_support: int | None) -> int:
    """Number of support points for an activation of L1 path length ``length``.

    ``max(min_support, ceil(scale * length))``, capped at ``max_support`` when given.
    """
    if scale < 0 or min_support < 1:
        raise ConfigError(
            f"support_scale must be >= 0 and min_support >= 1, got {scale} and {min_support}"
        )
    count = max(min_support, math.ceil(scale * length))
    if max_support is not None:
        count = min(count, max_support)
    return count


def _count_for_length(
    length: float, scale: float, min_support: int, max_support: int | None
) -> int:
    """:func:`support_count`, except that a trajectory of zero length gets one point."""
    return support_count(length, scale, min_support, max_support) if length > 0.0 else 1


def support_point_count(
    features: np.ndarray,
    scale: float = 2.0,
    min_support: int = 3,
    max_support: int | None = None,
) -> int:
    """How many points :func:`support_points` places along ``features (n, d)``, without
    placing them."""
    return _count_for_length(path_length(features), scale, min_support, max_support)


def support_points(
    features: np.ndarray,
    scale: float = 2.0,
    min_support: int = 3,
    max_support: int | None = None,
) -> np.ndarray:
    """Support points ``(S, d)`` equidistant by L1 arc length along a trajectory ``(n, d)``.

    ``S = max(min_support, ceil(scale * L))`` where ``L`` is the L1 path length; the first and
    last points are the trajectory's ends and the others are interpolated linearly between
    samples. A trajectory of zero length yields a single support point (its constant value).
    """
    x = _as_trajectory(features)
    cum = cumulative_path_length(x)
    total = cum[-1]
    count = _count_for_length(total, scale, min_support, max_support)
    if total <= 0.0:
        return x[:1].copy()
    targets = np.linspace(0.0, total, count)
    idx = np.clip(np.searchsorted(cum, targets, side="right") - 1, 0, len(cum) - 2)
    seg = cum[idx + 1] - cum[idx]
    frac = np.divide(targets - cum[idx], seg, out=np.zeros_like(targets), where=seg > 0)
    frac = np.clip(frac, 0.0, 1.0)
    return x[idx] + frac[:, None] * (x[idx + 1] - x[idx])


LABELS = ("path", "time")
"""Kinds of training label: ``path`` (eq. 1, the L1 line integral) or ``time`` (normalised
elapsed time, the usual phase variable; the label ablation of eq. 1)."""


def time_labels(time: np.ndarray) -> np.ndarray:
    """Normalised elapsed time ``(n,)`` in [0, 1] of one activation sampled at ``time (n,)`` [s].

    ``(t - t_0) / (t_{n-1} - t_0)``: linear in time, first value 0 and last value 1 (for
    ``n >= 2``), whatever the features did. A single sample has ``[1.0]`` (as in
    :func:`expected_progress`); a zero time span falls back to the normalised sample index.
    """
    t = np.asarray(time, dtype=np.float64)
    if t.ndim != 1 or t.shape[0] == 0:
        raise DataError(f"time must have shape (n,) with n >= 1, got shape {t.shape}")
    if not np.all(np.isfinite(t)):
        raise DataError("time contains NaN or inf; clean or drop those samples")
    n = t.shape[0]
    if n == 1:
        return np.ones(1)
    span = t[-1] - t[0]
    if span <= 0.0:
        return np.linspace(0.0, 1.0, n)
    phase = (t - t[0]) / span
    phase[-1] = 1.0
    return phase


def progress_labels(features: np.ndarray, time: np.ndarray, kind: str = "path") -> np.ndarray:
    """Training labels ``(n,)`` of one activation ``features (n, d)``, ``time (n,)`` [s]:
    :func:`expected_progress` for ``kind="path"``, :func:`time_labels` for ``kind="time"``."""
    if kind == "path":
        return expected_progress(features, time)
    if kind == "time":
        labels = time_labels(time)
        if labels.shape[0] != _as_trajectory(features).shape[0]:
            raise DataError(
                f"time has {labels.shape[0]} samples but features have "
                f"{np.shape(features)[0]}; they must match"
            )
        return labels
    raise ConfigError(f"progress labels must be one of {', '.join(LABELS)}, got {kind!r}")
