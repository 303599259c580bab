"""Closed-loop outcomes on the two synthetic tasks (no simulator): cpmp's defaults, the paper's
method and single options switched off, over training sizes and seeds. Prints JSON.

python scripts/bench_synthetic.py [--seeds 0 1 2] [--sizes 3 6 9] [--episodes 20] [--out FILE]
"""

from __future__ import annotations

import argparse
import json
import sys

import torch

from cpmp.io import atomic_write_text
from cpmp.sequencer import PAPER_OPTIONS, ConcurrentSequencer
from cpmp.synthetic import evaluate as evaluate_two_point
from cpmp.synthetic import make_demonstrations as two_point_demos
from cpmp.synthetic_relay import evaluate as evaluate_relay
from cpmp.synthetic_relay import make_demonstrations as relay_demos

CONFIGS = {
    "defaults": {},
    "coupling=none": {"coupling": "none"},
    "switch_rule=plateau": {"switch_rule": "plateau"},
    "recovery=false": {"recovery": False},
    "paper": dict(PAPER_OPTIONS),
}
TASKS = {
    "two_point": (two_point_demos, lambda seq, s, n: evaluate_two_point(seq, None, n, 1000 + s)),
    "relay": (relay_demos, lambda seq, s, n: evaluate_relay(seq, None, n, 1000 + s)),
}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--sizes", type=int, nargs="+", default=[3, 6, 9])
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--configs", nargs="+", default=list(CONFIGS), choices=list(CONFIGS))
    parser.add_argument("--out", default=None, help="also write the JSON to this file")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    rows = []
    for task, (make, evaluate) in TASKS.items():
        for d in args.sizes:
            for seed in args.seeds:
                demos = make(d, seed)
                for name in args.configs:
                    seq = ConcurrentSequencer.fit(
                        demos, "klr", seed=seed, logger=None, **CONFIGS[name]
                    )
                    counts = evaluate(seq, seed, args.episodes)
                    row = {"task": task, "D": d, "seed": seed, "config": name}
                    rows.append(
                        {**row, **{k: counts[k] for k in ("complete", "wrong_start", "incomplete")}}
                    )
                    print(json.dumps(rows[-1]), file=sys.stderr, flush=True)
    text = json.dumps({"episodes": args.episodes, "rows": rows}, indent=2)
    if args.out:
        atomic_write_text(args.out, text + "\n")
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
