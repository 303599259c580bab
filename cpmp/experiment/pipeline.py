"""The paper's evaluation as composable functions: collect → split → train → evaluate.

``run_experiment`` ties them together with the simulator in front; ``train_from_file`` and
``evaluate_checkpoint`` serve users who bring their own demonstrations (no simulator).
"""

from __future__ import annotations

import dataclasses
import logging
import time
from collections import defaultdict
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from cpmp.errors import DataError
from cpmp.evaluation import (
    activation_progress,
    continuous_features,
    progress_errors,
    replay_demonstrations,
    switch_distances,
)
from cpmp.experiment.config import (
    ExperimentSettings,  # noqa: F401 (re-exported)
    FitSettings,
    fit_settings,
)

if TYPE_CHECKING:
    from cpmp.data import Demonstration
    from cpmp.sequencer import ConcurrentSequencer
    from cpmp.sim import Box, TaskConfig

log = logging.getLogger(__name__)

OTHER = "other"
"""Strategy label of an initial MP set that matches no demonstrated strategy."""


def progress_bar(items: list, desc: str) -> Any:
    """A tqdm progress bar over ``items`` on stderr (cleared when done)."""
    from tqdm import tqdm

    return tqdm(items, desc=desc, leave=False, dynamic_ncols=True)


@contextmanager
def stage(name: str) -> Iterator[None]:
    """Log the start and the duration of a pipeline stage."""
    log.info("stage %s: start", name)
    start = time.perf_counter()
    yield
    log.info("stage %s: done in %.1f s", name, time.perf_counter() - start)


# ------------------------------------------------------------------------------------ data
def strategy_of(demo: Demonstration) -> str:
    """The strategy a demonstration used (``metadata["strategy"]``)."""
    strategy = (demo.metadata or {}).get("strategy")
    if not strategy:
        raise DataError(f"{demo.name}: metadata has no 'strategy'; cannot balance by strategy")
    return str(strategy)


def by_strategy(demos: Sequence[Demonstration]) -> dict[str, list[Demonstration]]:
    """Demonstrations grouped by strategy, each group in the given order."""
    groups: dict[str, list[Demonstration]] = defaultdict(list)
    for demo in demos:
        groups[strategy_of(demo)].append(demo)
    return dict(sorted(groups.items()))


def split_by_strategy(
    demos: Sequence[Demonstration], train_per_strategy: int
) -> tuple[list[Demonstration], list[Demonstration]]:
    """First ``train_per_strategy`` demos of each strategy train, the rest test."""
    train, test = [], []
    for strategy, group in by_strategy(demos).items():
        if len(group) <= train_per_strategy:
            raise DataError(
                f"strategy {strategy!r} has {len(group)} demos; need more than "
                f"{train_per_strategy} to keep some for testing"
            )
        train += group[:train_per_strategy]
        test += group[train_per_strategy:]
    return train, test


def balanced_subset(demos: Sequence[Demonstration], size: int) -> list[Demonstration]:
    """``size`` demos taken round-robin over strategies (so 3 = one per strategy)."""
    groups = list(by_strategy(demos).values())
    out: list[Demonstration] = []
    k = 0
    while len(out) < size:
        if all(k >= len(g) for g in groups):
            raise DataError(f"asked for {size} training demos, only {len(out)} available")
        out += [g[k] for g in groups if k < len(g)][: size - len(out)]
        k += 1
    return out


def strategy_signatures(demos: Sequence[Demonstration]) -> dict[str, dict[str, str]]:
    """Initial MP per variable of each demonstrated strategy."""
    out: dict[str, dict[str, str]] = {}
    for demo in demos:
        out.setdefault(strategy_of(demo), {v: str(demo.labels[v][0]) for v in demo.variables})
    return out


def classify_start(initial: Mapping[str, str], signatures: Mapping[str, Mapping[str, str]]) -> str:
    """The strategy whose initial MPs equal ``initial``, else :data:`OTHER`."""
    for strategy, sig in signatures.items():
        if all(initial.get(v) == mp for v, mp in sig.items()):
            return strategy
    return OTHER


# ------------------------------------------------------------------------------- training
def train_sequencer(
    demos: Sequence[Demonstration],
    settings: FitSettings,
    seed: int = 0,
    log_dir: str | Path | None = None,
) -> Any:
    """Fit the sequencer ``settings`` describe on ``demos`` with ``seed`` (Lightning logs into
    ``log_dir`` when set): a :class:`~cpmp.sequencer.ConcurrentSequencer`, or the
    :class:`~cpmp.goal_nearest.GoalNearestSequencer` baseline (no predictor, no trainer)."""
    if settings.goal_nearest is not None:
        from cpmp.goal_nearest import GoalNearestSequencer

        options = dataclasses.asdict(settings.goal_nearest)
        return GoalNearestSequencer.fit(list(demos), seed=seed, **options)
    from cpmp.sequencer import ConcurrentSequencer

    fit = settings.fit
    trainer = fit.trainer
    if log_dir is not None:
        trainer = dataclasses.replace(trainer, log_dir=str(log_dir))
    config = dataclasses.replace(fit, trainer=trainer, seed=seed)
    return ConcurrentSequencer.fit_config(list(demos), config)


