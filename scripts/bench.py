"""Benchmark cpmp: convex fit vs scikit-learn, sequencer cost, real-time factor, main-job stages,
scaling, gradient-trained predictors. Writes bench.json, bench.md and bench_scaling.png.

python scripts/bench.py                               # every section, the issue's sizes
python scripts/bench.py --quick                       # small sizes, a minute or two
python scripts/bench.py --sections fit,sequencer --fit-demos 6 --out logs/bench/mine
"""

from __future__ import annotations

import argparse
import logging
import sys
import time
from pathlib import Path

from cpmp.errors import CpmpError
from cpmp.experiment.bench import SECTIONS, BenchSettings, run_bench


def _ints(text: str) -> list[int]:
    try:
        return [int(v) for v in text.split(",") if v.strip()]
    except ValueError as err:
        raise argparse.ArgumentTypeError(
            f"expected comma-separated integers, got {text!r}"
        ) from err


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", help="output directory (default: logs/bench/<timestamp>)")
    parser.add_argument("--quick", action="store_true", help="small sizes (BenchSettings.quick)")
    parser.add_argument(
        "--sections", help=f"comma-separated subset of {','.join(SECTIONS)} (default: all)"
    )
    parser.add_argument("--seed", type=int, help="seed of demos, boxes and fits (0)")
    parser.add_argument("--fit-demos", type=int, help="simulated training demos (9)")
    parser.add_argument("--repeats", type=int, help="timed repetitions of each fit (3)")
    parser.add_argument("--batch", type=int, help="episodes run together (20)")
    parser.add_argument("--ticks", type=int, help="ticks per episode, sequencer section (300)")
    parser.add_argument("--max-time", type=float, help="episode time limit [s], realtime")
    parser.add_argument("--experiment", help="experiment= of the stages section (quick)")
    parser.add_argument(
        "--experiment-override",
        action="append",
        dest="experiment_overrides",
        help="Hydra override of the stages run (repeatable), e.g. experiment.workers=2",
    )
    parser.add_argument("--scaling-demos", type=_ints, help="demo counts (3,6,12,25,50)")
    parser.add_argument("--scaling-features", type=_ints, help="feature counts (24,64,128,256)")
    parser.add_argument("--gradient-epochs", type=int, help="cap on mlp/klr_sparse epochs")
    parser.add_argument("--lbfgs", action="store_true", help="also time solver=lbfgs (slow)")
    parser.add_argument("--threads", type=int, help="torch and BLAS threads (1)")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="[%(asctime)s][%(name)s] %(message)s")
    options = {
        name: getattr(args, name)
        for name in (
            "seed",
            "fit_demos",
            "repeats",
            "batch",
            "ticks",
            "max_time",
            "experiment",
            "experiment_overrides",
            "scaling_demos",
            "scaling_features",
            "gradient_epochs",
            "threads",
        )
        if getattr(args, name) is not None
    }
    if args.sections:
        options["sections"] = [s.strip() for s in args.sections.split(",") if s.strip()]
    if args.lbfgs:
        options["lbfgs"] = True
    out = Path(args.out or f"logs/bench/{time.strftime('%Y-%m-%d_%H-%M-%S')}")
    try:
        settings = BenchSettings.quick(**options) if args.quick else BenchSettings(**options)
        path = run_bench(settings, out)
    except CpmpError as err:
        print(f"bench: error: {err}", file=sys.stderr)
        return 2
    print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
