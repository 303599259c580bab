"""Wrong starts of cpmp's start rules against classifiers handed the true box size, scored on
many fresh boxes (the start depends only on the first feature vector). JSON + Markdown.

python scripts/bench_start.py [--seeds 0 1 2 3 4] [--sizes 3 6 9] [--boxes 200] [--out FILE.json]
"""

from cpmp.benchmarks.cli import bench_start_main

if __name__ == "__main__":
    raise SystemExit(bench_start_main())
