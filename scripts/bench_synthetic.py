"""Closed-loop outcomes on the two synthetic tasks (no simulator): cpmp's defaults, the paper's
method and single options switched off, over training sizes and seeds. Prints JSON.

python scripts/bench_synthetic.py [--seeds 0 1 2] [--sizes 3 6 9] [--episodes 20] [--out FILE]
"""

from cpmp.benchmarks.cli import bench_synthetic_main

if __name__ == "__main__":
    raise SystemExit(bench_synthetic_main())
