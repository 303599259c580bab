"""Offline evaluation of a fitted sequencer on recorded demonstrations (no simulator needed).

* Progress prediction (paper Fig. 6): predicted φ against expected progress (eq. 1) for every
  MP activation of held-out demonstrations (a stateful predictor, such as ``dtw``, is fed each
  demonstration tick by tick). Whatever labels a predictor was trained on (``time_phase``:
  normalised time), it is scored against eq. 1. :func:`progress_curves` averages them over
  activations (the statistics the figure draws).
* Replay: the sequencer runs open-loop over each recorded feature stream; per variable we check
  that it reproduces the demonstrated MP sequence and measure the switch-state distance.

Switch-state distance: for a variable whose replayed sequence equals the demonstrated one, the
k-th triggered transition is paired with the k-th demonstrated switch; the distance is the
Euclidean norm of the difference of the two feature vectors (sequencer's state when it fired
minus the demonstration's state at its first sample under the new MP).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TypedDict

import numpy as np

from cpmp.data import Demonstration
from cpmp.errors import ConfigError, DataError
from cpmp.progress import expected_progress
from cpmp.records import TransitionEvent
from cpmp.sequencer import ConcurrentSequencer, indicator_features


@dataclass
class ActivationProgress:
    """Expected and predicted progress along one MP activation.

    Attributes:
        variable, mp: the node.
        demo: demonstration name.
        expected: (n,) expected progress (eq. 1, in the predictor's feature space).
        predicted: (n,) predicted φ.
    """

    variable: str
    mp: str
    demo: str
    expected: np.ndarray
    predicted: np.ndarray


class ProgressErrors(TypedDict):
    """Mean absolute progress errors (:func:`progress_errors`).

    Attributes:
        mae: over every sample of every activation.
        mae_first: over the first ``edge`` of each activation (by normalised time).
        mae_last: over the last ``edge`` of each activation.
        n_activations: the activations.
        per_node: ``"variable/mp"`` -> the node's MAE (sorted by node).
    """

    mae: float
    mae_first: float
    mae_last: float
    n_activations: int
    per_node: dict[str, float]


class ProgressCurves(TypedDict):
    """Average predicted progress over MP activations (:func:`progress_curves`).

    Attributes:
        time: ``(n_bins,)`` normalised time points in [0, 1].
        predicted_mean: ``(n_bins,)`` predicted progress per time point, over activations.
        predicted_std: ``(n_bins,)`` its standard deviation (ddof=0).
        expected_mean: ``(n_bins,)`` expected progress per time point, over activations.
        expected_std: ``(n_bins,)`` its standard deviation (ddof=0).
        progress_bins: ``(n_bins,)`` centres of the expected-progress bins.
        binned_mean: ``(n_bins,)`` predicted progress per bin (NaN where empty).
        binned_std: ``(n_bins,)`` its standard deviation (ddof=0; NaN where empty).
        binned_count: ``(n_bins,)`` samples per bin.
        n_activations: the activations.
    """

    time: np.ndarray
    predicted_mean: np.ndarray
    predicted_std: np.ndarray
    expected_mean: np.ndarray
    expected_std: np.ndarray
    progress_bins: np.ndarray
    binned_mean: np.ndarray
    binned_std: np.ndarray
    binned_count: np.ndarray
    n_activations: int


class VariableReplay(TypedDict):
    """One control variable of a replayed demonstration (:func:`replay_demonstrations`).

    Attributes:
        expected: the demonstrated MPs, in order.
        replayed: the MPs the sequencer ran, in order.
        match: whether the two are the same.
        distances: per switch, the distance between the triggered and the demonstrated switch
            state (:func:`switch_distances`); ``None`` without a match.
    """

    expected: list[str]
    replayed: list[str]
    match: bool
    distances: list[float] | None


class DemoReplay(TypedDict):
    """One replayed demonstration (:func:`replay_demonstrations`).

    Attributes:
        demo: its name (``demo_<m>`` if unnamed).
        variables: control variable -> its replay.
        match: every variable matched.
    """

    demo: str
    variables: dict[str, VariableReplay]
    match: bool


class ReplaySummary(TypedDict):
    """The replay of demonstrations through a sequencer (:func:`replay_demonstrations`).

    Attributes:
        per_demo: one entry per demonstration, in order.
        sequence_match: control variable -> the fraction of demonstrations it matched on.
        all_match: the fraction of demonstrations every variable matched on.
        distance_mean: the mean switch distance over the matched variables (``None``: none).
        distance_std: their standard deviation (ddof=0; ``None``: none).
        n_switches: the switch distances measured.
    """

    per_demo: list[DemoReplay]
    sequence_match: dict[str, float]
    all_match: float
    distance_mean: float | None
    distance_std: float | None
    n_switches: int


class OfflineEvaluation(TypedDict):
    """Everything offline about a sequencer on demonstrations (:func:`evaluate_offline`).

    Attributes:
        progress: the progress errors.
        curves: the Fig. 6 curves.
        replay: the replay of the recorded feature streams.
        pairs: ``(expected (n,), predicted (n,))`` progress per activation.
    """

    progress: ProgressErrors
    curves: ProgressCurves
    replay: ReplaySummary
    pairs: list[tuple[np.ndarray, np.ndarray]]


def activation_progress(
    seq: ConcurrentSequencer, demos: Sequence[Demonstration]
) -> list[ActivationProgress]:
    """Predicted vs expected progress for every activation of every known node in ``demos``."""
    out = []
    index = {key: i for i, key in enumerate(seq.node_keys)}
    for m, demo in enumerate(demos):
        _check_features(seq, demo)
        phi = stream_progress(seq, demo.features)
        scaled = seq.predictor.scaler.transform(demo.features)
        for v in sorted(seq.graphs):
            for seg in demo.segments(v):
                key = (v, seg.mp)
                if key not in index:
                    continue
                sl = slice(seg.start, seg.stop)
                out.append(
                    ActivationProgress(
                        variable=v,
                        mp=seg.mp,
                        demo=demo.name or f"demo_{m}",
                        expected=expected_progress(scaled[sl], demo.time[sl]),
                        predicted=phi[sl, index[key]],
                    )
                )
    return out


def stream_progress(seq: ConcurrentSequencer, features: np.ndarray) -> np.ndarray:
    """φ ``(n, K)`` of every node along one recorded trajectory ``features (n, d)``.

    A stateless predictor takes the whole trajectory in one batched call. A stateful one
    (``dtw``: it aligns a window of recent features) is restarted as one stream and fed the
    trajectory tick by tick, as the sequencer feeds it in closed loop; this resets the
    predictor's streams, so do not interleave it with a running sequencer on the same model.
    """
    x = np.asarray(features, dtype=np.float64)
    if not seq.predictor.stateful:
        return seq.progress(x)
    seq.predictor.reset_state(1)
    return np.concatenate([seq.progress(row[None]) for row in x], axis=0)


def _check_features(seq: ConcurrentSequencer, demo: Demonstration) -> None:
    """:class:`DataError` unless ``demo`` has the features ``seq`` was trained on."""
    if list(demo.feature_names) != seq.feature_names:
        raise DataError(
            f"{demo.name or 'demonstration'} has features {list(demo.feature_names)[:4]}... but "
            f"the sequencer was trained on {seq.feature_names[:4]}...; use matching recordings"
        )


def progress_errors(records: Sequence[ActivationProgress], edge: float = 0.1) -> ProgressErrors:
    """Mean absolute progress error: overall, at the ends of the activations and per node.

    Args:
        records: expected and predicted progress per activation.
        edge: the fraction of each activation (by normalised time) at its start and at its
            end that ``mae_first`` and ``mae_last`` cover.

    Returns:
        ``mae``, ``mae_first``, ``mae_last``, ``n_activations`` and ``per_node``
        (``"variable/mp"`` -> MAE), a :class:`ProgressErrors`.

    Raises:
        DataError: no activations.
    """
    if not records:
        raise DataError("no activations to evaluate: the demonstrations share no MP with the model")
    errs, first, last = [], [], []
    per_node: dict[str, list[np.ndarray]] = {}
    for r in records:
        e = np.abs(r.predicted - r.expected)
        u = np.linspace(0.0, 1.0, len(e)) if len(e) > 1 else np.zeros(1)
        errs.append(e)
        first.append(e[u <= edge])
        last.append(e[u >= 1.0 - edge])
        per_node.setdefault(f"{r.variable}/{r.mp}", []).append(e)
    cat = np.concatenate
    return ProgressErrors(
        mae=float(cat(errs).mean()),
        mae_first=float(cat(first).mean()),
        mae_last=float(cat(last).mean()),
        n_activations=len(records),
        per_node={k: float(cat(v).mean()) for k, v in sorted(per_node.items())},
    )


def progress_curves(
    activations: Sequence[tuple[np.ndarray, np.ndarray]], n_bins: int = 50
) -> ProgressCurves:
    """Average predicted progress over MP activations (the statistics of Fig. 6).

    ``activations``: (expected (n,), predicted (n,)) per activation, n >= 2 samples in time
    order. Each is resampled (linear interpolation) onto ``n_bins`` points of normalised time
    in [0, 1]; all samples are also binned by expected progress into ``n_bins`` equal bins.

    Returns arrays of shape (n_bins,): ``time``, ``predicted_mean``, ``predicted_std``,
    ``expected_mean``, ``expected_std`` (over activations, per time point); ``progress_bins``
    (bin centres), ``binned_mean``, ``binned_std`` (predicted progress per expected-progress
    bin, NaN where empty), ``binned_count``; and ``n_activations`` (a :class:`ProgressCurves`).
    Standard deviations are population (ddof=0) values.
    """
    if int(n_bins) < 2:
        raise ConfigError(f"n_bins must be >= 2, got {n_bins}")
    n_bins = int(n_bins)
    if len(activations) == 0:
        raise DataError("progress_curves needs at least one activation")
    time = np.linspace(0.0, 1.0, n_bins)
    resampled_expected, resampled_predicted = [], []
    all_expected, all_predicted = [], []
    for i, pair in enumerate(activations):
        if len(pair) != 2:
            raise DataError(f"activations[{i}] must be a pair (expected, predicted)")
        expected, predicted = (np.asarray(a, dtype=float) for a in pair)
        if expected.ndim != 1 or expected.shape != predicted.shape or len(expected) < 2:
            raise DataError(
                f"activations[{i}]: expected and predicted must both have shape (n,) with "
                f"n >= 2, got {expected.shape} and {predicted.shape}"
            )
        if not (np.all(np.isfinite(expected)) and np.all(np.isfinite(predicted))):
            raise DataError(f"activations[{i}] contains NaN or inf")
        own_time = np.linspace(0.0, 1.0, len(expected))
        resampled_expected.append(np.interp(time, own_time, expected))
        resampled_predicted.append(np.interp(time, own_time, predicted))
        all_expected.append(expected)
        all_predicted.append(predicted)

    expected_flat, predicted_flat = np.concatenate(all_expected), np.concatenate(all_predicted)
    edges = np.linspace(0.0, 1.0, n_bins + 1)
    bin_index = np.clip(np.digitize(expected_flat, edges) - 1, 0, n_bins - 1)
    count = np.bincount(bin_index, minlength=n_bins)
    total = np.bincount(bin_index, weights=predicted_flat, minlength=n_bins)
    total_sq = np.bincount(bin_index, weights=predicted_flat**2, minlength=n_bins)
    with np.errstate(invalid="ignore", divide="ignore"):
        binned_mean = np.where(count > 0, total / count, np.nan)
        binned_var = np.where(count > 0, total_sq / count - binned_mean**2, np.nan)
    return ProgressCurves(
        time=time,
        predicted_mean=np.mean(resampled_predicted, axis=0),
        predicted_std=np.std(resampled_predicted, axis=0),
        expected_mean=np.mean(resampled_expected, axis=0),
        expected_std=np.std(resampled_expected, axis=0),
        progress_bins=0.5 * (edges[:-1] + edges[1:]),
        binned_mean=binned_mean,
        binned_std=np.sqrt(np.maximum(binned_var, 0.0)),
        binned_count=count,
        n_activations=len(activations),
    )


def switch_distances(
    events: Sequence[TransitionEvent],
    demo: Demonstration,
    variable: str,
    columns: np.ndarray | None = None,
) -> list[float] | None:
    """Distances between triggered and demonstrated switch states of ``variable``.

    Args:
        events: the triggered switches, each with its ``state``.
        demo: the demonstration (:meth:`~cpmp.data.Demonstration.transitions`).
        variable: the control variable.
        columns: ``(d,)`` bool, the features the distance is measured on (e.g.
            :func:`continuous_features`); ``None``: all.

    Returns:
        One Euclidean distance per switch, or ``None`` if the triggered switches do not match
        the demonstrated ones one to one.
    """
    fired = [e for e in events if e.variable == variable]
    shown = demo.transitions(variable)
    if [(e.source, e.target) for e in fired] != [(s.source, s.target) for s in shown]:
        return None
    keep = slice(None) if columns is None else np.asarray(columns, dtype=bool)
    return [
        float(np.linalg.norm((e.state - s.state)[keep])) for e, s in zip(fired, shown, strict=True)
    ]


def continuous_features(demos: Sequence[Demonstration]) -> np.ndarray:
    """``(d,)`` bool: the features that take more than two distinct values in ``demos``.

    Binary signals, such as touch, flip by 1 when a switch comes one tick early or late.
    """
    return ~indicator_features(np.concatenate([d.features for d in demos], axis=0))


def replay_demonstrations(
    seq: ConcurrentSequencer, demos: Sequence[Demonstration]
) -> ReplaySummary:
    """Replay each demo's feature stream through ``seq``; sequence match and switch distances.

    Returns ``{"per_demo": [...], "sequence_match": {variable: fraction}, "all_match": fraction,
    "distance_mean": float | None, "distance_std": float | None, "n_switches": int}`` (a
    :class:`ReplaySummary`).
    """
    per_demo: list[DemoReplay] = []
    distances: list[float] = []
    match = {v: 0 for v in sorted(seq.graphs)}
    all_match = 0
    for m, demo in enumerate(demos):
        _check_features(seq, demo)
        seqs, events = seq.replay(demo.time, demo.features)
        variables: dict[str, VariableReplay] = {}
        ok_all = True
        for v in sorted(seq.graphs):
            expected = [s.mp for s in demo.segments(v)]
            ok = seqs[v] == expected
            d = switch_distances(events, demo, v) if ok else None
            variables[v] = VariableReplay(
                expected=expected, replayed=seqs[v], match=ok, distances=d
            )
            match[v] += ok
            ok_all &= ok
            if d:
                distances.extend(d)
        all_match += ok_all
        per_demo.append(
            DemoReplay(demo=demo.name or f"demo_{m}", variables=variables, match=ok_all)
        )
    n = max(len(demos), 1)
    return ReplaySummary(
        per_demo=per_demo,
        sequence_match={v: c / n for v, c in match.items()},
        all_match=all_match / n,
        distance_mean=float(np.mean(distances)) if distances else None,
        distance_std=float(np.std(distances)) if distances else None,
        n_switches=len(distances),
    )


def evaluate_offline(
    seq: ConcurrentSequencer, demos: Sequence[Demonstration], n_bins: int = 50
) -> OfflineEvaluation:
    """Everything offline about ``seq`` on ``demos``.

    Progress MAE (overall, first/last 10 %, per node; :func:`progress_errors`), Fig. 6 curves
    (:func:`progress_curves` with ``n_bins``) and the raw ``(expected, predicted)`` pairs per
    activation, and a replay of the recorded feature streams (:func:`replay_demonstrations`).

    Returns:
        ``{"progress", "curves", "replay", "pairs"}`` (an :class:`OfflineEvaluation`).
    """
    records = activation_progress(seq, demos)
    errors = progress_errors(records)
    curves = progress_curves([(r.expected, r.predicted) for r in records], n_bins=n_bins)
    replay = replay_demonstrations(seq, demos)
    pairs = [(r.expected, r.predicted) for r in records]
    return OfflineEvaluation(progress=errors, curves=curves, replay=replay, pairs=pairs)
