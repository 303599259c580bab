"""``dtw``: progress by dynamic-time-warping alignment of the recent features to training data.

A stateful baseline: for every input stream the bank keeps the features of the last
``window`` ticks. At each tick the window's points (the newest tick and every ``stride``-th
tick before it, oldest first) are aligned by open-begin, open-end DTW (dtw-python, step pattern
``asymmetric``: the reference may advance by 0, 1 or 2 samples per window point) to each
node's training activations, thinned to every ``stride``-th sample (at most ``max_reference``
per activation). The node's progress is the expected progress (eq. 1) at the reference
sample matched to the newest tick in the activation that matches best (lowest accumulated
cost), interpolated along that activation: the newest tick is projected onto the segment from
the matched sample to the next kept sample (or from the previous one, if it lies before the
matched sample), and φ is interpolated linearly between the two samples' progress
(:func:`interpolate_progress`).

Why the interpolation: kept samples are ``stride`` ticks apart (0.1 s at the defaults), so the
matched sample's own progress holds still for up to ``stride`` ticks while the MP moves. The
switching rule reads a p that has not improved for its patience (50 ms) as "converged" and
fires, so without the interpolation dtw switches mid-motion in closed loop (the closed-loop
results: see docs/benchmarks.md).

All nodes are aligned in *one* dtw-python call per stream and tick: the training activations
of all nodes are laid side by side in one reference, two columns of infinite cost between
activations so that no warping path crosses from one into the next (a path can skip at most
one column per step). The last row of the cumulative cost matrix then holds, for every
reference sample, the cost of the best window alignment ending there; each node takes the
argmin over its own columns, as dtw-python's open end does over a whole reference.

Units: ``window`` and ``stride`` count control ticks (at the simulator's 100 Hz the defaults,
50 and 10, put 5 points into the last 0.5 s); distances are Euclidean in the scaled feature
space (``feature_scaling``). A tick costs one cost matrix of ``ceil(window / stride)`` rows by
(kept training samples + 2 per activation) columns per stream.
"""

from __future__ import annotations

import math
from typing import ClassVar

import numpy as np
import torch
from torch.nn import functional as F

from cpmp.config.predictors import DTWConfig
from cpmp.config.trainer import SolverOptions
from cpmp.errors import ConfigError, DataError, require
from cpmp.predictors.base import (
    NodeData,
    NodeKey,
    ProgressPredictor,
)
from cpmp.predictors.newton import NewtonInfo
from cpmp.progress import expected_progress
from cpmp.records import JsonValue

SEPARATOR = 2
"""Columns of infinite cost between two activations in the joint reference (the asymmetric
step pattern skips at most one)."""


def window_ticks(newest: int, window: int, stride: int) -> np.ndarray:
    """Ticks of the window points at tick ``newest``, oldest first.

    ``newest`` and every ``stride``-th tick before it, within the last ``window`` ticks and
    not before tick 0.
    """
    return np.arange(newest, max(newest - window, -1), -stride)[::-1]


def interpolate_progress(
    matched: np.ndarray, dist: np.ndarray, steps: np.ndarray, progress: np.ndarray
) -> np.ndarray:
    """Progress at the newest tick's projection next to each matched reference sample.

    ``matched (U,)``: indices of the matched samples; ``dist (R,)``: distances of the newest
    tick to every reference sample; ``steps (R,)``: distance from each sample to the next one
    of its activation (``nan`` at an activation's last sample); ``progress (R,)``: the samples'
    expected progress. The projection onto the segment from a sample ``j`` to ``j + 1`` (of
    length ``L``) lies at the fraction ``u = (dist[j]² − dist[j + 1]² + L²) / (2 L²)`` (law of
    cosines; Euclidean distances). If ``u > 0`` φ interpolates between ``j`` and ``j + 1``,
    else between ``j − 1`` and ``j`` (same formula one sample back), with ``u`` clipped to
    [0, 1]; a sample without such a neighbour keeps its own progress. Returns ``(U,)``.
    """
    j = np.asarray(matched, dtype=np.int64)
    last = len(progress) - 1
    after, before = np.minimum(j + 1, last), np.maximum(j - 1, 0)
    ahead = steps[j]
    behind = np.where(j > 0, steps[before], np.nan)
    with np.errstate(divide="ignore", invalid="ignore"):
        u_ahead = (dist[j] ** 2 - dist[after] ** 2 + ahead**2) / (2 * ahead**2)
        u_behind = (dist[before] ** 2 - dist[j] ** 2 + behind**2) / (2 * behind**2)
    use_ahead = (ahead > 0) & (u_ahead > 0)  # False where ahead is nan
    use_behind = ~use_ahead & (behind > 0)
    phi = progress[j].astype(np.float64)
    phi = np.where(
        use_ahead, progress[j] + np.clip(u_ahead, 0, 1) * (progress[after] - progress[j]), phi
    )
    return np.where(
        use_behind,
        progress[before] + np.clip(u_behind, 0, 1) * (progress[j] - progress[before]),
        phi,
    )


