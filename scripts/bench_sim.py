"""Print a JSON speed report of the simulation with IK control and a policy in the loop.

Usage: python scripts/bench_sim.py [--width 0.25 --depth 0.15 --threads 1]
"""

from __future__ import annotations

import argparse
import json

from cpmp.sim import Box, TaskConfig
from cpmp.sim.bench import benchmark


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--width", type=float, default=0.25, help="box width [m]")
    parser.add_argument("--depth", type=float, default=0.15, help="box depth [m]")
    parser.add_argument("--threads", type=int, default=1, help="torch threads")
    args = parser.parse_args()
    cfg = TaskConfig()
    report = benchmark(cfg, Box(args.width, args.depth, cfg.box_height), args.threads)
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