def fit_sequencer(
    demos: Sequence[Demonstration],
    predictor_cfg: Any,
    sequencer_cfg: Any = None,
    trainer_cfg: Any = None,
    seed: int = 0,
    log_dir: str | Path | None = None,
) -> Any:
    """:func:`train_sequencer` from config groups (``predictor``, ``sequencer``, ``trainer``:
    nodes or mappings), converted by :func:`~cpmp.experiment.config.fit_settings`."""
    settings = fit_settings(predictor_cfg, sequencer_cfg, trainer_cfg)
    return train_sequencer(demos, settings, seed, log_dir)


# ----------------------------------------------------------------------------- evaluation
def evaluate_offline(
    seq: ConcurrentSequencer, demos: Sequence[Demonstration], n_bins: int = 50
) -> dict[str, Any]:
    """Progress MAE (overall, first/last 10 %, per node), Fig. 6 curves (and the raw
    ``(expected, predicted)`` pairs per activation) and a replay of the recorded feature streams
    (per-variable sequence match, switch-state distance)."""
    from cpmp.experiment.plots import progress_curves

    records = activation_progress(seq, demos)
    errors = progress_errors(records)
    curves = progress_curves([(r.expected, r.predicted) for r in records], n_bins=n_bins)
    replay = replay_demonstrations(seq, demos)
    pairs = [(r.expected, r.predicted) for r in records]
    return {"progress": errors, "curves": curves, "replay": replay, "pairs": pairs}


@dataclass
class EpisodeRecord:
    """One reproduction episode, summarised for the report."""

    box: tuple[float, float]
    correct: str
    chosen: str
    outcome: str
    reason: str
    duration: float
    distances: list[float]
    distances_continuous: list[float] = field(default_factory=list)
    recoveries: int = 0
    holds: int = 0
    rrd: str | None = None

    def to_dict(self) -> dict[str, Any]:
        return dict(self.__dict__)


class EpisodeLogger:
    """``on_tick`` callback that writes a rerun recording of a sequencer-driven episode."""

    def __init__(self, recorder: Any, seq: ConcurrentSequencer) -> None:
        self.recorder = recorder
        self.seq = seq
        self._n_events = 0
        self._n_notes = 0

    def __call__(self, info: Any) -> None:
        tick = self.seq.last_tick
        self.recorder.log_tick(
            info.t,
            info.features,
            tick.progress if tick else {},
            info.active,
            tick.transition_probs if tick else None,
            info.body_poses,
        )
        for event in self.seq.events[self._n_events :]:
            self.recorder.log_transition(
                event.t, event.variable, event.source, event.target, event.probability, event.kind
            )
        for note in self.seq.notes[self._n_notes :]:
            self.recorder.log_note(note.t, note.kind, note.variable, note.text)
        self._n_events = len(self.seq.events)
        self._n_notes = len(self.seq.notes)


