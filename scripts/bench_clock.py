"""The clock benchmark: completion and switch-time error of the default sequencer on every
synthetic world and the simulator under control rates, jitter, dropped ticks, slow sensors, a
clock step and NaN bursts. Writes JSON, prints a Markdown table.

python scripts/bench_clock.py [--quick] [--worlds two_point relay repetition sim] [--seeds 0 1 2]
    [--episodes 20] [--sim-seeds 0] [--out logs/bench_clock.json]
"""

from cpmp.benchmarks.clock import main

if __name__ == "__main__":
    raise SystemExit(main())
