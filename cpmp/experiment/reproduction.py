"""Reproduction (Table I): a fitted sequencer closed-loop on the reproduction boxes.

Each episode is classified (:data:`~cpmp.sim.runner.Outcome`: wrong start, incomplete,
complete) with its switch-state distances; rerun recordings keep the episodes worth looking at
(:data:`~cpmp.experiment.settings.RecordMode`); :func:`summarize_episodes` counts one set of
episodes.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TypedDict

import numpy as np

from cpmp.config.task import TaskConfig
from cpmp.data.demonstration import Demonstration
from cpmp.evaluation.offline import continuous_features, switch_distances
from cpmp.experiment.collection import SeedData
from cpmp.experiment.console import progress_bar
from cpmp.experiment.settings import RecordMode
from cpmp.experiment.strategies import classify_start
from cpmp.recordings import EpisodeRecorder, StartReference
from cpmp.records import TickInfo, count_recoveries
from cpmp.sequencer.episode import SequencerEpisode
from cpmp.sequencer.sequencer import ConcurrentSequencer
from cpmp.sim import Box, Simulation, correct_strategy
from cpmp.sim.runner import Outcome, run_episodes

log = logging.getLogger(__name__)


@dataclass
class EpisodeRecord:
    """One reproduction episode, summarised for the report.

    Attributes:
        box_size_m: the box's (width, depth) [m] (``episodes.json``: ``box_size_m``; a
            recording's metadata: ``box_width_m``, ``box_depth_m``).
        correct: the box's correct strategy.
        chosen: the strategy the sequencer started with (``other`` if none).
        outcome: how the episode ended.
        reason: why, in words.
        duration: simulated time [s].
        distances: switch-state distances of a complete episode.
        distances_continuous: the same over the continuous features only.
        recoveries: stalls the sequencer resolved.
        recoveries_right: recoveries to the MP the demonstrator ran next
            (:func:`cpmp.records.count_recoveries`); ``recoveries_wrong``: the others.
        give_ups: stalls the sequencer gave up on (0 or 1).
        holds: switches the sequencer held back.
        rrd: the episode's recording, if kept.
        cause: an incomplete (or diverged) episode's missing switch
            (:meth:`cpmp.records.PendingSwitch.to_dict`), ``None`` otherwise.
    """

    box_size_m: tuple[float, float]
    correct: str
    chosen: str
    outcome: Outcome
    reason: str
    duration: float
    distances: list[float]
    distances_continuous: list[float] = field(default_factory=list)
    recoveries: int = 0
    recoveries_right: int = 0
    recoveries_wrong: int = 0
    give_ups: int = 0
    holds: int = 0
    rrd: str | None = None
    cause: dict[str, str | float | None] | None = None

    def to_dict(self) -> dict[str, object]:
        """The fields as a dict (``episodes.json``)."""
        return dict(self.__dict__)


START_AXES = ("box_width_m", "box_depth_m")
"""What a recording compares an episode's start with the training starts in: the box's width
and depth [m] (the size decides the strategy, :func:`cpmp.sim.correct_strategy`; the sequencer's
``box_width`` and ``box_depth`` features are these scaled to the task's size ranges)."""


def start_references(demos: Sequence[Demonstration]) -> list[StartReference]:
    """The starts of ``demos``: initial MPs, features at the first sample, box size [m].

    The box size (:data:`START_AXES`) comes from a demonstration's metadata (``box_width``,
    ``box_depth``), where it has them.
    """
    return [
        StartReference(
            demo.name or f"demo {i}",
            initial_mps(demo),
            dict(zip(demo.feature_names or [], demo.features[0].tolist(), strict=True))
            | {
                axis: float(demo.metadata[key])
                for axis, key in zip(START_AXES, ("box_width", "box_depth"), strict=True)
                if key in (demo.metadata or {})
            },
        )
        for i, demo in enumerate(demos)
    ]


def initial_mps(demo: Demonstration) -> dict[str, str]:
    """Each variable's first MP in ``demo`` (the start a run of its box is judged against)."""
    return {v: str(labels[0]) for v, labels in sorted(demo.labels.items())}


class EpisodeLogger:
    """``on_tick`` callback that writes a rerun recording of a sequencer-driven episode.

    At the first tick it also logs the sequencer's start decision against the training starts
    ``references`` (compared in the features ``axes``). A hold note is passed with the MP it
    holds back, so that the recording logs each hold once, with its duration and how many
    times the sequencer noted it (its p hovering at the threshold).

    Args:
        recorder: the episode's :class:`~cpmp.recordings.EpisodeRecorder`.
        seq: the sequencer (or the episode of a batched one) driving the episode (its start
            decision, events and notes are logged).
        references: the training demonstrations' starts.
        axes: what to compare the starts in (features or keys of ``values``).
        correct: the initial MPs the demonstrator uses for the episode's box.
        values: the episode's value of each axis that is not a feature.
    """

    def __init__(
        self,
        recorder: EpisodeRecorder,
        seq: ConcurrentSequencer | SequencerEpisode,
        references: Sequence[StartReference] = (),
        axes: Sequence[str] = (),
        *,
        correct: Mapping[str, str] | None = None,
        values: Mapping[str, float] | None = None,
    ) -> None:
        self.recorder = recorder
        self.seq = seq
        self.references = list(references)
        self.axes = list(axes)
        self.correct = None if correct is None else dict(correct)
        self.values = dict(values or {})
        self._started = False
        self._n_events = 0
        self._n_notes = 0

    def __call__(self, info: TickInfo) -> None:
        """Log one tick: features, progress, active MPs, and the new transitions and notes."""
        tick = self.seq.last_tick
        self.recorder.log_tick(
            info.t,
            info.features,
            tick.progress if tick else {},
            info.active,
            tick.transition_probs if tick else None,
            info.body_poses,
        )
        decision = getattr(self.seq, "start_decision", None)
        if not self._started and decision is not None:
            self.recorder.log_start(
                decision, self.references, self.axes, correct=self.correct, values=self.values
            )
        self._started = True
        # Notes first: a hold noted at the tick its variable switched (to another successor)
        # ended with that switch.
        for note in self.seq.notes[self._n_notes :]:
            held = tick.held.get(note.variable) if tick and note.kind == "hold" else None
            self.recorder.log_note(note.t, note.kind, note.variable, note.text, held=held)
        for event in self.seq.events[self._n_events :]:
            self.recorder.log_transition(
                event.t, event.variable, event.source, event.target, event.probability, event.kind
            )
        self._n_events = len(self.seq.events)
        self._n_notes = len(self.seq.notes)


def reproduce(
    seq: ConcurrentSequencer,
    boxes: Sequence[Box],
    expected: Sequence[Demonstration],
    task: TaskConfig,
    signatures: Mapping[str, Mapping[str, str]],
    *,
    record: RecordMode,
    record_dir: Path | None = None,
    max_time: float | None = None,
    label: str = "",
    train: Sequence[Demonstration] = (),
    pacing_seed: int | None = None,
) -> list[EpisodeRecord]:
    """Run ``seq`` closed-loop on every box; classify outcomes and measure switch distances.

    ``expected[i]`` is the demonstrator's recording of ``boxes[i]``: its switch states are the
    "desired states" of Table Ib. All boxes run together (:func:`cpmp.sim.runner.run_episodes`
    with ``seq.batched``); every number equals a run of one box at a time. ``record``: which
    episodes are written into ``record_dir`` as ``.rrd`` (nothing without ``record_dir``);
    a recording compares its start with the starts of ``train`` (the demonstrations ``seq``
    was fitted on) in :data:`START_AXES`. ``pacing_seed``: with the task's ``robot_*`` pacing
    options set, the robot's pace in episode ``i`` is drawn from ``(pacing_seed, ROBOT_STREAM,
    i)`` (:func:`~cpmp.sim.runner.run_episodes`; ``None``: from the task's ``seed``).
    """
    out: list[EpisodeRecord] = []
    if not boxes:
        return out
    if record_dir is not None and record != "none":
        record_dir.mkdir(parents=True, exist_ok=True)
    batch = seq.batched(len(boxes))
    references = start_references(train)
    axes = [a for a in START_AXES if references and all(a in r.values for r in references)]
    paths: list[Path | None] = []
    recorders: list[EpisodeRecorder | None] = []
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
                metadata={"box_width_m": box.width, "box_depth_m": box.depth},
                threshold=seq.config.threshold,
            )
            callback = EpisodeLogger(
                recorder,
                batch.episodes[i],
                references,
                axes,
                correct=initial_mps(expected[i]),
                values=dict(zip(START_AXES, (box.width, box.depth), strict=True)),
            )
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
            pacing_seed=pacing_seed,
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
        complete = result.outcome == "complete"
        if recorder is not None and record == "failures" and i > 0 and complete:
            recorder.abort()  # nothing to look at: keep the disk for the failures
            rrd = None
        elif recorder is not None:
            recorder.log_outcome(
                result.duration, result.outcome, result.reason, success=complete, cause=result.cause
            )
            recorder.close()
        distances: list[float] = []
        continuous: list[float] = []
        judged = count_recoveries(episode.events, result.expected)
        if complete:
            columns = continuous_features([demo])
            for v in seq.graphs:
                distances += switch_distances(result.transitions, demo, v) or []
                continuous += switch_distances(result.transitions, demo, v, columns) or []
        out.append(
            EpisodeRecord(
                box_size_m=(box.width, box.depth),
                correct=correct_strategy(box, task),
                chosen=classify_start(result.initial, signatures),
                outcome=result.outcome,
                reason=result.reason,
                duration=result.duration,
                distances=distances,
                distances_continuous=continuous,
                recoveries=sum(e.kind == "recovery" for e in episode.events),
                recoveries_right=judged.right,
                recoveries_wrong=judged.wrong,
                give_ups=sum(n.kind == "give_up" for n in episode.notes),
                holds=sum(n.kind == "hold" for n in episode.notes),
                rrd=str(rrd) if rrd else None,
                cause=result.cause.to_dict() if result.cause is not None else None,
            )
        )
        log.info("%sepisode %d: %s (%s)", label, i, result.outcome, result.reason)
    return out