def reproduce(
    seq: ConcurrentSequencer,
    boxes: Sequence[Box],
    expected: Sequence[Demonstration],
    task: TaskConfig,
    signatures: Mapping[str, Mapping[str, str]],
    *,
    record_dir: Path | None = None,
    record: str = "failures",
    max_time: float | None = None,
    label: str = "",
) -> list[EpisodeRecord]:
    """Run ``seq`` closed-loop on every box; classify outcomes and measure switch distances.

    ``expected[i]`` is the demonstrator's recording of ``boxes[i]``: its switch states are the
    "desired states" of Table Ib. All boxes run together (:func:`cpmp.sim.runner.run_episodes`
    with ``seq.batched``); every number equals a run of one box at a time.
    """
    from cpmp.experiment.recording import EpisodeRecorder
    from cpmp.sim import Simulation, correct_strategy
    from cpmp.sim.runner import run_episodes

    out: list[EpisodeRecord] = []
    if not boxes:
        return out
    if record_dir is not None and record != "none":
        record_dir.mkdir(parents=True, exist_ok=True)
    batch = seq.batched(len(boxes))
    paths: list[Path | None] = []
    recorders: list[Any] = []
    callbacks: list[EpisodeLogger | None] = []
    for i, box in enumerate(boxes):
        rrd = recorder = callback = None
        if record_dir is not None and (
            record in ("all", "failures") or (record == "first" and i == 0)
        ):
            sim = Simulation(task, box)
            rrd = record_dir / f"{label}episode_{i:03d}.rrd"
            recorder = EpisodeRecorder(
                rrd,
                feature_names=seq.feature_names,
                mp_names={v: g.ordered_nodes() for v, g in seq.graphs.items()},
                episode=f"{label}episode_{i:03d}",
                geoms=sim.geoms(),
                metadata={"box_width": box.width, "box_depth": box.depth},
            )
            callback = EpisodeLogger(recorder, batch.episodes[i])
        paths.append(rrd)
        recorders.append(recorder)
        callbacks.append(callback)
    bar = progress_bar(list(boxes), f"{label}episodes")
    try:
        results = run_episodes(
            boxes,
            batch,
            task,
            expected=expected,
            max_time=max_time,
            on_tick=callbacks,
            on_result=lambda i, result: bar.update(1),
        )
    except BaseException:
        for recorder in recorders:
            if recorder is not None:
                recorder.abort()
        raise
    finally:
        bar.close()
    for i, (box, demo, result) in enumerate(zip(boxes, expected, results, strict=True)):
        rrd, recorder, episode = paths[i], recorders[i], batch.episodes[i]
        if recorder is not None and record == "failures" and i > 0 and result.outcome == "complete":
            recorder.abort()  # nothing to look at: keep the disk for the failures
            rrd = None
        elif recorder is not None:
            recorder.log_outcome(
                result.duration, result.outcome, result.reason, success=result.outcome == "complete"
            )
            recorder.close()
        distances: list[float] = []
        continuous: list[float] = []
        if result.outcome == "complete":
            columns = continuous_features([demo])
            for v in seq.graphs:
                distances += switch_distances(result.transitions, demo, v) or []
                continuous += switch_distances(result.transitions, demo, v, columns) or []
        out.append(
            EpisodeRecord(
                box=(box.width, box.depth),
                correct=correct_strategy(box, task),
                chosen=classify_start(result.initial, signatures),
                outcome=result.outcome,
                reason=result.reason,
                duration=result.duration,
                distances=distances,
                distances_continuous=continuous,
                recoveries=sum(e.kind == "recovery" for e in episode.events),
                holds=sum(n.kind == "hold" for n in episode.notes),
                rrd=str(rrd) if rrd else None,
            )
        )
        log.info("%sepisode %d: %s (%s)", label, i, result.outcome, result.reason)
    return out


def summarize_episodes(episodes: Sequence[EpisodeRecord]) -> dict[str, Any]:
    """Table I for one set of episodes: counts W/I/C (diverged counted apart, also in I) and
    the mean/std switch-state distance over all complete episodes."""
    counts = {k: 0 for k in ("W", "I", "C", "diverged")}
    for e in episodes:
        if e.outcome == "wrong_start":
            counts["W"] += 1
        elif e.outcome == "complete":
            counts["C"] += 1
        else:
            counts["I"] += 1
            counts["diverged"] += e.outcome == "diverged"
    distances = [d for e in episodes if e.outcome == "complete" for d in e.distances]
    continuous = [d for e in episodes if e.outcome == "complete" for d in e.distances_continuous]
    return {
        **counts,
        "n": len(episodes),
        "distance_mean": float(np.mean(distances)) if distances else None,
        "distance_std": float(np.std(distances)) if distances else None,
        "n_distances": len(distances),
        "distance_continuous_mean": float(np.mean(continuous)) if continuous else None,
        "distance_continuous_std": float(np.std(continuous)) if continuous else None,
        "recoveries": sum(e.recoveries for e in episodes),
        "recovered_episodes": sum(e.recoveries > 0 for e in episodes),
        "recovered_complete": sum(e.recoveries > 0 and e.outcome == "complete" for e in episodes),
        "holds": sum(e.holds for e in episodes),
    }


def strategy_map(
    seq: ConcurrentSequencer,
    task: TaskConfig,
    signatures: Mapping[str, Mapping[str, str]],
    grid: Sequence[int],
) -> dict[str, Any]:
    """Fig. 7: the initial strategy chosen over a width x depth grid against the correct one."""
    from cpmp.sim import Box, Simulation, correct_strategy

    widths = np.linspace(*task.width_range, grid[0])
    depths = np.linspace(*task.depth_range, grid[1])
    chosen = np.empty((len(depths), len(widths)), dtype=object)
    correct = np.empty_like(chosen)
    for j, depth in enumerate(progress_bar(list(depths), "strategy map rows")):
        for i, width in enumerate(widths):
            box = Box(float(width), float(depth), task.box_height)
            x0 = Simulation(task, box).features()
            chosen[j, i] = classify_start(seq.reset(0.0, x0), signatures)
            correct[j, i] = correct_strategy(box, task)
    return {
        "widths": widths,
        "depths": depths,
        "chosen": chosen.astype(str),
        "correct": correct.astype(str),
        "accuracy": float(np.mean(chosen == correct)),
    }
