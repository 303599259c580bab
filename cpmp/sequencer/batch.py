"""``N`` episodes of a sequencer at once, for many rollouts (:func:`cpmp.sim.run_episodes`).

:class:`EpisodeBatch` is what every batched policy shares (per-episode ``active``, ``events``,
``notes``, and the checks of a batch call's inputs); :class:`BatchedSequencer` runs ``N``
episodes of a fitted sequencer (:class:`FittedSequencer`, e.g. a
:class:`~cpmp.sequencer.ConcurrentSequencer`) with one predictor call per tick for all of them.
The goal-nearest baseline's batch, :class:`~cpmp.baselines.GoalNearestBatch`, is another
:class:`EpisodeBatch`. Build either with the sequencer's ``batched(n)``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import NamedTuple, Protocol

import numpy as np
import torch

from cpmp.errors import ConfigError, CpmpError, DataError
from cpmp.predictors import ProgressPredictor
from cpmp.records import PendingSwitch, SequencerNote, TransitionEvent
from cpmp.sequencer.episode import SequencerEpisode
from cpmp.sequencer.inputs import checked_features
from cpmp.sequencer.model import TransitionModel

Times = float | np.ndarray
"""One time [s] for every episode, or ``(N,)`` times."""
Features = np.ndarray | torch.Tensor
"""Features ``(N, d)`` of ``N`` episodes."""
LiveMask = np.ndarray | Sequence[bool] | None
"""``(N,)`` bool: the episodes a batch call advances (``None``: all)."""
Stamps = float | np.ndarray | Sequence[float] | None
"""When the features were measured [s]: one time for every episode, ``(N,)`` times, or
``None`` (unknown; see :mod:`cpmp.sequencer.timing`)."""


class BatchInputs(NamedTuple):
    """The checked inputs of a batch call.

    Attributes:
        times: each episode's time [s], ``N`` floats.
        features: ``(N, d)`` float64.
        rows: the indices of the episodes to advance, in order.
    """

    times: list[float]
    features: np.ndarray
    rows: list[int]


class EpisodeRecord(Protocol):
    """What a batch reads of each of its episodes: the episode's record so far."""

    active: dict[str, str]
    """Variable -> active MP (empty before the episode's start)."""
    events: list[TransitionEvent]
    """The episode's transitions, in order."""
    notes: list[SequencerNote]
    """The episode's notes (held transitions, recoveries, non-finite φ)."""


class FittedSequencer(Protocol):
    """What :class:`BatchedSequencer` reads of a fitted sequencer.

    A :class:`~cpmp.sequencer.ConcurrentSequencer` is one.
    """

    feature_names: list[str]
    """The ``d`` feature names."""
    predictor: ProgressPredictor
    """The progress predictor (``stateful`` ones run one stream per episode)."""
    transition_model: TransitionModel
    """What each episode of the transition rule reads."""

    def progress(self, x: np.ndarray) -> np.ndarray:
        """φ of every node ``(N, K)`` for features ``x (N, d)``."""
        ...