class _Streams:
    """Distances of the last ``span`` ticks of ``n`` streams to every reference sample.

    Kept in a ring buffer ``(n, span, R)``.
    """

    def __init__(self, n: int, span: int, n_reference: int) -> None:
        self.rows = np.zeros((n, span, n_reference))
        self.ticks = 0

    @property
    def n(self) -> int:
        return self.rows.shape[0]

    def push(self, dist: np.ndarray) -> None:
        """Append one tick: ``dist (n, R)``."""
        self.rows[:, self.ticks % self.rows.shape[1]] = dist
        self.ticks += 1

    def window(self, stride: int) -> np.ndarray:
        """Ring slots of the newest tick's window points, oldest first."""
        span = self.rows.shape[1]
        return window_ticks(self.ticks - 1, span, stride) % span


class DTWPredictor(ProgressPredictor):
    """``dtw``: open-end DTW of each stream's recent features against the training activations.

    Stateful (:attr:`stateful`): each :meth:`forward` call is one tick of
    :meth:`reset_state`'s ``n_streams`` streams, one row each (a first call without a reset
    starts as many streams as it has rows). Nothing is trained: :meth:`initialize` stores the
    thinned activations and their expected progress as buffers. Logits are ``logit(φ)``
    (``±inf`` at φ = 0 and 1, which the sigmoid of :meth:`forward` maps back exactly).
    """

    config: DTWConfig
    kind: ClassVar[str] = "dtw"
    config_class = DTWConfig
    convex: ClassVar[bool] = True
    stateful: ClassVar[bool] = True

    def __init__(
        self, node_keys: list[NodeKey], n_features: int, config: DTWConfig, n_reference: int = 1
    ) -> None:
        super().__init__(node_keys, n_features, config)
        dt = self.dtype_
        self.register_buffer("reference", torch.zeros(n_reference, n_features, dtype=dt))
        self.register_buffer("reference_progress", torch.zeros(n_reference, dtype=dt))
        self.register_buffer("column", torch.arange(n_reference, dtype=torch.long))
        self.register_buffer("head_range", torch.zeros(self.n_nodes, 2, dtype=torch.long))
        self._streams: _Streams | None = None
        self._loss_cache: tuple[list[NodeData], torch.Tensor] | None = None
        self._layout_cache: tuple[tuple[int, int], tuple[np.ndarray, ...]] | None = None
        self._steps_cache: tuple[tuple[int, ...], np.ndarray] | None = None

    def shape_spec(self) -> dict[str, int]:
        """The number of kept reference samples ``R``."""
        return {"n_reference": int(self.reference.shape[0])}

    # ----------------------------------------------------------------------------- fitting
    def _thin(self, n: int) -> np.ndarray:
        """Indices of the kept samples of an activation of ``n`` samples.

        Every ``stride``-th and the last, at most ``max_reference`` (evenly thinned).
        """
        c = self.config
        idx = np.arange(0, n, c.stride)
        if idx[-1] != n - 1:
            idx = np.append(idx, n - 1)
        if len(idx) > c.max_reference:
            idx = np.unique(np.round(np.linspace(0, n - 1, c.max_reference)).astype(np.int64))
        return idx

    def initialize(self, data: list[NodeData], generator: torch.Generator) -> None:
        """Store every node's thinned activations (scaled features) and expected progress."""
        refs, progress, columns, ranges = [], [], [], []
        count = column = 0
        for node in data:
            start = count
            for act in node.activations:
                idx = self._thin(len(act))
                refs.append(np.asarray(act)[idx])
                progress.append(expected_progress(act)[idx])
                columns.append(column + np.arange(len(idx)))
                column += len(idx) + SEPARATOR
                count += len(idx)
            if count == start:
                raise DataError(f"node {node.key[0]}/{node.key[1]} has no activation data for dtw")
            ranges.append((start, count))
        dt = self.dtype_
        self.reference = torch.as_tensor(np.concatenate(refs), dtype=dt)
        self.reference_progress = torch.as_tensor(np.concatenate(progress), dtype=dt)
        self.column = torch.as_tensor(np.concatenate(columns), dtype=torch.long)
        self.head_range = torch.as_tensor(ranges, dtype=torch.long)
        self._streams = None
        self._loss_cache = None
        self._layout_cache = None
        self._steps_cache = None

    def solve_convex(self, data: list[NodeData], solver: SolverOptions) -> list[NewtonInfo]:
        """Nothing to solve: the references were stored by :meth:`initialize`."""
        return []

    def training_loss(
        self, data: list[NodeData], rows: list[torch.Tensor] | None = None
    ) -> torch.Tensor:
        """Sum over nodes of the mean soft BCE (eq. 5) of φ against expected progress.

        Each training activation is replayed (as a fresh stream) against the node's own
        references and scored at every ``stride``-th tick and the last one (:meth:`replay`).
        Cached for the same ``data`` list (the fit asks twice).

        Args:
            data: every node's training data.
            rows: must be ``None``: the replay scores whole activations (full batch only).

        Returns:
            The scalar loss.

        Raises:
            ConfigError: ``rows`` given.
        """
        if rows is not None:
            raise ConfigError("the dtw predictor scores whole activations: no mini-batches")
        if self._loss_cache is not None and self._loss_cache[0] is data:
            return self._loss_cache[1]
        total = self._tensor(0.0)
        for i, node in enumerate(data):
            phi, target = [], []
            for act in node.activations:
                z = self._tensor(np.asarray(act))
                ticks = self._scored_ticks(len(act))
                phi.append(self._tensor(self.replay(z, i, ticks)))
                target.append(self._tensor(expected_progress(act)[ticks]))
            total = total + F.binary_cross_entropy(torch.cat(phi), torch.cat(target))
        self._loss_cache = (data, total)
        return total

    def _tensor(self, values: np.ndarray | float) -> torch.Tensor:
        """``values`` (a NumPy array or a number) as a tensor of the bank's dtype and device."""
        return torch.as_tensor(values, dtype=self.dtype_, device=self.reference.device)

    def _scored_ticks(self, n: int) -> np.ndarray:
        """Every ``stride``-th tick of ``n`` and the last one."""
        ticks = np.arange(0, n, self.config.stride)
        return ticks if ticks[-1] == n - 1 else np.append(ticks, n - 1)

    # ----------------------------------------------------------------------------- inference
    def reset_state(self, n_streams: int) -> None:
        """Start ``n_streams`` fresh streams (empty windows)."""
        if isinstance(n_streams, bool) or not isinstance(n_streams, int) or n_streams < 1:
            raise ConfigError(f"n_streams must be a whole number >= 1, got {n_streams!r}")
        self._streams = _Streams(n_streams, self.config.window, self.reference.shape[0])

    @property
    def n_streams(self) -> int | None:
        """Streams of the current state (``None`` before the first tick or reset)."""
        return None if self._streams is None else self._streams.n

    def logits(self, z: torch.Tensor) -> torch.Tensor:
        """One tick of every stream: logits ``logit(φ)`` ``(n_streams, K)``.

        ``z (n_streams, d)``: the streams' scaled features at this tick.
        """
        if self._streams is None:
            self.reset_state(int(z.shape[0]))
        streams = self._streams
        if z.shape[0] != streams.n:
            raise DataError(
                f"the dtw predictor runs {streams.n} stream(s) and takes one row per stream "
                f"and tick, got {z.shape[0]} rows; call reset_state({z.shape[0]}) to start "
                "that many streams, or feed a trajectory one tick at a time"
            )
        streams.push(self._distances(z))
        slots = streams.window(self.config.stride)
        starts, segment = self._layout()
        columns = self.column.numpy(force=True)
        width = int(columns[-1]) + 1
        progress = self.reference_progress.numpy(force=True)
        steps = self._steps()
        phi = np.stack(
            [
                self._align(
                    streams.rows[b, slots], columns, width, starts, segment, progress, steps
                )
                for b in range(streams.n)
            ]
        )
        return torch.logit(self._tensor(phi))

    def _layout(self) -> tuple[np.ndarray, np.ndarray]:
        """The heads' reference ranges as segments, one per head, in order.

        First sample of each head's range ``(K,)`` and the head of each reference sample
        ``(R,)``. Cached until ``head_range`` changes.
        """
        key = (id(self.head_range), self.head_range._version)
        if self._layout_cache is None or self._layout_cache[0] != key:
            ranges = self.head_range.numpy(force=True)
            segment = np.repeat(np.arange(len(ranges)), ranges[:, 1] - ranges[:, 0])
            self._layout_cache = (key, (ranges[:, 0], segment))
        return self._layout_cache[1]

    def _steps(self) -> np.ndarray:
        """``(R,)`` distance from each kept reference sample to the next one of its activation.

        In scaled feature units; ``nan`` at an activation's last sample. Cached until
        ``reference`` or ``column`` changes.
        """
        key = (id(self.reference), self.reference._version, id(self.column), self.column._version)
        if self._steps_cache is None or self._steps_cache[0] != key:
            reference = self.reference.numpy(force=True)
            column = self.column.numpy(force=True)
            steps = np.full(len(column), np.nan)
            same = column[1:] == column[:-1] + 1
            lengths = np.linalg.norm(np.diff(reference, axis=0), axis=1)
            steps[:-1][same] = lengths[same]
            self._steps_cache = (key, steps)
        return self._steps_cache[1]

    def node_logits(self, z: torch.Tensor, i: int) -> torch.Tensor:
        """Logits ``(B,)`` of node ``i``, the rows of ``z (B, d)`` one fresh stream's ticks.

        The live streams are left alone. A self-check for long training sets, so aligned only
        at every ``stride``-th tick and the last one, each value held until the next aligned
        tick.
        """
        ticks = self._scored_ticks(int(z.shape[0])) if z.shape[0] else np.zeros(0, np.int64)
        phi = self.replay(z, i, ticks)
        held = np.searchsorted(ticks, np.arange(z.shape[0]), side="right") - 1
        return torch.logit(self._tensor(phi[held]))

    def _distances(self, z: torch.Tensor, lo: int = 0, hi: int | None = None) -> np.ndarray:
        """Euclidean distances ``(B, R)`` of ``z (B, d)`` to the reference samples ``lo:hi``."""
        dist = torch.cdist(
            z.to(self.dtype_),
            self.reference[lo:hi],
            compute_mode="donot_use_mm_for_euclid_dist",
        )
        return dist.to(torch.float64).numpy(force=True)

    def replay(self, z: torch.Tensor, i: int, ticks: np.ndarray | None = None) -> np.ndarray:
        """φ ``(len(ticks),)`` of node ``i`` at ``ticks`` of one fresh stream.

        The stream's consecutive ticks are the rows of ``z (B, d)`` (scaled features), aligned
        against node ``i``'s references only; the live streams are left alone. ``ticks``:
        default every tick.
        """
        lo, hi = self.head_range[i].tolist()
        columns = self.column[lo:hi].numpy(force=True)
        columns = columns - columns[0]
        width = int(columns[-1]) + 1
        ticks = np.arange(z.shape[0]) if ticks is None else np.asarray(ticks, dtype=np.int64)
        needed = np.unique(
            np.concatenate(
                [window_ticks(int(t), self.config.window, self.config.stride) for t in ticks]
                or [np.zeros(0, np.int64)]
            )
        )
        dist = np.zeros((z.shape[0], hi - lo))
        if len(needed):
            dist[needed] = self._distances(z[torch.as_tensor(needed)], lo, hi)
        progress = self.reference_progress[lo:hi].numpy(force=True)
        steps = self._steps()[lo:hi]
        starts, segment = np.zeros(1, np.int64), np.zeros(hi - lo, np.int64)
        return np.array(
            [
                self._align(
                    dist[window_ticks(int(t), self.config.window, self.config.stride)],
                    columns,
                    width,
                    starts,
                    segment,
                    progress,
                    steps,
                )[0]
                for t in ticks
            ]
        )

    @staticmethod
    def _align(
        dist: np.ndarray,
        columns: np.ndarray,
        width: int,
        starts: np.ndarray,
        segment: np.ndarray,
        progress: np.ndarray,
        steps: np.ndarray,
    ) -> np.ndarray:
        """φ ``(U,)`` per segment of reference samples, by open-end DTW of one window.

        Segments are contiguous, in order (first samples ``starts (U,)``, ``segment (R,)`` of
        each sample). φ is the ``progress (R,)`` at the sample where the cheapest open-begin,
        open-end alignment of the window ``dist (n_w, R)`` (distances of the window points,
        oldest first, to the reference samples laid out at ``columns (R,)`` of a
        ``width``-column cost matrix) ends within that segment, interpolated towards its
        neighbours (:func:`interpolate_progress`, ``steps (R,)`` as :meth:`_steps`).
        """
        require("dtw", "baselines", "the dtw predictor")
        from dtw import asymmetric, dtw  # lazy: the [baselines] extra

        local = np.full((dist.shape[0], width), np.inf)
        local[:, columns] = dist
        result = dtw(
            local,
            step_pattern=asymmetric,
            open_begin=True,
            open_end=True,
            distance_only=True,
            keep_internals=True,
        )
        ends = result.costMatrix[-1][columns]
        hit = np.flatnonzero(ends == np.minimum.reduceat(ends, starts)[segment])
        _, first = np.unique(segment[hit], return_index=True)
        return interpolate_progress(hit[first], dist[-1], steps, progress)

    def summary(self) -> dict[str, JsonValue]:
        """The base facts, the reference size and the window."""
        out = super().summary()
        out["n_reference"] = int(self.reference.shape[0])
        out["window"] = self.config.window
        out["stride"] = self.config.stride
        out["window_points"] = math.ceil(self.config.window / self.config.stride)
        return out
