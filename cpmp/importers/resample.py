"""One clock for streams recorded at different rates.

Recorded streams (a ROS topic, a dataset column) arrive at their own rates, sometimes with
repeated or out-of-order stamps and silent stretches. :func:`clean_stream` sorts a stream by
time, keeps the last-received sample of each repeated stamp and reports what it changed and
every gap longer than a limit; :func:`uniform_clock` makes the common clock;
:func:`interpolate_linear` (continuous features) and :func:`zero_order_hold` (labels: the MP
named last stays active) put a stream on it; :func:`merge_short_activations` removes label
glitches shorter than a minimum duration.

Rotations recorded as unit quaternions are not interpolated component by component (a sign
flip ``q -> -q``, which mocap systems emit, would pass through ``|q| = 0``):
:func:`align_quaternions` puts consecutive samples in one hemisphere, :func:`interpolate_slerp`
interpolates along the great arc, and :func:`rotation_columns` gives a representation a kernel
can use (the quaternion, the rotation vector, or the continuous 6-D representation).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from cpmp.errors import DataError


@dataclass(frozen=True)
class Gap:
    """A stretch in which a stream was silent.

    Attributes:
        stream: the stream's name (topic, column).
        start: [s] time of the last sample before the gap.
        stop: [s] time of the first sample after it.
    """

    stream: str
    start: float
    stop: float

    @property
    def duration(self) -> float:
        """``stop - start`` [s]."""
        return self.stop - self.start


@dataclass(frozen=True)
class StreamReport:
    """What :func:`clean_stream` found in one stream.

    Attributes:
        stream: the stream's name.
        n_samples: samples received.
        n_duplicates: samples dropped because a later-received sample has the same stamp.
        n_out_of_order: samples received after a sample with a later stamp (reordered).
        gaps: silent stretches longer than the limit, in time order.
    """

    stream: str
    n_samples: int
    n_duplicates: int
    n_out_of_order: int
    gaps: tuple[Gap, ...]


@dataclass(frozen=True)
class CleanStream:
    """A stream sorted by strictly increasing time.

    Attributes:
        time: (m,) [s] strictly increasing.
        values: (m, ...) the sample of each time (any dtype).
        report: what cleaning found.
    """

    time: np.ndarray
    values: np.ndarray
    report: StreamReport

    @property
    def rate(self) -> float:
        """Mean sample rate [Hz] (``nan`` for fewer than two samples)."""
        if len(self.time) < 2:
            return math.nan
        return float((len(self.time) - 1) / (self.time[-1] - self.time[0]))


@dataclass(frozen=True)
class Glitch:
    """A label activation shorter than the minimum, merged into a neighbour.

    Attributes:
        mp: the MP of the short activation.
        start: [s] when it began.
        duration: [s] how long it lasted.
        merged_into: the MP that replaced it.
    """

    mp: str
    start: float
    duration: float
    merged_into: str


@dataclass(frozen=True)
class Relabelled:
    """Labels after :func:`merge_short_activations`.

    Attributes:
        labels: (n,) str MP names.
        glitches: the activations that were merged away, in the order they were removed.
    """

    labels: np.ndarray
    glitches: tuple[Glitch, ...]


def clean_stream(
    stream: str, time: np.ndarray, values: np.ndarray, max_gap: float | None = None
) -> CleanStream:
    """Sort ``stream`` by time, drop repeated stamps, find gaps.

    Args:
        stream: the stream's name, used in reports and messages.
        time: (n,) [s] stamps in the order the samples were received.
        values: (n, ...) the samples.
        max_gap: [s] report every interval between consecutive stamps longer than this;
            ``None``: report none.

    Returns:
        The stream with strictly increasing times; of several samples with the same stamp the
        last received is kept.

    Raises:
        DataError: the stream is empty, or a stamp is NaN/inf.
    """
    t = np.asarray(time, dtype=np.float64)
    v = np.asarray(values)
    if t.ndim != 1 or len(t) != len(v):
        raise DataError(
            f"{stream}: {len(t)} stamps for {len(v)} samples; give one stamp per sample"
        )
    if len(t) == 0:
        raise DataError(f"{stream}: no samples; record it or remove it from the mapping")
    bad = np.flatnonzero(~np.isfinite(t))
    if bad.size:
        raise DataError(
            f"{stream}: stamp {bad[0]} is {t[bad[0]]}; every sample needs a finite stamp"
        )
    running_max = np.maximum.accumulate(t)
    n_out_of_order = int(np.count_nonzero(t[1:] < running_max[:-1]))
    order = np.argsort(t, kind="stable")
    t_sorted, v_sorted = t[order], v[order]
    # keep the last received of equal stamps: a sample is kept if the next one differs
    keep = np.append(t_sorted[1:] != t_sorted[:-1], True)
    t_clean, v_clean = t_sorted[keep], v_sorted[keep]
    gaps: tuple[Gap, ...] = ()
    if max_gap is not None and len(t_clean) > 1:
        long = np.flatnonzero(np.diff(t_clean) > max_gap)
        gaps = tuple(Gap(stream, float(t_clean[i]), float(t_clean[i + 1])) for i in long)
    report = StreamReport(
        stream=stream,
        n_samples=len(t),
        n_duplicates=int(len(t) - len(t_clean)),
        n_out_of_order=n_out_of_order,
        gaps=gaps,
    )
    return CleanStream(t_clean, v_clean, report)


def uniform_clock(start: float, stop: float, rate: float) -> np.ndarray:
    """Ticks ``start, start + 1/rate, ...`` up to ``stop`` (inclusive within 1e-9 s).

    Args:
        start: [s] first tick.
        stop: [s] no tick after this.
        rate: [Hz] ticks per second, > 0.

    Returns:
        (m,) [s] tick times, ``m >= 1`` when ``stop >= start`` (else empty).
    """
    if stop < start:
        return np.empty(0)
    m = math.floor((stop - start) * rate + 1e-9) + 1
    return start + np.arange(m) / rate


def interpolate_linear(time: np.ndarray, values: np.ndarray, clock: np.ndarray) -> np.ndarray:
    """Linear interpolation of a continuous stream onto ``clock``.

    Args:
        time: (n,) [s] strictly increasing.
        values: (n,) or (n, k) numeric samples.
        clock: (m,) [s] inside ``[time[0], time[-1]]``.

    Returns:
        (m, k) float64 (k = 1 for 1-D ``values``).
    """
    v = np.asarray(values, dtype=np.float64)
    if v.ndim == 1:
        v = v[:, None]
    if len(time) == 1:
        return np.repeat(v, len(clock), axis=0)
    return np.column_stack([np.interp(clock, time, v[:, j]) for j in range(v.shape[1])])


def zero_order_hold(time: np.ndarray, values: np.ndarray, clock: np.ndarray) -> np.ndarray:
    """The last sample at or before every tick (labels: the MP named last stays active).

    Args:
        time: (n,) [s] strictly increasing.
        values: (n, ...) samples of any dtype.
        clock: (m,) [s], none before ``time[0]``.

    Returns:
        (m, ...) ``values`` at the ticks.

    Raises:
        DataError: a tick lies before the first sample.
    """
    idx = np.searchsorted(time, clock, side="right") - 1
    if len(idx) and idx[0] < 0:
        raise DataError(
            f"clock tick {clock[0]:.6f} s lies before the first sample ({time[0]:.6f} s); "
            "start the clock after every label stream's first message"
        )
    return np.asarray(values)[idx]


def merge_short_activations(
    time: np.ndarray, labels: np.ndarray, min_duration: float
) -> Relabelled:
    """Merge label activations shorter than ``min_duration`` into their neighbours.

    The shortest too-short activation goes first; it takes the MP of the activation before it
    (the first one takes the MP after it), and adjacent equal activations join. This repeats
    until every activation lasts at least ``min_duration`` or one activation is left.

    Args:
        time: (n,) [s] sample times, strictly increasing.
        labels: (n,) str MP names.
        min_duration: [s] 0 keeps every activation. An activation lasts from its first sample
            to the next activation's first sample (the last: one sample period past its last).

    Returns:
        The new labels and the activations merged away.
    """
    out = np.asarray(labels).copy()
    glitches: list[Glitch] = []
    if min_duration <= 0 or len(out) < 2:
        return Relabelled(out, ())
    end = float(time[-1] + (time[-1] - time[-2]))
    while True:
        bounds = [0, *(np.flatnonzero(out[1:] != out[:-1]) + 1).tolist(), len(out)]
        if len(bounds) <= 2:
            break
        spans = [
            (float((time[b] if b < len(out) else end) - time[a]), k)
            for k, (a, b) in enumerate(itertools.pairwise(bounds))
        ]
        duration, k = min(spans)
        if duration >= min_duration:
            break
        a, b = bounds[k], bounds[k + 1]
        neighbour = out[a - 1] if k > 0 else out[b]
        glitches.append(Glitch(str(out[a]), float(time[a]), duration, str(neighbour)))
        out[a:b] = neighbour
    return Relabelled(out, tuple(glitches))


# ----------------------------------------------------------------------------- rotations
ROTATION_ELEMENTS: dict[str, tuple[str, ...]] = {
    "quat": ("x", "y", "z", "w"),
    "rotvec": ("rx", "ry", "rz"),
    "matrix6": ("r11", "r21", "r31", "r12", "r22", "r32"),
}
"""Element names of each rotation representation (:func:`rotation_columns`)."""


@dataclass(frozen=True)
class AlignedQuaternions:
    """Unit quaternions with consecutive samples in one hemisphere.

    Attributes:
        values: (n, 4) ``x, y, z, w``, unit norm, ``dot(values[i], values[i + 1]) >= 0``.
        n_flips: samples whose sign was flipped relative to the one before (``q -> -q``).
    """

    values: np.ndarray
    n_flips: int


def align_quaternions(quaternions: np.ndarray, where: str = "quaternion") -> AlignedQuaternions:
    """Normalise quaternions and flip each into the hemisphere of the one before it.

    ``q`` and ``-q`` are the same rotation; mocap and some drivers switch between them, which
    linear interpolation turns into a jump through ``|q| = 0``. After alignment the series is
    continuous (for rotations slower than half a turn between samples).

    Args:
        quaternions: (n, 4) ``x, y, z, w`` in time order.
        where: names the stream in messages.

    Returns:
        The aligned unit quaternions and how many sign flips were undone.

    Raises:
        DataError: a quaternion is (nearly) zero or not finite.
    """
    q = np.asarray(quaternions, dtype=np.float64)
    if q.ndim != 2 or q.shape[1] != 4:
        raise DataError(f"{where}: quaternions must be (n, 4) x, y, z, w, got shape {q.shape}")
    norm = np.linalg.norm(q, axis=1)
    bad = np.flatnonzero(~np.isfinite(norm) | (norm < 1e-6))
    if bad.size:
        raise DataError(
            f"{where}: quaternion {bad[0]} is {q[bad[0]].tolist()}, not a rotation; a rotation "
            "needs a unit quaternion (drop or repair the sample)"
        )
    q = q / norm[:, None]
    if len(q) < 2:
        return AlignedQuaternions(q, 0)
    flipped = np.einsum("ij,ij->i", q[1:], q[:-1]) < 0
    sign = np.concatenate([[1.0], np.cumprod(np.where(flipped, -1.0, 1.0))])
    return AlignedQuaternions(q * sign[:, None], int(np.count_nonzero(flipped)))


def interpolate_slerp(time: np.ndarray, quaternions: np.ndarray, clock: np.ndarray) -> np.ndarray:
    """Spherical linear interpolation of unit quaternions onto ``clock``.

    Each interval takes the shorter arc (the sign of its end is chosen for that), so the
    result is a unit quaternion at every tick; ticks are expected inside
    ``[time[0], time[-1]]`` (outside, the nearest end is held).

    Args:
        time: (n,) [s] strictly increasing.
        quaternions: (n, 4) unit quaternions ``x, y, z, w`` (:func:`align_quaternions`).
        clock: (m,) [s].

    Returns:
        (m, 4) unit quaternions.
    """
    q = np.asarray(quaternions, dtype=np.float64)
    if len(time) == 1:
        return np.repeat(q, len(clock), axis=0)
    i = np.clip(np.searchsorted(time, clock, side="right") - 1, 0, len(time) - 2)
    u = np.clip((clock - time[i]) / (time[i + 1] - time[i]), 0.0, 1.0)[:, None]
    q0, q1 = q[i], q[i + 1]
    dot = np.einsum("ij,ij->i", q0, q1)
    q1 = np.where((dot < 0)[:, None], -q1, q1)
    dot = np.clip(np.abs(dot), 0.0, 1.0)[:, None]
    theta = np.arccos(dot)
    small = theta < 1e-6
    sin = np.where(small, 1.0, np.sin(theta))
    w0 = np.where(small, 1.0 - u, np.sin((1.0 - u) * theta) / sin)
    w1 = np.where(small, u, np.sin(u * theta) / sin)
    out = w0 * q0 + w1 * q1
    return out / np.linalg.norm(out, axis=1, keepdims=True)


def rotation_columns(quaternions: np.ndarray, representation: str) -> np.ndarray:
    """Unit quaternions ``x, y, z, w`` as feature columns of ``representation``.

    Args:
        quaternions: (n, 4) unit quaternions.
        representation: ``quat`` (the quaternions themselves), ``rotvec`` (axis times angle
            [rad], angle in ``[0, pi]``) or ``matrix6`` (the rotation matrix's first two
            columns, ``r11, r21, r31, r12, r22, r32``: continuous, Zhou et al. 2019).

    Returns:
        (n, 4), (n, 3) or (n, 6).

    Raises:
        DataError: an unknown representation.
    """
    q = np.asarray(quaternions, dtype=np.float64)
    if representation == "quat":
        return q.copy()
    x, y, z, w = q.T
    if representation == "rotvec":
        s = np.where(w < 0, -1.0, 1.0)  # the same rotation with w >= 0: angle in [0, pi]
        vec = q[:, :3] * s[:, None]
        sin_half = np.linalg.norm(vec, axis=1)
        angle = 2.0 * np.arctan2(sin_half, np.abs(w))
        scale = np.where(sin_half < 1e-12, 2.0, angle / np.where(sin_half < 1e-12, 1.0, sin_half))
        return vec * scale[:, None]
    if representation == "matrix6":
        return np.column_stack(
            [
                1 - 2 * (y * y + z * z),
                2 * (x * y + w * z),
                2 * (x * z - w * y),
                2 * (x * y - w * z),
                1 - 2 * (x * x + z * z),
                2 * (y * z + w * x),
            ]
        )
    raise DataError(
        f"unknown rotation representation {representation!r}; use one of "
        f"{', '.join(ROTATION_ELEMENTS)}"
    )


__all__ = [
    "ROTATION_ELEMENTS",
    "AlignedQuaternions",
    "CleanStream",
    "Gap",
    "Glitch",
    "Relabelled",
    "StreamReport",
    "align_quaternions",
    "clean_stream",
    "interpolate_linear",
    "interpolate_slerp",
    "merge_short_activations",
    "rotation_columns",
    "uniform_clock",
    "zero_order_hold",
]
