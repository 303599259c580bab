"""Print a JSON speed report of the simulation with IK control and a policy in the loop.

Usage: python scripts/bench_sim.py [--width 0.25 --depth 0.15 --threads 1 --demos 6 --seed 1]

``replay`` times physics + IK + features (the demonstration's labels replayed); ``learned``
times the full loop with a sequencer fitted on ``--demos`` demonstrations (0 skips it).
"""

from cpmp.benchmarks.cli import bench_sim_main

if __name__ == "__main__":
    raise SystemExit(bench_sim_main())
