"""Stage 1 of the main job, per seed: the scripted demonstrations and the reproduction boxes.

The demonstrations are split into train and test (saved with the split); the demonstrator
runs every reproduction box once, as the expected result.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from omegaconf import DictConfig

from cpmp.config.task import TaskConfig
from cpmp.data.augment import add_feature_noise
from cpmp.data.datafile import save_demonstrations
from cpmp.data.demonstration import Demonstration
from cpmp.experiment.config import experiment_job
from cpmp.experiment.console import progress_bar, timed
from cpmp.experiment.settings import ExperimentJob
from cpmp.experiment.strategies import split_by_strategy, strategy_signatures
from cpmp.recordings.demos import record_demo_rrd
from cpmp.sim import Box, record_demonstrations, sample_box
from cpmp.sim.collect import sample_boxes
from cpmp.sim.simulation import shared_kinematics


@dataclass
class SeedData:
    """One seed's collected data, handed to each of its training sizes.

    Attributes:
        seed: the seed.
        train: training demonstrations (with feature noise when ``feature_noise > 0``).
        test: held-out demonstrations.
        boxes: the reproduction boxes.
        expected: the demonstrator's recording of each reproduction box.
        signatures: initial MP per variable of each demonstrated strategy.
        seconds: wall time [s] per stage (``kinematics``: building the arm kinematics, once
            per process; ``collect``; ``expected``).
    """

    seed: int
    train: list[Demonstration]
    test: list[Demonstration]
    boxes: list[Box]
    expected: list[Demonstration]
    signatures: dict[str, dict[str, str]]
    seconds: dict[str, float] = field(default_factory=dict)


def collect_seed(job: ExperimentJob | DictConfig, run_dir: str | Path, seed: int) -> SeedData:
    """Stage 1 of one seed: its demonstrations and the demonstrator on every reproduction box.

    The demonstrations are saved as ``seed_<s>/demos.h5`` with the train/test split.

    Args:
        job: the typed job (or its composed config, converted here).
        run_dir: the run directory.
        seed: the seed of the demonstrations' boxes (and, offset, of the reproduction boxes).

    Raises:
        RuntimeError: the scripted demonstrator failed on a box.
    """
    job = experiment_job(job)
    settings, task = job.settings, job.task
    seed_dir = Path(run_dir) / f"seed_{seed}"
    seed_dir.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    shared_kinematics(task.compile_kinematics)  # built (compiled) once per process
    seconds: dict[str, float] = {"kinematics": time.perf_counter() - start}
    n_demos = 3 * settings.demos_per_strategy
    with timed(seconds, "collect", f"seed {seed}: collect {n_demos} demonstrations"):
        rng = np.random.default_rng(seed)
        boxes = sample_boxes(rng, task, n_demos, balanced=True)
        names = [f"demo_{i:03d}" for i in range(n_demos)]
        demos = _record_together(boxes, task, names, f"seed {seed} demos", seed)
        failed = [d.name for d in demos if not d.metadata.get("success")]
        if failed:
            raise RuntimeError(f"the scripted demonstrator failed on {failed}")
        if settings.record_demos:
            (seed_dir / "recordings").mkdir(exist_ok=True)
            for demo, box in zip(demos, boxes, strict=True):
                record_demo_rrd(demo, box, task, seed_dir / "recordings" / f"{demo.name}.rrd")
        train, test = split_by_strategy(demos, settings.train_per_strategy)
        save_demonstrations(
            seed_dir / "demos.h5",
            demos,
            splits={"train": [d.name for d in train], "test": [d.name for d in test]},
        )
    name = f"seed {seed}: demonstrator on {settings.n_boxes} reproduction boxes"
    with timed(seconds, "expected", name):
        box_rng = np.random.default_rng(seed + settings.box_seed_offset)
        repro_boxes = [sample_box(box_rng, task) for _ in range(settings.n_boxes)]
        expected = _record_together(
            repro_boxes, task, None, "expected", seed + settings.box_seed_offset
        )
    signatures = strategy_signatures(train)
    if settings.feature_noise > 0:
        train = add_feature_noise(train, settings.feature_noise, seed=seed)
    return SeedData(seed, train, test, repro_boxes, expected, signatures, seconds)


def _record_together(
    boxes: Sequence[Box], task: TaskConfig, names: list[str] | None, desc: str, seed: int
) -> list[Demonstration]:
    """The scripted demonstrations of ``boxes``, all boxes run together, with a progress bar.

    :func:`cpmp.sim.record_demonstrations` gives the same data as one box at a time; with the
    task's ``demo_*`` pacing options, the demonstrator's pace is drawn from ``seed``.
    """
    bar = progress_bar(boxes, desc)
    try:
        return record_demonstrations(
            boxes, task, names, on_result=lambda i, demo: bar.update(1), pacing_seed=seed
        )
    finally:
        bar.close()