class EpisodeBatch:
    """What every batched policy shares.

    ``episodes`` holds one object per episode with its ``active`` MPs, ``events`` and
    ``notes`` (:class:`EpisodeRecord`); the batch offers per-episode views of them and the
    checks of a batch call's inputs.
    """

    episodes: Sequence[EpisodeRecord]

    @staticmethod
    def checked_count(n: int) -> int:
        """``n`` as the number of episodes of a batch.

        Raises:
            ConfigError: unless ``n`` is an integer ``>= 1``.
        """
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
            raise ConfigError(f"a batched sequencer needs n >= 1 episodes, got {n!r}")
        return int(n)

    def _inputs(self, t: Times, x: Features, live: LiveMask, d: int) -> BatchInputs:
        """The inputs of a batch call, checked.

        Args:
            t: one time [s] or ``(N,)`` times.
            x: features ``(N, d)``.
            live: ``(N,)`` bool, the episodes to advance (``None``: all).
            d: the number of features.

        Returns:
            Times, features as float64 and the live rows.

        Raises:
            DataError: a shape, a non-finite time or a mask that is not boolean.
        """
        n = len(self.episodes)
        if isinstance(x, torch.Tensor):
            x = x.detach().cpu().numpy()
        xn = np.asarray(x, dtype=np.float64)
        if xn.shape != (n, d):
            raise DataError(
                f"a batch of {n} episodes needs features of shape ({n}, {d}), got {tuple(xn.shape)}"
            )
        try:
            times = np.broadcast_to(np.asarray(t, dtype=np.float64), (n,))
        except ValueError as err:
            raise DataError(f"t must be one time or {n} times, got shape {np.shape(t)}") from err
        if not np.isfinite(times).all():
            raise DataError(f"time must be finite, got t={t}")
        if live is None:
            rows = list(range(n))
        else:
            mask = np.asarray(live)
            if mask.shape != (n,) or mask.dtype != np.bool_:
                raise DataError(
                    f"live must be a boolean mask of shape ({n},), got {mask.dtype} of shape "
                    f"{mask.shape}"
                )
            rows = np.flatnonzero(mask).tolist()
        return BatchInputs(times.tolist(), xn, rows)

    def _stamps(self, stamp: Stamps) -> list[float | None]:
        """Each episode's measurement stamp [s] (``None``: unknown).

        Raises:
            DataError: ``stamp`` is neither one time nor ``N`` times.
        """
        n = len(self.episodes)
        if stamp is None:
            return [None] * n
        try:
            stamps = np.broadcast_to(np.asarray(stamp, dtype=np.float64), (n,))
        except ValueError as err:
            raise DataError(
                f"stamp must be one time or {n} times, got shape {np.shape(stamp)}"
            ) from err
        return stamps.tolist()

    @property
    def n_episodes(self) -> int:
        """N, the number of episodes."""
        return len(self.episodes)

    def __len__(self) -> int:
        return len(self.episodes)

    @property
    def active(self) -> list[dict[str, str]]:
        """Per episode, variable -> active MP (empty before its first reset)."""
        return [dict(ep.active) for ep in self.episodes]

    @property
    def events(self) -> list[list[TransitionEvent]]:
        """Per episode, its transitions."""
        return [ep.events for ep in self.episodes]

    @property
    def notes(self) -> list[list[SequencerNote]]:
        """Per episode, its notes."""
        return [ep.notes for ep in self.episodes]


