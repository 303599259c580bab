"""The sections of ``scripts/bench.py`` that need the simulator.

The real-time factor of closed-loop episodes (:func:`bench_realtime`, on the data :class:`SimData`
makes once) and the main job in a fresh process with its stage timings (:func:`bench_stages`). Every
function returns a JSON-ready dict of measurements; nothing here asserts a speed.
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from cpmp.benchmarks.settings import BenchSettings
from cpmp.benchmarks.sim_speed import TARGET_REAL_TIME_FACTOR, time_rollouts
from cpmp.config import TaskConfig
from cpmp.data.demonstration import Demonstration
from cpmp.errors import ConfigError
from cpmp.experiment.strategies import balanced_subset
from cpmp.records import JsonValue
from cpmp.sequencer.sequencer import ConcurrentSequencer
from cpmp.sim import Box, record_demonstration, sample_box
from cpmp.sim.collect import sample_boxes

MAIN_JOB = "from cpmp.cli.main import experiment_main; experiment_main()"
"""What ``cpmp-experiment`` and ``scripts/experiment.py`` run (the ``stages`` section runs it)."""


class SimData:
    """The simulated data the ``fit``, ``sequencer`` and ``realtime`` sections share.

    Made once on first use: training demonstrations, the fitted sequencer, reproduction boxes
    and their expected demonstrations.
    """

    def __init__(self, settings: BenchSettings) -> None:
        self.settings = settings
        self.task = TaskConfig()
        self._train: list[Demonstration] | None = None
        self._seq: ConcurrentSequencer | None = None
        self._boxes: tuple[list[Box], list[Demonstration]] | None = None

    @property
    def train(self) -> list[Demonstration]:
        """The main job's training demonstrations of seed ``seed`` at D = ``fit_demos``."""
        if self._train is None:
            s = self.settings
            rng = np.random.default_rng(s.seed)
            boxes = sample_boxes(rng, self.task, s.fit_demos, balanced=True)
            demos = [
                record_demonstration(b, self.task, name=f"demo_{i:03d}")
                for i, b in enumerate(boxes)
            ]
            self._train = balanced_subset(demos, s.fit_demos)
        return self._train

    @property
    def sequencer(self) -> ConcurrentSequencer:
        """``klr`` fitted on :attr:`train` with the settings' seed."""
        if self._seq is None:
            self._seq = ConcurrentSequencer.fit(
                self.train, "klr", seed=self.settings.seed, logger=None
            )
        return self._seq

    @property
    def boxes(self) -> tuple[list[Box], list[Demonstration]]:
        """``batch`` reproduction boxes and the demonstrator's recording of each.

        The boxes are the main job's of seed ``seed``.
        """
        if self._boxes is None:
            rng = np.random.default_rng(self.settings.seed + 1000)
            boxes = [sample_box(rng, self.task) for _ in range(self.settings.batch)]
            self._boxes = boxes, [record_demonstration(b, self.task) for b in boxes]
        return self._boxes


def bench_realtime(sim: SimData) -> dict[str, JsonValue]:
    """Real-time factor of ``batch`` closed-loop episodes, one at a time and batched.

    The episodes run the fitted sequencer (:func:`cpmp.benchmarks.sim_speed.time_rollouts`).
    """
    boxes, expected = sim.boxes
    seq, task, max_time = sim.sequencer, sim.task, sim.settings.max_time
    single = time_rollouts(boxes, seq, task, expected, batched=False, max_time=max_time)
    batched = time_rollouts(boxes, seq, task, expected, batched=True, max_time=max_time)
    return {
        "n_episodes": len(boxes),
        "target_real_time_factor": TARGET_REAL_TIME_FACTOR,
        "single": single.to_dict(),
        "batched": batched.to_dict(),
        "speedup": single.wall_time_s / batched.wall_time_s,
        "same_outcomes": single.outcomes == batched.outcomes,
    }


def bench_stages(
    experiment: str, threads: int = 1, overrides: Sequence[str] = ()
) -> dict[str, JsonValue]:
    """Run the main job in a fresh process; its wall time and the seconds of every stage.

    ``cpmp-experiment experiment=<experiment> [overrides]`` runs as a user runs it; the
    report has its wall time and its ``timings.json``: seconds per stage (kinematics set-up,
    collect, expected, train, evaluate, reproduce, strategy map, plots).
    """
    with tempfile.TemporaryDirectory(prefix="cpmp-bench-") as tmp:
        run_dir = Path(tmp) / "run"
        command = [
            sys.executable,
            "-c",
            MAIN_JOB,
            f"experiment={experiment}",
            f"hydra.run.dir={run_dir}",
            f"++threads={threads}",
            *overrides,
        ]
        start = time.perf_counter()
        proc = subprocess.run(command, cwd=tmp, capture_output=True, text=True, check=False)
        wall = time.perf_counter() - start
        if proc.returncode != 0:
            error = ConfigError if proc.returncode == 2 else RuntimeError
            raise error(
                f"the main job failed (exit {proc.returncode}): {' '.join(command)}\n"
                f"{proc.stderr[-2000:]}"
            )
        timings = json.loads((run_dir / "timings.json").read_text())
        report = json.loads((run_dir / "report.json").read_text())
    return {
        "experiment": experiment,
        "command": " ".join(
            ["python scripts/experiment.py", f"experiment={experiment}", *overrides]
        ),
        "process_wall_s": wall,
        "job_seconds": timings["seconds"],
        "workers": timings["workers"],
        "stages": timings["stages"],
        "reproduction": {
            d: {k: row[k] for k in ("W", "I", "C")} for d, row in report["reproduction"].items()
        },
    }
