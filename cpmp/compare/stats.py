"""Bootstrap intervals over seeds and episodes, and paired differences between rows.

Every number of the comparison is a weighted mean of *units* grouped by seed: a completion
rate is the mean of one 0/1 value per closed-loop episode, a held-out MAE the mean of each
held-out demonstration's MAE weighted by its samples (so that it equals the MAE over all
samples), a fit time the mean of one value per seed. Its interval is a hierarchical
percentile bootstrap: each replicate draws the seeds with replacement, then, inside every
drawn seed, that seed's units with replacement, and takes the weighted mean of what it drew;
the interval is the ``(1 - level) / 2`` and ``(1 + level) / 2`` quantiles of the replicates.
Both sources of variation count: which training data a seed drew and which episodes it ran.

Two rows run on the same seeds and the same episodes (the same boxes, the same held-out
demonstrations) are *paired*: :func:`paired_difference` draws one set of indices per
replicate and applies it to both rows, so the interval of their difference leaves out the
variation they share (an episode every row completes says nothing about their difference).
A difference is *significant* when its interval excludes 0 and a paired sign-flip
permutation test (:func:`sign_flip_p`) agrees at the same level. The second condition is there
because a percentile bootstrap is too sure of a difference that rests on a few episodes: when
``k`` of ``n`` paired episodes differ, all in one direction, a replicate misses all ``k`` with
probability about ``exp(-k)``, so the interval excludes 0 from ``k = 4`` on, where the exact
sign test wants ``k = 6`` (p = 0.031). Each test is at its own level: no correction for the
number of pairs a table shows.

Every function takes a seed; the same seed gives the same interval.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TypedDict

import numpy as np

from cpmp.errors import ConfigError, DataError

_CHUNK = 256
"""Replicates drawn at once (bounds the memory of one draw: chunk x seeds x units floats)."""


@dataclass(frozen=True)
class SeedUnits:
    """One seed's units of one number.

    Attributes:
        values: ``(n,)`` the units' values (an episode's 0/1 outcome, a demonstration's MAE).
        weights: ``(n,)`` their weights, > 0 (a demonstration's sample count; 1 for episodes).
    """

    values: np.ndarray
    weights: np.ndarray

    @classmethod
    def of(
        cls,
        values: Sequence[float] | np.ndarray,
        weights: Sequence[float] | np.ndarray | None = None,
    ) -> SeedUnits:
        """Units from values ``(n,)`` and weights ``(n,)`` (``None``: all 1), checked.

        Raises:
            DataError: no units, non-finite values, or weights of another length or not > 0.
        """
        v = np.asarray(values, dtype=np.float64).reshape(-1)
        w = np.ones_like(v) if weights is None else np.asarray(weights, np.float64).reshape(-1)
        if v.size == 0:
            raise DataError("a seed without units has no mean: leave the seed out")
        if w.shape != v.shape:
            raise DataError(f"{v.size} values but {w.size} weights")
        if not np.all(np.isfinite(v)) or not np.all(np.isfinite(w) & (w > 0)):
            raise DataError("unit values must be finite and weights finite and > 0")
        return cls(v, w)

    def __len__(self) -> int:
        """The number of units."""
        return int(self.values.size)


@dataclass(frozen=True)
class BootstrapOptions:
    """How intervals are drawn.

    Attributes:
        samples: bootstrap replicates.
        level: the interval's coverage, in (0, 1).
        seed: seeds the replicates' draws.
    """

    samples: int = 2000
    level: float = 0.95
    seed: int = 0

    def __post_init__(self) -> None:
        if (
            isinstance(self.samples, bool)
            or not isinstance(self.samples, int)
            or self.samples < 100
        ):
            raise ConfigError(f"bootstrap samples must be an integer >= 100, got {self.samples!r}")
        if not 0.5 <= self.level < 1.0:
            raise ConfigError(f"bootstrap level must lie in [0.5, 1), got {self.level!r}")
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise ConfigError(f"bootstrap seed must be a non-negative integer, got {self.seed!r}")


class IntervalRecord(TypedDict):
    """An :class:`Interval` as ``compare.json`` holds it (:meth:`Interval.to_dict`)."""

    estimate: float
    low: float
    high: float
    level: float
    seeds: int
    units: int


@dataclass(frozen=True)
class Interval:
    """A number with its bootstrap interval.

    Attributes:
        estimate: the weighted mean over every unit of every seed (a difference: of the two).
        low: the interval's lower end.
        high: its upper end.
        level: its coverage.
        seeds: the seeds it pools.
        units: the units it pools (over all seeds).
    """

    estimate: float
    low: float
    high: float
    level: float
    seeds: int
    units: int

    def excludes(self, value: float = 0.0) -> bool:
        """Whether ``value`` lies outside ``[low, high]`` (for a difference: significant)."""
        return bool(value < self.low or value > self.high)

    def scaled(self, factor: float) -> Interval:
        """The same interval in other units (``factor > 0``: a rate as a percentage)."""
        return Interval(
            self.estimate * factor,
            self.low * factor,
            self.high * factor,
            self.level,
            self.seeds,
            self.units,
        )

    def to_dict(self) -> IntervalRecord:
        """``{"estimate", "low", "high", "level", "seeds", "units"}`` for JSON."""
        return {
            "estimate": self.estimate,
            "low": self.low,
            "high": self.high,
            "level": self.level,
            "seeds": self.seeds,
            "units": self.units,
        }


def pooled_mean(seeds: Sequence[SeedUnits]) -> float:
    """The weighted mean of every unit of every seed.

    Raises:
        DataError: no seeds.
    """
    if not seeds:
        raise DataError("no seeds to pool")
    values = np.concatenate([s.values for s in seeds])
    weights = np.concatenate([s.weights for s in seeds])
    return float(np.sum(values * weights) / np.sum(weights))


def replicates(rows: Sequence[Sequence[SeedUnits]], samples: int, seed: int) -> np.ndarray:
    """Hierarchical bootstrap replicates of each row's weighted mean, drawn jointly.

    Every replicate draws ``S`` seed indices with replacement, then for each drawn seed its
    units with replacement; the same indices serve every row (rows are paired).

    Args:
        rows: ``k`` rows, each ``S`` seeds' units; row ``j``'s seed ``s`` has as many units as
            every other row's seed ``s``.
        samples: the number of replicates ``B``.
        seed: seeds the draws.

    Returns:
        ``(B, k)`` the rows' weighted means in each replicate.

    Raises:
        DataError: no rows or seeds, or rows whose seeds differ in their unit counts.
    """
    if not rows or not rows[0]:
        raise DataError("nothing to resample: no rows or no seeds")
    n = np.array([len(s) for s in rows[0]])
    for row in rows[1:]:
        if len(row) != len(n) or any(len(s) != m for s, m in zip(row, n, strict=True)):
            raise DataError(
                "paired rows must have the same seeds and units per seed, got "
                f"{[len(s) for s in rows[0]]} and {[len(s) for s in row]}"
            )
    k, n_seeds, width = len(rows), len(n), int(n.max())
    values = np.zeros((k, n_seeds, width))
    weights = np.zeros((k, n_seeds, width))
    for j, row in enumerate(rows):
        for s, units in enumerate(row):
            values[j, s, : n[s]] = units.values
            weights[j, s, : n[s]] = units.weights
    rng = np.random.default_rng(seed)
    out = np.empty((samples, k))
    columns = np.arange(width)
    for first in range(0, samples, _CHUNK):
        b = min(_CHUNK, samples - first)
        drawn = rng.integers(0, n_seeds, size=(b, n_seeds))  # (b, S) seed indices
        counts = n[drawn]  # (b, S) units of each drawn seed
        units = np.floor(rng.random((b, n_seeds, width)) * counts[..., None]).astype(np.int64)
        mask = columns < counts[..., None]  # (b, S, width): only the drawn seed's own units
        for j in range(k):
            w = weights[j][drawn[..., None], units] * mask
            v = values[j][drawn[..., None], units]
            out[first : first + b, j] = np.sum(v * w, axis=(1, 2)) / np.sum(w, axis=(1, 2))
    return out


def sign_flip_p(a: Sequence[SeedUnits], b: Sequence[SeedUnits], samples: int, seed: int) -> float:
    """The two-sided p-value of a paired sign-flip permutation test of ``mean(a) - mean(b)``.

    Under the null hypothesis the two rows are exchangeable on every unit, so each unit's
    difference is as likely negated: the statistic, the weighted mean of the differences, is
    recomputed with every unit's sign flipped at random ``samples`` times. With 0/1 units this
    is the exact sign test (McNemar's) on the episodes the rows disagree on, up to Monte Carlo
    error.

    Args:
        a: one row's units per seed.
        b: the other row's, paired (same seeds, same unit counts; weights are ``a``'s).
        samples: random sign flips.
        seed: seeds them.

    Returns:
        ``(1 + #{|flipped| >= |observed|}) / (1 + samples)``, in (0, 1].

    Raises:
        DataError: the rows are not paired.
    """
    if [len(s) for s in a] != [len(s) for s in b]:
        raise DataError(
            "paired rows must have the same seeds and units per seed, got "
            f"{[len(s) for s in a]} and {[len(s) for s in b]}"
        )
    diff = np.concatenate([x.values - y.values for x, y in zip(a, b, strict=True)])
    weights = np.concatenate([x.weights for x in a])
    observed = abs(float(np.sum(weights * diff)))
    moving = diff != 0.0  # units that agree add nothing, whatever their sign
    wd = (weights * diff)[moving]
    rng = np.random.default_rng(seed)
    exceed = 0
    for first in range(0, samples, _CHUNK):
        n = min(_CHUNK, samples - first)
        signs = rng.integers(0, 2, size=(n, wd.size)) * 2 - 1
        exceed += int(np.sum(np.abs(signs @ wd) >= observed * (1 - 1e-12)))
    return (1 + exceed) / (1 + samples)


def _quantiles(draws: np.ndarray, level: float) -> tuple[float, float]:
    """The percentile interval ``[(1 - level) / 2, (1 + level) / 2]`` of ``draws (B,)``."""
    low, high = np.quantile(draws, [(1.0 - level) / 2.0, (1.0 + level) / 2.0])
    return float(low), float(high)


def interval(seeds: Sequence[SeedUnits], options: BootstrapOptions | None = None) -> Interval:
    """The weighted mean of ``seeds``' units with its hierarchical bootstrap interval.

    Args:
        seeds: each seed's units.
        options: replicates, level and seed (default :class:`BootstrapOptions`).

    Returns:
        The interval.

    Raises:
        DataError: no seeds.
    """
    options = options or BootstrapOptions()
    draws = replicates([seeds], options.samples, options.seed)[:, 0]
    low, high = _quantiles(draws, options.level)
    units = sum(len(s) for s in seeds)
    return Interval(pooled_mean(seeds), low, high, options.level, len(seeds), units)


def paired_difference(
    a: Sequence[SeedUnits], b: Sequence[SeedUnits], options: BootstrapOptions | None = None
) -> Interval:
    """Row ``a``'s weighted mean minus row ``b``'s, with the paired bootstrap interval.

    Args:
        a: one row's units per seed.
        b: the other row's, on the same seeds and units (unit ``i`` of seed ``s`` is the same
            episode or demonstration in both).
        options: replicates, level and seed (default :class:`BootstrapOptions`).

    Returns:
        The difference ``a - b`` and its interval.

    Raises:
        DataError: the rows are not paired (other seeds or unit counts).
    """
    options = options or BootstrapOptions()
    draws = replicates([a, b], options.samples, options.seed)
    low, high = _quantiles(draws[:, 0] - draws[:, 1], options.level)
    units = sum(len(s) for s in a)
    return Interval(pooled_mean(a) - pooled_mean(b), low, high, options.level, len(a), units)
