"""Benchmark fitting and per-tick cost of the sequencer for each predictor; prints JSON.

python scripts/bench_sequencer.py                      # synthetic demos
python scripts/bench_sequencer.py --data demos.h5      # your own (or collected) demos
"""

from cpmp.benchmarks.cli import bench_sequencer_main

if __name__ == "__main__":
    raise SystemExit(bench_sequencer_main())
