"""How fast the features moved at each demonstrated switch, and which features always move.

Two facts the labelled demonstrations hold about motion, learned at fit time and read by the
transition rule (:mod:`cpmp.sequencer.switching`, :mod:`cpmp.sequencer.episode`):

**A speed envelope per demonstrated switch.** Progress (eq. 1) says *where* along an MP the
state is; it cannot say whether the MP has come to rest there. Many switches ``A -> B`` were
always demonstrated once some of the features ``A`` moves had slowed down (an arm arrives, a
lift settles, a partner's hand lets go). For each demonstrated switch the fastest speed of each
feature at the switch (over the :data:`SPEED_WINDOW` before it) is kept; at run time the
switch is inconsistent while a watched feature is more than :data:`SPEED_FACTOR` times faster
than that (with a floor of :data:`SPEED_FLOOR` times the feature's top speed under ``A``),
measured since ``A`` became active when that is less than :data:`SPEED_WINDOW` ago (a re-align
that starts from rest moves fast at once, while a window reaching back into the still retract
before it would read half that).

The same switch is also inconsistent while a watched feature moves at a larger *share of its
own top speed since* ``A`` *became active* than :data:`SPEED_FACTOR` times the largest share
seen at a demonstrated instance (the top speed measured the same way, over windows cut at the
activation's start). A speed in ranges per second says how close a first-order attractor is to
its goal only at the pace it was demonstrated at: a robot that runs the MP at half the pace
arrives twice as slowly, so at a demonstrated arrival's speed it is still twice as far away
(the paced relay's receiver, demonstrated and run at x0.5-2, let go of the object 10-18 cm
short of the shelf). Its speed over its top speed is the share of the move still ahead at any
pace. Neither bound replaces the other: an arm stopped by a jam was demonstrated at rest in
ranges per second, but over a 50 ms window its stop still reads as a sizeable share of its top
speed, so that switch is timed by the first bound (with the second alone, peg's inserter
retracted from unjammed insertions). A
feature is watched when it moves in ``A`` (its path under ``A`` is at least
:data:`MOVING_SHARE` of the longest feature path under ``A``) and had settled at every
demonstrated instance of the switch (at most :data:`SETTLED_SHARE` of its mean speed under
``A``): a feature still moving at its usual speed when the demonstrator switched (another
arm's reach while the fingers preshape) does not time the switch. All speeds are in units of
each feature's training range, measured along each demonstration denoised
(:func:`cpmp.progress.denoise_trajectory`); a feature with white noise in the demonstrations
(:func:`cpmp.progress.white_noise_std` ``σ``) gets :data:`NOISE_Z` ``· √2 σ /``
:data:`SPEED_WINDOW` more, what the same noise adds to a speed measured at run time (a noisy
feature's envelope is then loose: a speed over 50 ms cannot tell its motion from its noise). The
envelope is one more context of the switch, next to the other variables' MPs and progress
(:class:`~cpmp.sequencer.switching.Coupling`): it holds a switch back, never fires one.

**Ambient features.** A feature that moves at a similar rate under every MP of every variable
(a distractor's wobble, a conveyor, a clock) says nothing about whether the task is stuck: its
mean speed under the MP where it moves least is at least :data:`AMBIENT_RATIO` of its mean
speed under the MP where it moves most, and the switches do not bend its motion. A robot's own
coordinate whose variable never rests (a ladle always on its way, an arm that lifts while it
carries) also moves at a similar rate under every MP, but its velocity turns where its variable
switches (a new attractor pulls it elsewhere), while a drift goes on as before: a feature is
ambient only if, at the switches of every variable, its velocity changes over
:data:`SPEED_WINDOW` (after minus before) by less than :data:`KINK_RATIO` times its mean change
anywhere. The mean speeds and changes are measured along each demonstration
denoised (:func:`cpmp.progress.denoise_trajectory`), so that white sensor noise, which moves
every feature under every MP, makes no feature ambient. The stall detector ignores those features
(:class:`~cpmp.sequencer.switching.StallDetector`), so their motion never hides a stall.

Speeds are in training ranges per second (a feature of range 0 never moves).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Mapping, Sequence
from itertools import pairwise
from typing import NamedTuple

import numpy as np

from cpmp.data import Demonstration
from cpmp.progress import denoise_trajectory, white_noise_std
from cpmp.records import JsonValue

SPEED_WINDOW = 0.05
"""Seconds over which a speed is measured: the displacement since the newest measurement at
least this old, over the time between them. The switching rule's 50 ms: after an event (a jam
stops an arm) the demonstrator's switch comes within tens of milliseconds, and a longer window
still reads the motion before the event when the rule decides (100 ms held the procedural
family's retries until their ``p`` had fallen back)."""
SPEED_FACTOR = 2.0
"""How much faster than demonstrated at a switch a moving feature may be (``inf``: no
envelope)."""
SPEED_FLOOR = 0.002
"""The least envelope, as a share of the feature's top speed under the switch's source MP (for
a feature at rest at every demonstrated instance). A first-order attractor moves at this share
of its top speed when it is this share of its move from its goal: 0.2 % lets a switch wait for
a precise arrival (a 2.5 mm hole mouth at the end of a 30 cm reach), which 1 % did not."""
MOVING_SHARE = 0.05
"""A feature moves in an MP when its path there is at least this share of the longest one."""
SETTLED_SHARE = 0.5
"""A moving feature is in a switch's envelope only if, at every demonstrated instance of the
switch, it had slowed to at most this share of its mean speed under the source MP (``inf``:
every moving feature is)."""
NOISE_Z = 3.0
"""How many standard deviations of a noisy feature's run-time speed noise its envelope allows."""
AMBIENT_RATIO = 0.3
"""A feature is ambient when its least mean speed over the MPs is at least this share of its
greatest (``inf``: none is)."""
KINK_RATIO = 2.5
"""A feature whose velocity changes at some variable's switches by more than this many times
its mean change is not ambient, however alike its rates (``inf``: the rates alone decide). A
drift reads about 1 (peg's light level and table-height estimate 0.9–1.6 at 3–9
demonstrations); a first-order attractor's coordinate 3.5–9 (slip's arm height, repetition's
ladle, the procedural family's always-moving robots)."""

Edge = tuple[str, str, str]
"""(variable, source MP, target MP)."""


class SpeedLimit(NamedTuple):
    """The speed envelope of one demonstrated switch.

    Attributes:
        features: ``(k,)`` the indices of the features its source MP moves.
        limit: ``(k,)`` the fastest each may move for the switch to be consistent [ranges/s].
        share: ``(k,)`` the largest share of its top speed since the source MP became active
            each may move at (``None``: no such bound, as in checkpoints saved before it).
        slack: ``(k,)`` what that bound always allows on top [ranges/s]: the floor
            (:data:`SPEED_FLOOR`) and the noise allowance (:data:`NOISE_Z`), so that a feature
            at rest with a top speed of 0 is not held.
    """

    features: np.ndarray
    limit: np.ndarray
    share: np.ndarray | None = None
    slack: np.ndarray | None = None

    def exceeded(self, speed: np.ndarray, top: np.ndarray | None = None) -> np.ndarray:
        """The positions in :attr:`features` too fast at ``speed (d,)`` [ranges/s].

        Args:
            speed: each feature's speed now.
            top: ``(d,)`` each feature's top speed since the source MP became active (the
                speed now included) [ranges/s]; ``None``: the first bound only.
        """
        return np.flatnonzero(self.too_fast(speed) | self.too_fast_for_pace(speed, top))

    def too_fast(self, speed: np.ndarray) -> np.ndarray:
        """``(k,)`` bool: faster than :attr:`limit` at ``speed (d,)`` [ranges/s]."""
        return speed[self.features] > self.limit

    def too_fast_for_pace(self, speed: np.ndarray, top: np.ndarray | None) -> np.ndarray:
        """``(k,)`` bool: a larger share of ``top (d,)`` than :attr:`share` (plus the slack)."""
        if top is None or self.share is None or self.slack is None:
            return np.zeros(self.features.size, dtype=bool)
        return speed[self.features] > self.share * top[self.features] + self.slack

    def to_dict(self) -> dict[str, JsonValue]:
        """JSON/checkpoint-friendly form."""
        row: dict[str, JsonValue] = {
            "features": self.features.tolist(),
            "limit": self.limit.tolist(),
        }
        if self.share is not None and self.slack is not None:
            row["share"] = self.share.tolist()
            row["slack"] = self.slack.tolist()
        return row

    @classmethod
    def from_dict(cls, row: Mapping[str, JsonValue]) -> SpeedLimit:
        """Inverse of :meth:`to_dict` (a checkpoint saved without the second bound has none)."""
        features = np.asarray(row["features"], dtype=np.int64).reshape(-1)
        limit = np.asarray(row["limit"], dtype=np.float64).reshape(-1)
        if row.get("share") is None or row.get("slack") is None:
            return cls(features, limit)
        share = np.asarray(row["share"], dtype=np.float64).reshape(-1)
        slack = np.asarray(row["slack"], dtype=np.float64).reshape(-1)
        return cls(features, limit, share, slack)


class MotionData(NamedTuple):
    """One demonstration as the motion learners read it (:func:`motion_data`).

    Attributes:
        features: ``(T, d)`` denoised (:func:`cpmp.progress.denoise_trajectory`).
        time: ``(T,)`` [s].
        segments: variable -> its activations in time order, ``(start, stop, mp)``
            (:meth:`~cpmp.data.Demonstration.segments`).
        noise: ``(d,)`` each feature's white-noise standard deviation in the recording.
    """

    features: np.ndarray
    time: np.ndarray
    segments: Mapping[str, list[tuple[int, int, str]]]
    noise: np.ndarray


def motion_data(demos: Sequence[Demonstration]) -> list[MotionData]:
    """Each demonstration denoised once, with its noise level (for both learners)."""
    out = []
    for demo in demos:
        x = np.asarray(demo.features, np.float64)
        segments = {v: [(s.start, s.stop, s.mp) for s in demo.segments(v)] for v in demo.variables}
        out.append(
            MotionData(
                denoise_trajectory(x),
                np.asarray(demo.time, np.float64),
                segments,
                white_noise_std(x),
            )
        )
    return out


def _mp_paths(
    demos: Sequence[MotionData], variables: Sequence[str], n_features: int
) -> tuple[dict[tuple[str, str], np.ndarray], dict[tuple[str, str], float]]:
    """Each MP's motion: per ``(variable, mp)``, the L1 path of each feature.

    Returns:
        ``(path, duration)``: per ``(variable, mp)``, each feature's path ``(d,)`` [feature
        units] and the time [s], summed over its activations of at least two samples.
    """
    path: dict[tuple[str, str], np.ndarray] = {}
    duration: dict[tuple[str, str], float] = {}
    for demo in demos:
        x, t = demo.features, demo.time
        for v in variables:
            for a, b, mp in demo.segments[v]:
                if b - a < 2:
                    continue
                key = (v, mp)
                step = np.abs(np.diff(x[a:b], axis=0)).sum(axis=0)
                path[key] = path.get(key, np.zeros(n_features)) + step
                duration[key] = duration.get(key, 0.0) + float(t[b - 1] - t[a])
    return path, duration


def _inverse_range(feature_range: np.ndarray) -> np.ndarray:
    r = np.asarray(feature_range, dtype=np.float64)
    return np.divide(1.0, r, out=np.zeros_like(r), where=r > 0)


def window_speed(
    x: np.ndarray, t: np.ndarray, i: int, inv_range: np.ndarray, window: float = SPEED_WINDOW
) -> np.ndarray | None:
    """Each feature's speed at sample ``i`` over the newest sample at least ``window`` older.

    Args:
        x: features ``(T, d)``.
        t: their times ``(T,)`` [s].
        i: the sample.
        inv_range: ``(d,)`` one over each feature's range (0: ignored).
        window: [s].

    Returns:
        ``(d,)`` [ranges/s], or ``None`` when no sample is that old.
    """
    j = int(np.searchsorted(t, t[i] - window + 1e-9, side="right")) - 1
    if j < 0 or j >= i:
        return None
    return np.abs(x[i] - x[j]) / (t[i] - t[j]) * inv_range


def learn_speed_limits(
    demos: Sequence[MotionData], variables: Sequence[str], feature_range: np.ndarray
) -> dict[Edge, SpeedLimit]:
    """The speed envelope of every demonstrated switch (see the module doc).

    Args:
        demos: the labelled demonstrations (:func:`motion_data`).
        variables: the control variables.
        feature_range: ``(d,)`` each feature's training range (0: never moves).

    Returns:
        ``(variable, source, target)`` -> its envelope (none with :data:`SPEED_FACTOR` inf).
    """
    if not np.isfinite(SPEED_FACTOR):
        return {}
    inv = _inverse_range(feature_range)
    d = inv.size
    path, duration = _mp_paths(demos, variables, d)
    top: dict[tuple[str, str], np.ndarray] = {}
    at: dict[Edge, np.ndarray] = {}
    shares: dict[Edge, np.ndarray] = {}
    noise = np.zeros(d)
    for demo in demos:
        x, t = demo.features, demo.time
        noise = np.maximum(noise, demo.noise)
        for v in variables:
            segments = demo.segments[v]
            for a, b, mp in segments:
                if b - a < 2:
                    continue
                step = np.abs(np.diff(x[a:b], axis=0)) * inv
                fastest = (step / np.diff(t[a:b])[:, None]).max(axis=0)
                top[(v, mp)] = np.maximum(top.get((v, mp), np.zeros(d)), fastest)
            for (start, _, source), (a, _, target) in pairwise(segments):
                speed = window_speed(x, t, a, inv)
                if speed is not None:
                    edge = (v, source, target)
                    at[edge] = np.maximum(at.get(edge, np.zeros(d)), speed)
                    so_far = _top_speed_since(x, t, start, a, inv)
                    share = np.divide(speed, so_far, out=np.zeros(d), where=so_far > 0)
                    shares[edge] = np.maximum(shares.get(edge, np.zeros(d)), share)
    allowance = NOISE_Z * np.sqrt(2.0) * noise * inv / SPEED_WINDOW
    limits = {}
    for (v, source, target), speed in sorted(at.items()):
        p = path.get((v, source), np.zeros(d)) * inv  # [ranges]
        mean = p / max(duration.get((v, source), 0.0), 1e-12)
        watched = (p >= MOVING_SHARE * p.max()) & (speed <= SETTLED_SHARE * mean)
        moving = np.flatnonzero(watched) if p.max() > 0 else np.zeros(0, int)
        floor = SPEED_FLOOR * top.get((v, source), np.zeros(d))
        limits[(v, source, target)] = SpeedLimit(
            moving.astype(np.int64),
            (np.maximum(SPEED_FACTOR * speed, floor) + allowance)[moving],
            (SPEED_FACTOR * shares[(v, source, target)])[moving],
            (floor + allowance)[moving],
        )
    return limits


def _top_speed_since(
    x: np.ndarray, t: np.ndarray, start: int, stop: int, inv_range: np.ndarray
) -> np.ndarray:
    """``(d,)`` each feature's top speed [ranges/s] over samples ``start + 1 .. stop``.

    Each speed over the newest sample at least :data:`SPEED_WINDOW` older, cut at ``start``
    (where the MP became active), as :meth:`SpeedMeter.speed` measures it at run time.
    """
    i = np.arange(start + 1, stop + 1)
    if i.size == 0:
        return np.zeros(x.shape[1])
    j = np.searchsorted(t, t[i] - SPEED_WINDOW + 1e-9, side="right") - 1
    j = np.maximum(j, start)
    return (np.abs(x[i] - x[j]) / (t[i] - t[j])[:, None] * inv_range).max(axis=0)


def ambient_features(
    demos: Sequence[MotionData], variables: Sequence[str], n_features: int
) -> np.ndarray:
    """``(d,)`` bool: the features that move at a similar rate under every MP (module doc).

    Args:
        demos: the labelled demonstrations (:func:`motion_data`).
        variables: the control variables.
        n_features: ``d``.

    Returns:
        The mask (all false with fewer than two MPs, or :data:`AMBIENT_RATIO` inf).
    """
    path, duration = _mp_paths(demos, variables, n_features)
    rates = [path[k] / duration[k] for k in sorted(path) if duration[k] > 0]
    if len(rates) < 2 or not np.isfinite(AMBIENT_RATIO):
        return np.zeros(n_features, dtype=bool)
    stacked = np.stack(rates)
    hi, lo = stacked.max(axis=0), stacked.min(axis=0)
    alike = (hi > 0) & (lo >= AMBIENT_RATIO * hi)
    if alike.any() and np.isfinite(KINK_RATIO):
        alike &= ~_bent_at_switches(demos, variables, n_features)
    return alike


def without_ambient(feature_range: np.ndarray, ambient: np.ndarray | None) -> np.ndarray:
    """``feature_range (d,)`` with the ``ambient (d,)`` features' ranges set to 0 (left out).

    What reads features on those ranges does not read the ambient features: a learned choice
    (:func:`cpmp.sequencer.branches.learn_choice`), the stall detector
    (:class:`~cpmp.sequencer.switching.StallDetector`). ``None`` (no mask learned): the ranges
    as they are.
    """
    r = np.asarray(feature_range, dtype=np.float64)
    if ambient is None:
        return r
    return np.where(np.asarray(ambient, dtype=bool), 0.0, r)


def _bent_at_switches(
    demos: Sequence[MotionData], variables: Sequence[str], n_features: int
) -> np.ndarray:
    """``(d,)`` bool: the features whose velocity turns at some variable's switches.

    The velocity change at sample ``i`` is the velocity over the :data:`SPEED_WINDOW` after
    ``i`` minus the one over the window before; a feature is bent when its mean change at the
    first samples of one variable's activations exceeds :data:`KINK_RATIO` times its mean change
    at every sample (and a negligible floor, for a feature moving at a constant velocity).
    """
    total, count, speed, duration = np.zeros(n_features), 0, np.zeros(n_features), 0.0
    at = {v: np.zeros(n_features) for v in variables}
    seen = dict.fromkeys(variables, 0)
    for demo in demos:
        x, t = demo.features, demo.time
        if len(t) < 3:
            continue
        change = _velocity_change(x, t)  # (T, d), NaN where a window does not fit
        fits = ~np.isnan(change[:, 0])
        total += change[fits].sum(axis=0)
        count += int(fits.sum())
        speed += np.abs(np.diff(x, axis=0)).sum(axis=0)
        duration += float(t[-1] - t[0])
        for v in variables:
            for a, _, _ in demo.segments[v][1:]:
                if fits[a]:
                    at[v] += change[a]
                    seen[v] += 1
    if count == 0:
        return np.zeros(n_features, dtype=bool)
    mean = total / count
    floor = 1e-3 * speed / max(duration, 1e-12)
    bent = np.zeros(n_features, dtype=bool)
    for v in variables:
        if seen[v]:
            at_switch = at[v] / seen[v]
            bent |= (at_switch > KINK_RATIO * mean) & (at_switch > floor)
    return bent


def _velocity_change(x: np.ndarray, t: np.ndarray) -> np.ndarray:
    """``(T, d)`` |velocity over the window after each sample − over the window before|.

    Each window reaches to the nearest sample at least :data:`SPEED_WINDOW` away (irregular
    sampling allowed); NaN rows where either window leaves the recording.
    """
    n = len(t)
    before = np.searchsorted(t, t - SPEED_WINDOW + 1e-9, side="right") - 1
    after = np.searchsorted(t, t + SPEED_WINDOW - 1e-9, side="left")
    out = np.full(x.shape, np.nan)
    ok = (before >= 0) & (after < n)
    i = np.flatnonzero(ok)
    if i.size:
        j, k = before[i], after[i]
        v_before = (x[i] - x[j]) / (t[i] - t[j])[:, None]
        v_after = (x[k] - x[i]) / (t[k] - t[i])[:, None]
        out[i] = np.abs(v_after - v_before)
    return out


class SpeedMeter:
    """Each feature's speed over the last :data:`SPEED_WINDOW` of measurements, at run time.

    Feed it new measurements only (as the stall detector). Args: ``feature_range (d,)`` as
    in :func:`learn_speed_limits`.
    """

    def __init__(self, feature_range: np.ndarray) -> None:
        self.inv_range = _inverse_range(feature_range)
        self._seen: deque[tuple[float, np.ndarray]] = deque()

    def reset(self, t: float, x: np.ndarray) -> None:
        """Start an episode at ``t`` [s] with features ``x (d,)``."""
        self._seen.clear()
        self._seen.append((t, np.array(x, dtype=np.float64)))

    def observe(self, t: float, x: np.ndarray) -> None:
        """Feed the measurement ``x (d,)`` taken at ``t`` [s] (later than the last one)."""
        seen = self._seen
        seen.append((t, np.array(x, dtype=np.float64)))
        while len(seen) > 2 and t - seen[1][0] >= SPEED_WINDOW - 1e-9:
            seen.popleft()

    def speed(self, since: float | None = None) -> np.ndarray | None:
        """``(d,)`` [ranges/s] over the newest measurement at least :data:`SPEED_WINDOW` old.

        Args:
            since: the measurement time [s] at which the MP whose motion is asked about
                became active: a window reaching before it is cut there, so that the speed
                is the MP's own (a re-align that has just started from rest moves fast
                although the 50 ms before it were still). ``None``: the whole window.

        Returns:
            The speed; ``None`` before a measurement is :data:`SPEED_WINDOW` old (or, with
            ``since``, before one was taken after it).
        """
        seen = self._seen
        if len(seen) < 2:
            return None
        (t0, x0), (t1, x1) = seen[0], seen[-1]
        if since is not None and since > t0 + 1e-9:
            t0, x0 = next((t, x) for t, x in seen if t >= since - 1e-9)
            if t1 - t0 <= 1e-9:
                return None
        elif t1 - t0 < SPEED_WINDOW - 1e-9:
            return None
        return np.abs(x1 - x0) / (t1 - t0) * self.inv_range
