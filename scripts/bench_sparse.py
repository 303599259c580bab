"""The sparsity benchmark: klr_sparse's defaults against the default predictor (issue #23's
targets: MAE, supports, tick cost, fit time, closed-loop C) per world and D. Writes JSON, prints
a Markdown table.

python scripts/bench_sparse.py [--quick] [--worlds two_point relay repetition sim]
    [--sizes 3 6 9] [--seeds 0 1 2] [--sim-seeds 0] [--cache /tmp/cpmp_sparse]
    [--out logs/bench_sparse.json]
"""

from cpmp.benchmarks.sparse import main

if __name__ == "__main__":
    raise SystemExit(main())
