"""Rerun recordings of demonstrations, replayed in the simulator (``experiment.record_demos``).

A recorded demonstration's MP labels are replayed in the simulator and the episode written as
an ``.rrd`` in the layout of :mod:`cpmp.recordings`.

The recording has the robot and box geometry, the features, the active MP per variable and
the body poses at every control tick. There are no progress values (no predictor is involved:
the ``progress/`` entities are absent); each switch of the demonstration's labels is logged as
a transition with probability 1.0 (the demonstrator switched for certain), and the replay's
outcome at the end.
"""

from __future__ import annotations

import os
from dataclasses import replace
from pathlib import Path

from cpmp.config.task import TaskConfig
from cpmp.data.demonstration import Demonstration
from cpmp.errors import DataError
from cpmp.recordings.writer import EpisodeRecorder
from cpmp.records import JsonValue, TickInfo, TransitionEvent
from cpmp.sim import Box, Simulation, run_episode
from cpmp.sim.policies import ReplayPolicy

DEMO_TRANSITION_PROBABILITY = 1.0
"""Probability logged with a demonstrated switch (it is a label, not a prediction)."""

_TIME_TOL = 1e-9
"""[s] a switch at ``t`` is logged at the first tick with ``tick.t >= t - _TIME_TOL``; ticks lie
on the ``control_dt`` grid, so only float round-off needs absorbing."""


def label_switches(demo: Demonstration) -> list[TransitionEvent]:
    """Every label change of ``demo`` with probability :data:`DEMO_TRANSITION_PROBABILITY`.

    The changes are :meth:`~cpmp.data.Demonstration.transitions`, in time order (variables in
    ``demo.variables`` order at equal times).
    """
    return [replace(e, probability=DEMO_TRANSITION_PROBABILITY) for e in demo.transitions()]


class _DemoLogger:
    """``on_tick`` callback: logs the tick, then the demonstrated switches due by its time."""

    def __init__(self, recorder: EpisodeRecorder, switches: list[TransitionEvent]) -> None:
        self.recorder = recorder
        self.pending = list(switches)

    def __call__(self, info: TickInfo) -> None:
        """Log the tick, then the switches due by its time."""
        self.recorder.log_tick(info.t, info.features, {}, info.active, None, info.body_poses)
        self.flush(info.t)

    def flush(self, t: float) -> None:
        """Log the pending switches at or before ``t`` [s]."""
        while self.pending and self.pending[0].t <= t + _TIME_TOL:
            e = self.pending.pop(0)
            self.recorder.log_transition(e.t, e.variable, e.source, e.target, e.probability, e.kind)


def record_demo_rrd(
    demo: Demonstration,
    box: Box,
    task: TaskConfig,
    path: str | os.PathLike[str],
    *,
    max_time: float | None = None,
) -> Path:
    """Replay ``demo``'s labels open-loop on ``box`` and write the episode to ``path`` (.rrd).

    ``demo`` must be a recording of ``box`` under ``task`` (e.g. from
    :func:`cpmp.sim.record_demonstration`): its MP names and feature names are the
    simulator's. ``max_time`` [s] defaults to the task's limit. The file is written atomically
    (a failed replay leaves none); returns ``path``. The replay's outcome (normally
    ``complete``) and reason are logged at the end; switches the replay did not reach (it
    ended early) are not logged.

    Raises:
        DataError: ``demo``'s feature names are not the simulator's.
    """
    sim = Simulation(task, box)
    if list(demo.feature_names) != list(sim.feature_names):
        raise DataError(
            f"{demo.name or 'demonstration'}: feature names differ from the simulator's; "
            "record_demo_rrd replays demonstrations recorded in cpmp.sim only"
        )
    metadata: dict[str, JsonValue] = {
        "kind": "demonstration",
        "demo": demo.name,
        "box_width": box.width,
        "box_depth": box.depth,
        **{k: v for k, v in (demo.metadata or {}).items() if k not in ("box_width", "box_depth")},
    }
    recorder = EpisodeRecorder(
        path,
        feature_names=sim.feature_names,
        mp_names=sim.mp_names,
        episode=demo.name or Path(path).stem,
        geoms=sim.geoms(),
        metadata=metadata,
        threshold=None,  # a replay has no switching rule: its switches are p = 1
    )
    logger = _DemoLogger(recorder, label_switches(demo))
    try:
        result = run_episode(
            box, ReplayPolicy(demo), task, max_time=max_time, expected=demo, on_tick=logger
        )
        logger.flush(result.duration)
        recorder.log_outcome(
            result.duration,
            result.outcome,
            result.reason,
            success=result.outcome == "complete",
        )
    except BaseException:
        recorder.abort()
        raise
    return recorder.close()
