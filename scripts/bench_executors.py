"""The executor benchmark: the same jobs (small torch jobs, the main job experiment=tiny with
two seeds) on the inline, local, submitit (cluster=local) and dask (LocalCluster) backends:
wall time, start, cost per job, identical numbers. Writes JSON, prints a Markdown table.

python scripts/bench_executors.py [--quick] [--backends inline local submitit dask]
    [--jobs 16] [--workers 2] [--no-main-job] [--out logs/bench_executors.json]
"""

from cpmp.benchmarks.executors import main

if __name__ == "__main__":
    raise SystemExit(main())
