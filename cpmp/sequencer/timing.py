"""When the features a tick is given were measured: the episode's measurement clock.

The switching rule and the stall detector (:mod:`cpmp.sequencer.switching`) run on
*measurement time*, not on ticks: a tick whose features are not a new measurement adds no
evidence. :class:`MeasurementClock` turns the caller's tick times ``t``, features and optional
stamps into that time, one tick at a time:

* **Clock steps.** A tick interval more than :data:`CLOCK_STEP_FACTOR` times the median of the
  last :data:`TICK_HISTORY` intervals is a step of the caller's clock (an NTP correction, a
  paused process), not time in which the task went on: it counts as one median interval, and
  the rest is kept as an offset that every later time is shifted by.
* **Stamps.** With a stamp (the time the features were measured, on the caller's clock, at or
  before ``t``), the measurement time is the tick's time less the features' age ``t - stamp``;
  a stamp that has not advanced past the last measurement is a repeat of it.
* **Without a stamp**, a feature vector equal to the last one is a repeat of the last
  measurement (a sensor slower than the loop, read by zero-order hold), for at most
  ``stale_time`` seconds since it was first seen; unchanged for longer, the state counts as at
  rest and each tick as a new measurement at its own time.
"""

from __future__ import annotations

import statistics
from collections import deque
from typing import NamedTuple

import numpy as np

CLOCK_STEP_FACTOR = 5.0
"""A tick interval longer than this many median tick intervals is a clock step."""
TICK_HISTORY = 8
"""How many recent tick intervals the median tick interval is taken over."""
EPS_T = 1e-9
"""Slack [s] when comparing times (ticks are sums of floating-point periods)."""
MEASUREMENT_STEP = 0.01
"""The sequencer reads the way between two measurements twice this far apart or more [s]
as states this far apart or less (the usual 100 Hz of demonstrations; ``advance`` of
:class:`~cpmp.sequencer.episode.SequencerEpisode`)."""


class Reading(NamedTuple):
    """What one tick's features are, in measurement time.

    Attributes:
        m: the measurement time [s] of the features the tick decides on (the episode's clock:
            the caller's, less every clock step so far).
        fresh: whether they are a new measurement (``m`` later than the last one's).
        clock_step: the clock step [s] found at this tick (0: none).
    """

    m: float
    fresh: bool
    clock_step: float


class MeasurementClock:
    """The measurement time of each tick of one episode (see module doc).

    Args:
        stale_time: how long [s] an unchanged feature vector without a stamp is a repeat of
            the last measurement.
    """

    def __init__(self, stale_time: float) -> None:
        self.stale_time = stale_time
        self._intervals: deque[float] = deque(maxlen=TICK_HISTORY)
        self._offset = 0.0
        self._last_t = 0.0
        self._last_m = 0.0
        self._last_x: np.ndarray | None = None
        self._x_since = 0.0

    @property
    def period(self) -> float | None:
        """The median of the recent tick intervals [s] (``None`` before the first)."""
        return statistics.median(self._intervals) if self._intervals else None

    def reset(self, t: float, x: np.ndarray) -> float:
        """Start an episode at the caller's time ``t`` [s] with features ``x (d,)``.

        Returns:
            The measurement time of the start (``t``).
        """
        self._intervals.clear()
        self._offset = 0.0
        self._last_t = self._last_m = self._x_since = t
        self._last_x = np.array(x, dtype=np.float64)
        return t

    def tick(self, t: float, x: np.ndarray | None, stamp: float | None = None) -> Reading:
        """The measurement time of the tick at the caller's time ``t`` [s].

        Args:
            t: the tick's time [s], not before the last tick's.
            x: the tick's features ``(d,)``; ``None``: no usable features (not finite).
            stamp: when ``x`` was measured [s], on the caller's clock, at or before ``t``;
                ``None``: unknown (a changed ``x`` is then measured at ``t``).

        Returns:
            The tick's :class:`Reading`.
        """
        interval = t - self._last_t
        self._last_t = t
        step = 0.0
        period = self.period
        if period is not None and interval > CLOCK_STEP_FACTOR * period:
            step = interval - period
            self._offset += step
        elif interval > EPS_T:
            self._intervals.append(interval)
        now = t - self._offset
        last = self._last_m
        if x is None:
            return Reading(last, False, step)
        if stamp is not None:
            m = now - max(t - stamp, 0.0)
        elif self._last_x is None or not np.array_equal(x, self._last_x):
            m = self._x_since = now
            self._last_x = np.array(x, dtype=np.float64)
        else:
            m = now if now - self._x_since > self.stale_time + EPS_T else last
        if m <= last + EPS_T:
            return Reading(last, False, step)
        self._last_m = m
        return Reading(m, True, step)


__all__ = [
    "CLOCK_STEP_FACTOR",
    "EPS_T",
    "MEASUREMENT_STEP",
    "TICK_HISTORY",
    "MeasurementClock",
    "Reading",
]