class BatchedSequencer(EpisodeBatch):
    """``n`` independent episodes of one fitted :class:`ConcurrentSequencer`, stepped together.

    Every tick evaluates all nodes' predictors in one call over the features ``(N, d)`` of the
    live episodes; each episode then decides exactly as a :class:`ConcurrentSequencer` of its
    own would (same events, notes and tick information; φ may differ in the last bits, ~1e-14,
    where the predictor rounds a batch of rows differently). Build one with
    ``seq.batched(n)`` or ``BatchedSequencer(seq, n)``::

        batch = seq.batched(len(x0))
        active = batch.reset(0.0, x0)  # x0 (N, d) -> one dict variable -> MP per episode
        active = batch.step(0.01, x1, live=running)  # running: (N,) bool, others skipped
        batch.episodes[i].events, batch.episodes[i].notes, batch.episodes[i].last_tick

    ``live`` (optional, ``(N,)`` bool) leaves the other episodes untouched (finished
    rollouts); ``stamp`` (optional, one time or ``(N,)``) says when each row's features were
    measured (:meth:`ConcurrentSequencer.step`). A row of non-finite features is not given to
    the predictor: its episode follows the option ``nonfinite``. A stateful predictor
    (``predictor.stateful``, e.g. ``dtw``) runs one stream per episode: :meth:`reset` restarts
    all ``N`` streams and every call evaluates all ``N`` rows, whatever ``live`` says (a row
    of non-finite features as the last finite features of its episode).
    """

    def __init__(self, seq: FittedSequencer, n: int) -> None:
        self.sequencer = seq
        self.episodes = [
            SequencerEpisode(seq.transition_model) for _ in range(self.checked_count(n))
        ]
        """One :class:`SequencerEpisode` per episode (``active``, ``events``, ``notes``,
        ``last_tick``)."""
        self._held = np.zeros((len(self.episodes), len(seq.feature_names)))
        """Each episode's last finite features (what a stateful predictor gets instead of
        non-finite ones)."""

    def explain(self, index: int, expected: Mapping[str, Sequence[str]]) -> PendingSwitch | None:
        """Why episode ``index`` has not run ``expected``: the switch that never came.

        Args:
            index: the episode.
            expected: variable -> the MPs the demonstrator ran on its context.

        Returns:
            The cause (:meth:`SequencerEpisode.explain`), or ``None`` when there is none.
        """
        return self.episodes[index].explain(expected)

    def reset(self, t: Times, x: Features, live: LiveMask = None) -> list[dict[str, str]]:
        """Start the ``live`` episodes (default: all).

        Args:
            t: one time [s] or ``(N,)`` times.
            x: features ``(N, d)``.
            live: ``(N,)`` bool, the episodes to start (``None``: all).

        Returns:
            Every episode's active MPs (variable -> MP).

        Raises:
            DataError: a started episode's features are not finite (there is no MP to keep).
        """
        seq = self.sequencer
        ts, xn, rows = self._inputs(t, x, live, len(seq.feature_names))
        checked_features(xn[rows], seq.feature_names)
        stateful = getattr(seq.predictor, "stateful", False)
        if stateful:
            seq.predictor.reset_state(len(self.episodes))
        finite = np.isfinite(xn).all(axis=1)
        self._held[finite] = xn[finite]
        if rows:
            phi = seq.progress(np.where(finite[:, None], xn, self._held) if stateful else xn[rows])
            for j, i in enumerate(rows):
                self.episodes[i].start(ts[i], xn[i], phi[i if stateful else j])
        return self.active

    def step(
        self, t: Times, x: Features, live: LiveMask = None, stamp: Stamps = None
    ) -> list[dict[str, str]]:
        """Advance the ``live`` episodes (default: all) one tick.

        Args:
            t: one time [s] or ``(N,)`` times.
            x: features ``(N, d)``; a row with a NaN or inf holds every MP of its episode
                (``nonfinite="hold"``, the default) or raises (``"raise"``).
            live: ``(N,)`` bool, the episodes to advance (``None``: all).
            stamp: when the features were measured [s], one time or ``(N,)`` times on the
                clock of ``t`` (``None``: unknown; see :meth:`ConcurrentSequencer.step`).

        Returns:
            Every episode's active MPs (variable -> MP).

        Raises:
            CpmpError: what an episode raised, with the episode's index in the message.
        """
        seq = self.sequencer
        ts, xn, rows = self._inputs(t, x, live, len(seq.feature_names))
        stamps = self._stamps(stamp)
        for i in rows:
            try:
                self.episodes[i].check_time(ts[i], stamps[i])
            except CpmpError as err:
                raise type(err)(f"episode {i}: {err}") from err
        if not rows:
            return self.active
        finite = np.isfinite(xn).all(axis=1)
        self._held[finite] = xn[finite]
        stateful = getattr(seq.predictor, "stateful", False)
        if stateful:
            phi = seq.progress(np.where(finite[:, None], xn, self._held))[rows]
            usable = rows
        else:
            usable = [i for i in rows if finite[i]]
            phi = seq.progress(xn[usable]) if usable else np.zeros((0, 0))
        rows_phi: dict[int, list[float]] = dict(zip(usable, phi.tolist(), strict=True))
        ok = dict(zip(usable, np.isfinite(phi).all(axis=1).tolist(), strict=True))
        between = None if stateful else seq.progress
        for i in rows:
            row = rows_phi[i] if finite[i] else None
            try:
                self.episodes[i].advance(ts[i], xn[i], row, ok.get(i, False), stamps[i], between)
            except CpmpError as err:
                raise type(err)(f"episode {i}: {err}") from err
        return self.active
