"""Benchmark cpmp: convex fit vs scikit-learn, sequencer cost, real-time factor, main-job stages,
scaling, gradient-trained predictors. Writes bench.json, bench.md and bench_scaling.png.

python scripts/bench.py                               # every section, the issue's sizes
python scripts/bench.py --quick                       # small sizes (see docs/benchmarks.md)
python scripts/bench.py --sections fit,sequencer --fit-demos 6 --out logs/bench/mine
"""

from cpmp.benchmarks.cli import bench_main

if __name__ == "__main__":
    raise SystemExit(bench_main())
