"""Speed benchmark of the simulation with IK control and a policy in the loop."""

from __future__ import annotations

import time
from typing import Any

import torch

from cpmp.sim.config import TaskConfig
from cpmp.sim.runner import ReplayPolicy, record_demonstration, run_episode
from cpmp.sim.scene import Box


def benchmark(cfg: TaskConfig, box: Box, threads: int = 1) -> dict[str, Any]:
    """Time one recorded demonstration and one closed-loop episode on ``box``.

    The episode replays the demonstration's labels (a policy of negligible cost), so its
    real-time factor is that of physics + IK + features. Returns a JSON-ready dict: simulated
    and wall times [s], real-time factors, and the episode's wall-time shares of physics,
    kinematics (IK + features), policy and the rest (bookkeeping).
    """
    torch.set_num_threads(threads)
    start = time.perf_counter()
    demo = record_demonstration(box, cfg)
    demo_wall = time.perf_counter() - start
    start = time.perf_counter()
    result = run_episode(box, ReplayPolicy(demo), cfg, expected=demo)
    wall = time.perf_counter() - start
    timing = result.timing
    other = wall - sum(timing.values())
    return {
        "box": {"width": box.width, "depth": box.depth, "height": box.height},
        "torch_threads": threads,
        "demonstration": {
            "sim_time_s": float(demo.duration),
            "wall_time_s": demo_wall,
            "real_time_factor": float(demo.duration) / demo_wall,
            "success": bool((demo.metadata or {}).get("success")),
        },
        "episode": {
            "outcome": result.outcome,
            "sim_time_s": result.duration,
            "wall_time_s": wall,
            "real_time_factor": result.duration / wall,
            "share": {
                "physics": timing["physics"] / wall,
                "kinematics": timing["kinematics"] / wall,
                "policy": timing["policy"] / wall,
                "other": other / wall,
            },
        },
    }
