"""The worlds table: every registered synthetic world x the scripted policy, the paper's method,
the BC switcher, goal_nearest, cpmp's defaults and klr_sparse, at D = 3 / 6 / 9 (no simulator).
Writes JSON, prints a Markdown table.

python scripts/bench_synthetic.py [--quick] [--worlds ...] [--policies ...] [--sizes 3 6 9]
    [--seeds 0 1 2] [--episodes 20] [--tasks 100] [--out logs/bench_synthetic.json]
"""

from cpmp.benchmarks.synthetic import main

if __name__ == "__main__":
    raise SystemExit(main())
