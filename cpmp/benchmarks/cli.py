"""The command lines of the benchmark scripts (``scripts/bench*.py`` are two-line wrappers).

Each parses its arguments, runs its benchmark and prints JSON (and the path it wrote, for
``bench.py``). A :class:`~cpmp.errors.CpmpError` (a bad option, a missing file) becomes one
``<name>: error:`` line on stderr and exit status 2. The benchmark modules (torch, MuJoCo,
scikit-learn) are imported inside each command, after its arguments are parsed.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Protocol, TypeVar

import torch

from cpmp.benchmarks.settings import SECTIONS, BenchSettings
from cpmp.config import TaskConfig
from cpmp.errors import CpmpError
from cpmp.io import atomic_write_text
from cpmp.records import JsonValue

SettingsT = TypeVar("SettingsT")
SettingsT_co = TypeVar("SettingsT_co", covariant=True)


class SettingsClass(Protocol[SettingsT_co]):
    """A benchmark's settings class: built from the options given, or small with ``quick``."""

    def __call__(self, **options: object) -> SettingsT_co:
        """The settings of ``options`` (each field's default where not given)."""
        ...

    def quick(self, **options: object) -> SettingsT_co:
        """The small settings of a test run, with ``options`` over them."""
        ...


def _print_json(name: str, measure: Callable[[], dict[str, JsonValue]]) -> int:
    """Print ``measure()`` as indented JSON and return 0.

    When it raises a :class:`CpmpError`, print ``<name>: error: ...`` to stderr and return 2.
    """
    try:
        result = measure()
    except CpmpError as err:
        print(f"{name}: error: {err}", file=sys.stderr)
        return 2
    print(json.dumps(result, indent=2))
    return 0


def given_options(args: argparse.Namespace, names: tuple[str, ...]) -> dict[str, object]:
    """The options among ``names`` given on the command line (lists as tuples).

    The values are passed through to a settings class, which checks them.
    """
    return {
        name: tuple(value) if isinstance(value, list) else value
        for name in names
        if (value := getattr(args, name)) is not None
    }


def run_settings_benchmark(
    name: str,
    args: argparse.Namespace,
    settings_class: SettingsClass[SettingsT],
    options: dict[str, object],
    run: Callable[[SettingsT, Callable[[str], None]], dict[str, JsonValue]],
    markdown: Callable[[dict[str, JsonValue]], str],
) -> int:
    """The command line's end of a benchmark with a settings class (``bench_clock``, ...).

    On one thread: the settings from ``options`` (``settings_class.quick`` with ``--quick``),
    ``run(settings, log)`` with progress lines to stderr, the result written as JSON to
    ``args.out`` (atomically), its Markdown table and the file's path printed.

    Returns:
        0, or 2 after a :class:`~cpmp.errors.CpmpError` (a bad option), said on stderr as
        ``<name>: error: ...``.
    """
    torch.set_num_threads(1)
    started = time.perf_counter()
    try:
        settings = settings_class.quick(**options) if args.quick else settings_class(**options)
        result = run(settings, lambda line: print(line, file=sys.stderr))
    except CpmpError as err:
        print(f"{name}: error: {err}", file=sys.stderr)
        return 2
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(out, json.dumps(result, indent=1) + "\n")
    print(markdown(result), end="")
    print(f"{out} ({time.perf_counter() - started:.0f} s)")
    return 0


def _ints(text: str) -> list[int]:
    """Comma-separated integers (an ``argparse`` type)."""
    try:
        return [int(v) for v in text.split(",") if v.strip()]
    except ValueError as err:
        raise argparse.ArgumentTypeError(
            f"expected comma-separated integers, got {text!r}"
        ) from err


def bench_main(argv: list[str] | None = None) -> int:
    """``scripts/bench.py``: benchmark cpmp; prints the path of bench.json.

    The sections: convex fit vs scikit-learn, sequencer cost, real-time factor, main-job
    stages, scaling, gradient-trained predictors. Writes bench.json, bench.md and
    bench_scaling.png.
    """
    parser = argparse.ArgumentParser(
        description=(
            "Benchmark cpmp: convex fit vs scikit-learn, sequencer cost, real-time factor, "
            "main-job stages, scaling, gradient-trained predictors."
        )
    )
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
    parser.add_argument("--gradient-epochs", type=int, help="cap on mlp epochs")
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
    from cpmp.benchmarks.suite import run_bench  # lazy: torch, MuJoCo after the arguments

    try:
        settings = BenchSettings.quick(**options) if args.quick else BenchSettings(**options)
        path = run_bench(settings, out)
    except CpmpError as err:
        print(f"bench: error: {err}", file=sys.stderr)
        return 2
    print(path)
    return 0


