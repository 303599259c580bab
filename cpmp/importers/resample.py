"""One clock for streams recorded at different rates.

Recorded streams (a ROS topic, a dataset column) arrive at their own rates, sometimes with
repeated or out-of-order stamps and silent stretches. :func:`clean_stream` sorts a stream by
time, keeps the last-received sample of each repeated stamp and reports what it changed and
every gap longer than a limit; :func:`uniform_clock` makes the common clock;
:func:`interpolate_linear` (continuous features) and :func:`zero_order_hold` (labels: the MP
named last stays active) put a stream on it; :func:`merge_short_activations` removes label
glitches shorter than a minimum duration.
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


__all__ = [
    "CleanStream",
    "Gap",
    "Glitch",
    "Relabelled",
    "StreamReport",
    "clean_stream",
    "interpolate_linear",
    "merge_short_activations",
    "uniform_clock",
    "zero_order_hold",
]
