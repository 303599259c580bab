"""Print a JSON speed report of the simulation with IK control and a policy in the loop.

Usage: python scripts/bench_sim.py [--width 0.25 --depth 0.15 --threads 1 --demos 6 --seed 1]

``replay`` times physics + IK + features (the demonstration's labels replayed); ``learned``
times the full loop with a sequencer fitted on ``--demos`` demonstrations (0 skips it).
"""

from __future__ import annotations

import argparse
import json
import sys

from cpmp.errors import CpmpError
from cpmp.sim import Box, TaskConfig
from cpmp.sim.bench import benchmark


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--width", type=float, default=0.25, help="box width [m]")
    parser.add_argument("--depth", type=float, default=0.15, help="box depth [m]")
    parser.add_argument("--threads", type=int, default=1, help="torch threads")
    parser.add_argument("--demos", type=int, default=6, help="demos for the learned policy")
    parser.add_argument("--seed", type=int, default=1, help="seed of the training boxes")
    args = parser.parse_args(argv)
    cfg = TaskConfig()
    try:
        box = Box(args.width, args.depth, cfg.box_height)
        report = benchmark(cfg, box, args.threads, n_demos=args.demos, seed=args.seed)
    except CpmpError as err:
        print(f"bench_sim: error: {err}", file=sys.stderr)
        return 2
    print(json.dumps(report, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
