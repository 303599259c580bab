"""Wrong starts of cpmp's start rules against classifiers handed the true box size, scored on
many fresh boxes (the start depends only on the first feature vector). JSON + Markdown.

python scripts/bench_start.py [--seeds 0 1 2 3 4] [--sizes 3 6 9] [--boxes 200] [--out FILE.json]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import torch

from cpmp.experiment.start_analysis import analyse_starts, markdown
from cpmp.io import atomic_write_text


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    parser.add_argument("--sizes", type=int, nargs="+", default=[3, 6, 9])
    parser.add_argument("--boxes", type=int, default=200, help="scored boxes per seed")
    parser.add_argument("--out", default=None, help="write the JSON here (and .md beside it)")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    result = analyse_starts(args.seeds, args.sizes, args.boxes)
    text = json.dumps(result, indent=2)
    if args.out:
        out = Path(args.out)
        atomic_write_text(out, text)
        atomic_write_text(out.with_suffix(".md"), markdown(result))
    print(markdown(result), file=sys.stderr)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
