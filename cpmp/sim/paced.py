"""The simulator as a paced world (issue #23): varied demonstrations and a closed loop to score.

With the task's pacing options (:class:`~cpmp.config.task.TaskConfig`: ``demo_speed``,
``demo_pause``, ``demo_pause_probability`` for the scripted demonstrator; ``robot_speed``,
``robot_pause``, ``robot_pause_probability`` for the closed-loop robot; all off by default),
every activation of an MP runs at its own speed factor and may hold once mid-MP
(:mod:`cpmp.worlds.pacing`), so that eq. 1 and elapsed time disagree. ``conf/experiment/
varied.yaml`` sets them for the main job: demonstrations x0.5-2 with a 0.3-1 s hold in half the
activations; the robot x0.5-2 without holds.

**The closed-loop robot** varies its speed as the demonstrator did (a robot carrying loads runs
slower; the world is one where an MP's duration does not tell its progress, whoever runs it).
The predictors read features, not clocks, so its speed reaches them only through the switching
rule's timing, alike for every label. It does not hold by default: in the features, a hold
mid-MP is the state of an arrival for *every* feature-based progress (φ stops rising and the
paper's rule fires once ``p`` passes the threshold), so closed-loop holds test the switching
rule, not the labels; ``robot_pause`` turns them on for that test.

:func:`paced_sim` is the face the comparison uses (:class:`~cpmp.worlds.pacing.PacedWorld`)::

    world = paced_sim(seed, n_demos, cfg)      # cfg: TaskConfig with the pacing options set
    world.demonstrations                       # list[Demonstration], strategies balanced
    world.evaluate(policy, n_boxes, seed)      # list[EpisodeScore], one per box
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from cpmp.config.task import TaskConfig, as_task_config
from cpmp.config.validation import OptionValue
from cpmp.records import Policy
from cpmp.sim.collect import record_demonstrations, sample_boxes
from cpmp.sim.runner import run_episodes
from cpmp.sim.scene import correct_strategy
from cpmp.worlds.pacing import EpisodeScore, PacedWorld


def paced_sim(
    seed: int, n_demos: int, cfg: TaskConfig | Mapping[str, OptionValue] | None = None
) -> PacedWorld:
    """The simulator's world of ``seed``: scripted demonstrations and the closed loop.

    Args:
        seed: draws the demonstrations' boxes (strategies balanced round-robin) and seeds
            their pacing.
        n_demos: the number of demonstrations.
        cfg: the task, its pacing options set (default: the task's defaults, unpaced).

    Returns:
        ``demonstrations`` (named ``demo_<i>_<strategy>``) and ``evaluate(policy, n_boxes,
        seed)``: the policy (a fitted sequencer, a batched policy or one policy per box) on
        ``n_boxes`` boxes drawn from ``seed`` (balanced), the robot paced from ``seed``; one
        :class:`~cpmp.worlds.pacing.EpisodeScore` per box (``diverged`` scores
        ``incomplete``).
    """
    cfg = as_task_config(cfg)
    boxes = sample_boxes(np.random.default_rng(seed), cfg, n_demos, balanced=True)
    names = [f"demo_{i:03d}_{correct_strategy(box, cfg)}" for i, box in enumerate(boxes)]
    demos = record_demonstrations(boxes, cfg, names=names, pacing_seed=seed)

    def evaluate(policy: Policy, n_boxes: int, seed: int) -> list[EpisodeScore]:
        test_boxes = sample_boxes(np.random.default_rng(seed), cfg, n_boxes, balanced=True)
        results = run_episodes(test_boxes, policy, cfg, pacing_seed=seed)
        return [
            EpisodeScore(
                "incomplete" if r.outcome == "diverged" else r.outcome,
                correct_strategy(box, cfg),
                r.duration,
                r.reason,
                r.cause,
            )
            for box, r in zip(test_boxes, results, strict=True)
        ]

    return PacedWorld(demos, evaluate)
