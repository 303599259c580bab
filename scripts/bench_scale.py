"""The scale benchmark: the default fit at 12 / 48 / 192 / 768 demonstrations of two_point and
relay, each size in its own process (issue #34's targets: fit time, peak RSS, supports,
held-out MAE, closed-loop C, growth exponents), and 400 episodes of two_point written as a
LeRobot v3 dataset, imported by cpmp-import and fitted. Writes JSON, prints a Markdown table.

python scripts/bench_scale.py [--quick] [--worlds two_point relay] [--sizes 12 48 192 768]
    [--seed 0] [--held-out 20] [--episodes 20] [--timeout 1800] [--pythonpath OTHER_CHECKOUT]
    [--lerobot 400]
    [--out logs/bench_scale.json]
"""

from cpmp.benchmarks.scale import main

if __name__ == "__main__":
    raise SystemExit(main())