def bench_sequencer_main(argv: list[str] | None = None) -> int:
    """``scripts/bench_sequencer.py``: fit and per-tick cost of the sequencer per predictor.

    On 6 synthetic demos or ``--data`` (your own or collected demos); prints JSON.
    """
    parser = argparse.ArgumentParser(
        description=(
            "Benchmark fitting and per-tick cost of the sequencer for each predictor; prints JSON."
        )
    )
    parser.add_argument("--data", help="HDF5 demonstrations (default: 6 synthetic demos)")
    parser.add_argument("--split", default=None, help="split of --data to train on")
    parser.add_argument("--predictors", default="klr,klr_sparse,mlp,klr_full")
    parser.add_argument("--ticks", type=int, default=500)
    parser.add_argument("--threads", type=int, default=1)
    args = parser.parse_args(argv)
    import torch  # lazy: torch after the arguments

    from cpmp.benchmarks.sequencer import bench_sequencer  # lazy: torch after the arguments
    from cpmp.data.datafile import load_demonstrations  # lazy: h5py after the arguments
    from cpmp.worlds.two_point import make_demonstrations  # lazy: torch after the arguments

    torch.set_num_threads(args.threads)

    def measure() -> dict[str, JsonValue]:
        if args.data:
            demos = load_demonstrations(args.data, split=args.split)
        else:
            demos = make_demonstrations(6, seed=0)
        return bench_sequencer(demos, args.predictors.split(","), n_ticks=args.ticks)

    return _print_json("bench_sequencer", measure)


def bench_sim_main(argv: list[str] | None = None) -> int:
    """``scripts/bench_sim.py``: a JSON speed report of the simulation with a policy in the loop.

    ``replay`` times physics + IK + features (the demonstration's labels replayed);
    ``learned`` times the full loop with a sequencer fitted on ``--demos`` demonstrations (0
    skips it).
    """
    parser = argparse.ArgumentParser(
        description=(
            "Print a JSON speed report of the simulation with IK control and a policy in the loop."
        )
    )
    parser.add_argument("--width", type=float, default=0.25, help="box width [m]")
    parser.add_argument("--depth", type=float, default=0.15, help="box depth [m]")
    parser.add_argument("--threads", type=int, default=1, help="torch threads")
    parser.add_argument("--demos", type=int, default=6, help="demos for the learned policy")
    parser.add_argument("--seed", type=int, default=1, help="seed of the training boxes")
    args = parser.parse_args(argv)
    from cpmp.benchmarks.sim import benchmark  # lazy: torch, MuJoCo after the arguments
    from cpmp.sim import Box  # lazy: MuJoCo after the arguments

    cfg = TaskConfig()

    def measure() -> dict[str, JsonValue]:
        box = Box(args.width, args.depth, cfg.box_height)
        return benchmark(cfg, box, args.threads, n_demos=args.demos, seed=args.seed)

    return _print_json("bench_sim", measure)


def bench_start_main(argv: list[str] | None = None) -> int:
    """``scripts/bench_start.py``: wrong starts of cpmp's start rules against classifiers.

    The classifiers are handed the true box size; all are scored on many fresh boxes (the
    start depends only on the first feature vector). Prints the JSON (the Markdown table on
    stderr); ``--out`` also writes both.
    """
    parser = argparse.ArgumentParser(
        description=(
            "Wrong starts of cpmp's start rules against classifiers handed the true box "
            "size, scored on many fresh boxes."
        )
    )
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    parser.add_argument("--sizes", type=int, nargs="+", default=[3, 6, 9])
    parser.add_argument("--boxes", type=int, default=200, help="scored boxes per seed")
    parser.add_argument("--out", default=None, help="write the JSON here (and .md beside it)")
    args = parser.parse_args(argv)
    import torch  # lazy: torch after the arguments

    from cpmp.benchmarks.start import analyse_starts, markdown  # lazy: MuJoCo, scikit-learn

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