def reproduce_seed(
    seq: ConcurrentSequencer,
    data: SeedData,
    task: TaskConfig,
    *,
    record: RecordMode,
    record_dir: Path | None = None,
    max_time: float | None = None,
    label: str = "",
    train: Sequence[Demonstration] = (),
) -> list[EpisodeRecord]:
    """:func:`reproduce` on one seed's reproduction boxes.

    ``data.boxes`` run against the demonstrator's runs ``data.expected``, the chosen strategies
    told apart by ``data.signatures``; a paced robot (the task's ``robot_*`` options) is paced
    from the run's seed ``data.seed``, as the demonstrations were. The keywords are those of
    :func:`reproduce`.
    """
    return reproduce(
        seq,
        data.boxes,
        data.expected,
        task,
        data.signatures,
        record=record,
        record_dir=record_dir,
        max_time=max_time,
        label=label,
        train=train,
        pacing_seed=data.seed,
    )


class ReproductionSummary(TypedDict):
    """Table I for one set of episodes (:func:`summarize_episodes`), as the report holds it.

    ``W``, ``I``, ``C``: wrong-start, incomplete (diverged included) and complete episodes;
    ``diverged``: the diverged ones; ``n``: all episodes; ``distance_*``: mean and std of the
    switch-state distances over the complete episodes (``None`` without any), over
    ``n_distances`` switches, and over the continuous features only; the recovery, give-up and
    hold counts summed over the episodes; ``causes``: the incomplete episodes per cause.
    """

    W: int
    I: int  # noqa: E741 - Table I's name
    C: int
    diverged: int
    n: int
    distance_mean: float | None
    distance_std: float | None
    n_distances: int
    distance_continuous_mean: float | None
    distance_continuous_std: float | None
    recoveries: int
    recovered_episodes: int
    recovered_complete: int
    recoveries_right: int
    recoveries_wrong: int
    give_ups: int
    holds: int
    causes: dict[str, int]


