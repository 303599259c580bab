"""Benchmark fitting and per-tick cost of the sequencer for each predictor; prints JSON.

python scripts/bench_sequencer.py                      # synthetic demos
python scripts/bench_sequencer.py --data demos.h5      # your own (or collected) demos
"""

import argparse
import json
import sys

import torch

from cpmp.errors import CpmpError
from cpmp.experiment.bench import bench_sequencer


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", help="HDF5 demonstrations (default: 6 synthetic demos)")
    parser.add_argument("--split", default=None, help="split of --data to train on")
    parser.add_argument("--predictors", default="klr,klr_sparse,mlp,klr_full")
    parser.add_argument("--ticks", type=int, default=500)
    parser.add_argument("--threads", type=int, default=1)
    args = parser.parse_args(argv)
    torch.set_num_threads(args.threads)
    try:
        if args.data:
            from cpmp.data import load_demonstrations

            demos = load_demonstrations(args.data, split=args.split)
        else:
            from cpmp.synthetic import make_demonstrations

            demos = make_demonstrations(6, seed=0)
        result = bench_sequencer(demos, args.predictors.split(","), n_ticks=args.ticks)
    except CpmpError as err:
        print(f"bench_sequencer: error: {err}", file=sys.stderr)
        return 2
    print(json.dumps(result, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
