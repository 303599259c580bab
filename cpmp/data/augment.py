"""Feature noise for robustness experiments ("1 % / 5 % feature noise").

The noise of feature ``j`` is i.i.d. Gaussian with standard deviation ``sigma * range_j``, where
``range_j`` is the feature's peak-to-peak range over the demonstrations (or given ranges), so
``sigma = 0.01`` means 1 % of each feature's range whatever its unit. Features with range 0
(constants such as a context that never varies) get no noise.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from cpmp.data.demonstration import Demonstration
from cpmp.errors import ConfigError, DataError


def _check_sigma(sigma: float) -> float:
    if isinstance(sigma, bool) or not isinstance(sigma, (int, float, np.integer, np.floating)):
        raise ConfigError(f"noise level sigma must be a number, got {sigma!r}")
    value = float(sigma)
    if not math.isfinite(value) or value < 0.0:
        raise ConfigError(
            f"noise level sigma must be finite and >= 0 (a fraction of each feature's range, "
            f"0.01 = 1 %), got {sigma!r}"
        )
    return value


def _check_ranges(ranges: np.ndarray | Sequence[float], d: int) -> np.ndarray:
    r = np.asarray(ranges, dtype=np.float64).reshape(-1)
    if r.shape != (d,):
        raise ConfigError(f"ranges must have one entry per feature ({d}), got shape {r.shape}")
    if not np.isfinite(r).all() or (r < 0.0).any():
        raise ConfigError("ranges must be finite and >= 0")
    return r


def feature_ranges(demos: Sequence[Demonstration]) -> np.ndarray:
    """Peak-to-peak range ``(d,)`` of each feature over all samples of ``demos`` [its units]."""
    demos = list(demos)
    if not demos:
        raise DataError("no demonstrations to measure feature ranges on; give at least one")
    widths = {d.n_features for d in demos}
    if len(widths) != 1:
        raise DataError(f"demonstrations have different feature counts {sorted(widths)}")
    return np.ptp(np.concatenate([d.features for d in demos], axis=0), axis=0)


def noisy_features(
    x: np.ndarray, sigma: float, ranges: np.ndarray | Sequence[float], rng: np.random.Generator
) -> np.ndarray:
    """``x (..., d)`` plus Gaussian noise of standard deviation ``sigma * ranges (d,)``.

    For closed-loop observation noise: call once per tick on the features handed to a policy.
    Returns a new array; ``x`` is not modified. Features with range 0 are returned unchanged.
    """
    s = _check_sigma(sigma)
    arr = np.asarray(x, dtype=np.float64)
    if arr.ndim == 0:
        raise ConfigError("x must have at least one dimension (..., d)")
    r = _check_ranges(ranges, arr.shape[-1])
    return arr + rng.standard_normal(arr.shape) * (s * r)


def add_feature_noise(
    demos: Sequence[Demonstration],
    sigma: float,
    seed: int,
    ranges: np.ndarray | Sequence[float] | None = None,
) -> list[Demonstration]:
    """Copies of ``demos`` with i.i.d. Gaussian noise on every feature sample.

    Args:
        demos: demonstrations sharing the feature count ``d``; not modified.
        sigma: noise standard deviation as a fraction of each feature's range (0.01 = 1 %);
            finite and >= 0. ``0`` returns unchanged copies.
        seed: seed of the :class:`numpy.random.Generator`; the same seed gives identical noise.
        ranges: ``(d,)`` feature ranges [feature units]; default: peak-to-peak over ``demos``.

    Returns:
        New demonstrations with the same time, labels, names and feature names; ``metadata``
        gains ``feature_noise`` (= ``sigma``). Features of range 0 stay exact.

    Raises:
        ConfigError: ``sigma`` or ``ranges`` is invalid.
    """
    s = _check_sigma(sigma)
    demos = list(demos)
    if not demos:
        return []
    r = feature_ranges(demos) if ranges is None else _check_ranges(ranges, demos[0].n_features)
    rng = np.random.default_rng(seed)
    out = []
    for demo in demos:
        x = demo.features.copy()
        if s > 0.0:
            x = noisy_features(x, s, r, rng)
        out.append(
            Demonstration(
                time=demo.time.copy(),
                features=x,
                labels={v: lab.copy() for v, lab in demo.labels.items()},
                feature_names=list(demo.feature_names or []),
                name=demo.name,
                metadata={**(demo.metadata or {}), "feature_noise": s},
            )
        )
    return out


__all__ = ["add_feature_noise", "feature_ranges", "noisy_features"]