def summarize_episodes(episodes: Sequence[EpisodeRecord]) -> ReproductionSummary:
    """Table I for one set of episodes: the W/I/C counts and the switch-state distances.

    Diverged episodes are counted apart and also in I; the distance mean/std is over all
    complete episodes; ``causes``: the incomplete episodes per cause
    (:data:`~cpmp.records.CauseReason`).
    """
    counts = {k: 0 for k in ("W", "I", "C", "diverged")}
    for e in episodes:
        if e.outcome == "wrong_start":
            counts["W"] += 1
        elif e.outcome == "complete":
            counts["C"] += 1
        else:
            counts["I"] += 1
            counts["diverged"] += e.outcome == "diverged"
    complete = [e for e in episodes if e.outcome == "complete"]
    distances = [d for e in complete for d in e.distances]
    continuous = [d for e in complete for d in e.distances_continuous]
    return {
        "W": counts["W"],
        "I": counts["I"],
        "C": counts["C"],
        "diverged": counts["diverged"],
        "n": len(episodes),
        "distance_mean": float(np.mean(distances)) if distances else None,
        "distance_std": float(np.std(distances)) if distances else None,
        "n_distances": len(distances),
        "distance_continuous_mean": float(np.mean(continuous)) if continuous else None,
        "distance_continuous_std": float(np.std(continuous)) if continuous else None,
        "recoveries": sum(e.recoveries for e in episodes),
        "recovered_episodes": sum(e.recoveries > 0 for e in episodes),
        "recovered_complete": sum(e.recoveries > 0 for e in complete),
        "recoveries_right": sum(e.recoveries_right for e in episodes),
        "recoveries_wrong": sum(e.recoveries_wrong for e in episodes),
        "give_ups": sum(e.give_ups for e in episodes),
        "holds": sum(e.holds for e in episodes),
        "causes": cause_counts(episodes),
    }


def cause_counts(episodes: Sequence[EpisodeRecord]) -> dict[str, int]:
    """The incomplete (and diverged) episodes per cause reason, most frequent first."""
    counts: dict[str, int] = {}
    for e in episodes:
        if e.outcome in ("incomplete", "diverged"):
            reason = str((e.cause or {}).get("reason", "none"))
            counts[reason] = counts.get(reason, 0) + 1
    return dict(sorted(counts.items(), key=lambda kv: (-kv[1], kv[0])))
