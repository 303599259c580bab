"""Expected progress along an activation (paper eq. 1) and support-point placement.

The expected progress of sample ``i`` is the L1 line integral of the feature trajectory up to
``i``, normalised so that the last sample of the activation has progress 1. It grows with the
distance travelled in feature space, not with time.

Noise on the features adds L1 length at every sample, so on noisy demonstrations the integral
measures the noise rather than the motion (the labels drift towards normalised time and the
support count grows with the noise). With ``noise="auto"`` the integral is taken along a
denoised trajectory instead (:func:`denoise_trajectory`): each feature's white-noise level is
estimated from the activation itself (:func:`white_noise_std`: 0 for a trajectory that is
smooth at the sampling rate, which then stays exactly as recorded), and total-variation
denoising, whose penalty is the very per-feature L1 length that eq. 1 sums, removes it.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Literal, get_args

import numpy as np

from cpmp.errors import ConfigError, DataError

if TYPE_CHECKING:  # annotation only: the options (cpmp.config) import this module, and the
    # command line composes them before h5py and torch (which cpmp.data loads) are needed
    from cpmp.data import Demonstration


def _as_trajectory(features: np.ndarray) -> np.ndarray:
    x = np.asarray(features, dtype=np.float64)
    if x.ndim != 2:
        raise DataError(f"features must have shape (n, d), got shape {x.shape}")
    if x.shape[0] == 0:
        raise DataError("features must hold at least one sample, got 0")
    if not np.all(np.isfinite(x)):
        raise DataError("features contain NaN or inf; clean or drop those samples")
    return x


PathNoise = Literal["auto", "none"]
"""How eq. 1 treats noise on the features (see :data:`PATH_NOISE`)."""
PATH_NOISE: tuple[PathNoise, ...] = get_args(PathNoise)
"""Values of ``noise`` (the predictors' ``path_noise`` option): ``none`` measures eq. 1 on the
features as recorded (the paper); ``auto`` on :func:`denoise_trajectory`'s estimate of the
noise-free trajectory, which is the recorded one wherever no white noise is detected."""

_MAD_TO_STD = 1.482602218505602
"""``1 / Φ⁻¹(3/4)``: median absolute deviation -> standard deviation of a normal law."""


def _check_noise(noise: str) -> PathNoise:
    if noise not in PATH_NOISE:
        raise ConfigError(f"path noise must be one of {', '.join(PATH_NOISE)}, got {noise!r}")
    return noise


def _robust_power(u: np.ndarray) -> np.ndarray:
    """Mean square about zero ``(d,)`` of zero-mean samples ``u (m, d)``, robustly.

    From their median absolute value: robust to the few large values of jumps and contact
    events.
    """
    return (_MAD_TO_STD * np.median(np.abs(u), axis=0)) ** 2


def white_noise_std(features: np.ndarray) -> np.ndarray:
    """Standard deviation ``(d,)`` of the white noise on each feature of a trajectory ``(n, d)``.

    White: independent from sample to sample; in feature units, ``0`` where none is detected.

    Two filters cancel every straight line ``a + b t`` and respond to white noise of standard
    deviation σ with variance 20σ² and 4σ²: the third difference ``x₃ - 3x₂ + 3x₁ - x₀``, which
    also cancels a steady curvature, and ``x₃ - x₂ - x₁ + x₀``, which does not. So
    ``σ² = (P(third) - P(bent)) / 16`` with ``P`` the robust mean square: unbiased for white
    noise, and negative (reported as 0) for a trajectory that is smooth at the sampling rate,
    whose curvature only ``bent`` sees. Estimates at or below the filters' own float64
    rounding error, ``8 ε max|x_j|`` (8 = the sum of the third difference's absolute
    coefficients), are rounding, not noise, and also give 0; so do fewer than 4 samples.
    """
    x = _as_trajectory(features)
    if x.shape[0] < 4:
        return np.zeros(x.shape[1])
    third = x[3:] - 3.0 * x[2:-1] + 3.0 * x[1:-2] - x[:-3]
    bent = x[3:] - x[2:-1] - x[1:-2] + x[:-3]
    sigma = np.sqrt(np.maximum((_robust_power(third) - _robust_power(bent)) / 16.0, 0.0))
    rounding = 8.0 * np.finfo(np.float64).eps * np.max(np.abs(x), axis=0)
    return np.where(sigma > rounding, sigma, 0.0)


def tv_denoise(signal: np.ndarray, lam: float) -> np.ndarray:
    """Total-variation denoising of one feature ``signal (n,)``.

    The minimiser ``(n,)`` of ``½ Σ (y_i - signal_i)² + lam Σ |y_{i+1} - y_i|`` (``lam >= 0``,
    in the signal's units). Exact, by Johnson's dynamic programme (J. Comput. Graph. Stat. 22,
    2013), O(n). ``lam = 0`` returns a copy; a large ``lam`` returns the constant mean.
    """
    y = [float(v) for v in np.asarray(signal, dtype=np.float64).reshape(-1)]
    n = len(y)
    if n <= 1 or not lam > 0.0:
        return np.array(y)
    # The derivative of the forward message (the cost of y_0..y_k as a function of y_k) is
    # piecewise linear: its knots, with the slope and offset each adds, live in a deque
    # knot[left..right]; [low[k], high[k]] is where y_k goes given y_{k+1} (back-pointers).
    knot, slope, offset = [0.0] * (2 * n), [0.0] * (2 * n), [0.0] * (2 * n)
    low, high = [0.0] * (n - 1), [0.0] * (n - 1)
    low[0], high[0] = y[0] - lam, y[0] + lam
    left, right = n - 1, n
    knot[left], knot[right] = low[0], high[0]
    slope[left], offset[left] = 1.0, lam - y[0]
    slope[right], offset[right] = -1.0, lam + y[0]
    for k in range(1, n - 1):
        a_lo, b_lo = 1.0, -lam - y[k]  # the derivative left of the first knot: a·b + ...
        lo = left
        while lo <= right and a_lo * knot[lo] + b_lo <= -lam:
            a_lo += slope[lo]
            b_lo += offset[lo]
            lo += 1
        a_hi, b_hi = -1.0, -lam + y[k]  # ... and right of the last knot
        hi = right
        while hi >= lo and -a_hi * knot[hi] - b_hi >= lam:
            a_hi += slope[hi]
            b_hi += offset[hi]
            hi -= 1
        low[k] = (-lam - b_lo) / a_lo
        high[k] = (lam + b_hi) / -a_hi
        left, right = lo - 1, hi + 1
        knot[left], slope[left], offset[left] = low[k], a_lo, b_lo + lam
        knot[right], slope[right], offset[right] = high[k], a_hi, b_hi + lam
    a_lo, b_lo = 1.0, -lam - y[n - 1]
    lo = left
    while lo <= right and a_lo * knot[lo] + b_lo <= 0.0:
        a_lo += slope[lo]
        b_lo += offset[lo]
        lo += 1
    out = [0.0] * n
    out[-1] = -b_lo / a_lo  # where the last message's derivative is 0
    for k in range(n - 2, -1, -1):
        out[k] = min(max(out[k + 1], low[k]), high[k])
    return np.array(out)


def denoise_trajectory(features: np.ndarray) -> np.ndarray:
    """Estimate ``(n, d)`` of the noise-free trajectory of one activation ``(n, d)``.

    Each feature ``j`` with white noise (``σ_j = white_noise_std(features)[j] > 0``) is
    total-variation denoised (:func:`tv_denoise`) with ``lam = σ_j · n^(1/3)``, the order of
    the penalty at which TV denoising attains its optimal rate on signals of bounded variation
    (Mammen & van de Geer, Ann. Stat. 25, 1997); its L1 length is then that of the motion, not
    of the noise. Features without detected noise are returned exactly as recorded.
    """
    x = _as_trajectory(features)
    sigma = white_noise_std(x)
    out = x.copy()
    lam = sigma * x.shape[0] ** (1.0 / 3.0)
    for j in np.flatnonzero(lam > 0.0):
        out[:, j] = tv_denoise(x[:, j], float(lam[j]))
    return out


def path_trajectory(features: np.ndarray, noise: PathNoise) -> np.ndarray:
    """The trajectory ``(n, d)`` along which eq. 1 measures an activation ``features (n, d)``.

    :func:`denoise_trajectory` of it for ``noise="auto"``, the features as recorded for
    ``"none"`` (see :data:`PATH_NOISE`). Every function below that takes ``noise`` starts with
    this step; on its result they measure with ``noise="none"``. Denoising being the costly
    part, a fit takes this step once per activation
    (:func:`cpmp.sequencer.fit_data.node_training_data`) and hands the result on in
    :attr:`~cpmp.predictors.NodeData.paths`.
    """
    x = _as_trajectory(features)
    return denoise_trajectory(x) if _check_noise(noise) == "auto" else x


def feature_path_lengths(features: np.ndarray, noise: PathNoise = "none") -> np.ndarray:
    """L1 path length of each feature ``(d,)`` of a trajectory ``(n, d)``.

    The terms eq. 1's integral splits into (they sum to :func:`path_length`).
    """
    x = path_trajectory(features, noise)
    return np.abs(np.diff(x, axis=0)).sum(axis=0)


def cumulative_path_length(features: np.ndarray, noise: PathNoise = "none") -> np.ndarray:
    """Unnormalised eq. 1: ``(n,)`` running L1 path length, starting at 0.

    With ``noise="auto"`` along :func:`denoise_trajectory` (see :data:`PATH_NOISE`).
    """
    x = path_trajectory(features, noise)
    steps = np.abs(np.diff(x, axis=0)).sum(axis=1)
    return np.concatenate([[0.0], np.cumsum(steps)])


def path_length(features: np.ndarray, noise: PathNoise = "none") -> float:
    """Total L1 path length of a trajectory ``(n, d)`` (the final ϕ before normalising)."""
    return float(cumulative_path_length(features, noise)[-1])


def expected_progress(
    features: np.ndarray, time: np.ndarray | None = None, noise: PathNoise = "none"
) -> np.ndarray:
    """Expected progress ``(n,)`` in [0, 1] of one activation ``(n, d)`` (paper eq. 1).

    With ``noise="auto"`` measured along :func:`denoise_trajectory` (see :data:`PATH_NOISE`).
    Monotone non-decreasing, first value 0 and last value 1 (for ``n >= 2``).

    Zero path length (features constant while the MP was active) carries no information about
    progress in feature space. Rather than dividing by zero, progress then falls back to
    normalised time (``time`` given) or normalised sample index, so it still runs from 0 to 1.
    A single-sample activation has progress ``[1.0]``: it is entered and left at once.
    """
    cum = cumulative_path_length(features, noise)
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
    features: np.ndarray, scale: float, min_support: int, max_support: int | None, noise: PathNoise
) -> int:
    """How many points :func:`support_points` places along ``features (n, d)``.

    Counted without placing them.
    """
    return _count_for_length(path_length(features, noise), scale, min_support, max_support)


def support_points(
    features: np.ndarray, scale: float, min_support: int, max_support: int | None, noise: PathNoise
) -> np.ndarray:
    """Support points ``(S, d)`` equidistant by L1 arc length along a trajectory ``(n, d)``.

    ``S = max(min_support, ceil(scale * L))`` where ``L`` is the L1 path length; the first and
    last points are the trajectory's ends and the others are interpolated linearly between
    samples. A trajectory of zero length yields a single support point (its constant value).
    With ``noise="auto"`` the trajectory is first denoised (:func:`denoise_trajectory`), so
    the points lie on the estimate of the noise-free path and their count follows its length.
    ``scale``, ``min_support``, ``max_support`` and ``noise`` are a predictor's options
    (:class:`~cpmp.config.KLRConfig` ``support_scale``, ``min_support``, ``max_support``,
    ``path_noise``).
    """
    x = path_trajectory(features, noise)
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


LabelKind = Literal["path", "path_denoised", "time"]
"""A kind of training label (see :data:`LABELS`)."""
LABELS: tuple[LabelKind, ...] = get_args(LabelKind)
"""Kinds of training label: ``path`` (eq. 1, the L1 line integral), ``path_denoised`` (eq. 1
along :func:`denoise_trajectory`, i.e. ``noise="auto"``) or ``time`` (normalised elapsed time,
the usual phase variable; the label ablation of eq. 1)."""


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


def progress_labels(features: np.ndarray, time: np.ndarray, kind: LabelKind = "path") -> np.ndarray:
    """Training labels ``(n,)`` of one activation ``features (n, d)``, ``time (n,)`` [s].

    :func:`expected_progress` for ``kind="path"`` (``noise="auto"`` for ``"path_denoised"``),
    :func:`time_labels` for ``kind="time"``.

    Raises:
        ConfigError: an unknown ``kind`` (see :data:`LABELS`).
    """
    if kind in ("path", "path_denoised"):
        return expected_progress(features, time, "auto" if kind == "path_denoised" else "none")
    if kind == "time":
        labels = time_labels(time)
        if labels.shape[0] != _as_trajectory(features).shape[0]:
            raise DataError(
                f"time has {labels.shape[0]} samples but features have "
                f"{np.shape(features)[0]}; they must match"
            )
        return labels
    raise ConfigError(f"progress labels must be one of {', '.join(LABELS)}, got {kind!r}")


def demo_labels(
    demo: Demonstration,
    variables: Sequence[str],
    transform: Callable[[np.ndarray], np.ndarray] | None,
    labels: LabelKind,
) -> dict[str, np.ndarray]:
    """Progress labels ``(n,)`` of each variable along ``demo``.

    Each activation is labelled on its own: :func:`progress_labels` of ``labels`` kind on
    ``transform`` of its features.
    """
    x = demo.features if transform is None else transform(demo.features)
    done = {}
    for u in variables:
        done[u] = np.zeros(demo.n_samples)
        for seg in demo.segments(u):
            sl = slice(seg.start, seg.stop)
            done[u][sl] = progress_labels(x[sl], demo.time[sl], labels)
    return done
