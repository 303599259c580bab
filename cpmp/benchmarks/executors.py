"""The executor benchmark (``scripts/bench_executors.py``): which backend runs the jobs best.

Each backend of :mod:`cpmp.experiment.executors` (``inline``, ``local``, ``submitit`` with
``cluster=local``, ``dask`` on a ``LocalCluster``; ``workers`` jobs at once but ``inline``)
runs the same jobs:

- ``small``: two rounds of ``jobs`` small torch jobs (:func:`bench_job`: a seeded 64x64
  matrix product, a few ms) on one entered executor. The first round pays the backend's start
  (workers spawned, cpmp and torch imported there), the second is its steady state: its wall
  time over the jobs is the backend's cost per job (every job at once ``workers``-wide; the
  job itself costs ``inline``'s). Start, rounds and close are timed apart.
- ``main_job`` (unless ``main_job=False``): the main job ``experiment=tiny`` with two seeds
  (each seed's collection and its training size are jobs: 4 jobs), through
  :func:`~cpmp.experiment.jobs.run_experiment` with ``experiment.executor`` set: its wall time
  and whether every number of ``report.json`` and ``episodes.json`` but the wall times and
  paths is ``inline``'s. (The comparison's jobs go through the same executors, tested in
  ``tests/experiment/test_executors.py``.)

For each: whether the results are identical to ``inline``'s. The machine's load average is
written beside (other work slows every backend). Written as JSON (atomically); nothing here
asserts a number.
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

from cpmp.benchmarks.cli import given_options, run_settings_benchmark
from cpmp.errors import ConfigError
from cpmp.records import JsonValue

if TYPE_CHECKING:
    from cpmp.experiment.executors import JobExecutor
    from cpmp.experiment.settings import ExecutorSettings

BACKENDS = ("inline", "local", "submitit", "dask")
"""The backends measured, ``inline`` (the reference) first."""
MAIN_JOB_OVERRIDES = (
    "experiment=tiny",
    "experiment.seeds=[0,1]",
    "experiment.record=none",
    "task.compile_kinematics=false",
)
"""The main job of the ``main_job`` measure: ``experiment=tiny`` with two seeds, no recordings,
the arm Jacobian not compiled (each worker would compile it anew)."""
UNTIMED = ("seconds", "files", "rrd")
"""Report fields that hold wall times or paths (left out of the comparison)."""


@dataclass(frozen=True)
class ExecutorBenchSettings:
    """What the executor benchmark runs.

    Attributes:
        backends: the backends, among :data:`BACKENDS` (``inline`` is always run, first).
        jobs: small jobs per round.
        workers: jobs at once (worker processes of ``local`` and of ``dask``'s cluster).
        main_job: also run the main job ``experiment=tiny`` (two seeds) on every backend.
        folder: where the runs and submitit's jobs go (``None``: a temporary folder).
    """

    backends: tuple[str, ...] = BACKENDS
    jobs: int = 16
    workers: int = 2
    main_job: bool = True
    folder: str | None = None

    def __post_init__(self) -> None:
        unknown = sorted(set(self.backends) - set(BACKENDS))
        if unknown:
            raise ConfigError(
                f"unknown backend(s) {', '.join(unknown)}; choose among {', '.join(BACKENDS)}"
            )
        for name in ("jobs", "workers"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ConfigError(f"{name} must be an integer >= 1, got {value!r}")

    @classmethod
    def quick(cls, **options: object) -> ExecutorBenchSettings:
        """A test's run: 4 small jobs, no main job, ``options`` over them."""
        return replace(cls(jobs=4, main_job=False), **options)


def bench_job(index: int) -> tuple[list[float], int]:
    """A small job: a seeded 64x64 matrix product's first column sums, and torch's threads."""
    import torch

    generator = torch.Generator().manual_seed(index)
    matrix = torch.randn(64, 64, generator=generator, dtype=torch.float64)
    sums = (matrix @ matrix).sum(dim=0)[:4]
    return [float(v) for v in sums], torch.get_num_threads()


def _round(executor: JobExecutor, jobs: int) -> tuple[float, dict[int, list[float]], set[int]]:
    """``jobs`` small jobs through :func:`run_queue`: wall time, results, torch threads."""
    from cpmp.experiment.executors import Submission, run_queue

    queue = [Submission(i, bench_job, (i,), f"job {i}") for i in range(jobs)]
    results: dict[int, list[float]] = {}
    threads: set[int] = set()

    def finished(key: int, result: tuple[list[float], int]) -> None:
        results[key], n = result
        threads.add(n)

    started = time.perf_counter()
    run_queue(executor, lambda: queue.pop(0) if queue else None, finished)
    return time.perf_counter() - started, results, threads


def _executor_settings(name: str, folder: Path) -> ExecutorSettings:
    """The ``executor`` node of backend ``name`` (submitit: local processes in ``folder``)."""
    from cpmp.experiment.settings import ExecutorSettings

    if name == "submitit":
        return ExecutorSettings(folder=str(folder / "submitit"), cluster="local")
    return ExecutorSettings()


def measure_small(name: str, settings: ExecutorBenchSettings, folder: Path) -> dict[str, object]:
    """Two rounds of small jobs on one executor of backend ``name``, timed in parts."""
    from cpmp.experiment.executors import make_executor

    slots = 1 if name == "inline" else settings.workers
    started = time.perf_counter()
    executor = make_executor(name, _executor_settings(name, folder), slots)
    with executor:
        entered = time.perf_counter()
        first_s, _, _ = _round(executor, settings.jobs)
        steady_s, results, threads = _round(executor, settings.jobs)
        leaving = time.perf_counter()
    ended = time.perf_counter()
    return {
        "slots": executor.slots,
        "wall_s": ended - started,
        "start_s": entered - started,
        "first_round_s": first_s,
        "steady_round_s": steady_s,
        "per_job_ms": 1000 * steady_s / settings.jobs,
        "close_s": ended - leaving,
        "torch_threads": sorted(threads),
        "results": results,
    }


def without_timings(obj: JsonValue) -> JsonValue:
    """``obj`` without the fields of :data:`UNTIMED`, at any depth."""
    if isinstance(obj, dict):
        return {k: without_timings(v) for k, v in obj.items() if k not in UNTIMED}
    if isinstance(obj, list):
        return [without_timings(v) for v in obj]
    return obj


def measure_main_job(name: str, settings: ExecutorBenchSettings, folder: Path) -> dict[str, object]:
    """The main job's jobs on backend ``name``: wall time and numbers."""
    from hydra import compose, initialize_config_dir

    from cpmp.config.paths import conf_dir
    from cpmp.experiment.jobs import run_experiment

    overrides = [*MAIN_JOB_OVERRIDES, f"experiment.executor={name}"]
    if name != "inline":
        overrides.append(f"experiment.workers={settings.workers}")
    if name == "submitit":
        overrides.append(f"executor.folder={folder / 'submitit_main'}")
    with initialize_config_dir(config_dir=str(conf_dir()), version_base="1.3"):
        cfg = compose("experiment", overrides=overrides)
    started = time.perf_counter()
    run_dir = run_experiment(cfg, folder / f"main_{name}").parent
    wall = time.perf_counter() - started
    numbers = [
        without_timings(json.loads((run_dir / f).read_text()))
        for f in ("report.json", "episodes.json")
    ]
    return {"wall_s": wall, "numbers": numbers}


def run_executor_benchmark(
    settings: ExecutorBenchSettings, log: Callable[[str], None]
) -> dict[str, JsonValue]:
    """Every backend of ``settings`` on the same jobs; the results compared with ``inline``'s.

    Returns:
        The settings, the machine (cores, load average before and after) and per backend
        ``small`` (timings, torch threads, ``identical``) and ``main_job`` (wall time,
        ``identical``).
    """
    backends = ["inline", *(b for b in settings.backends if b != "inline")]
    load_before = os.getloadavg()
    out: dict[str, object] = {
        "settings": asdict(settings),
        "cores": len(os.sched_getaffinity(0)),
        "load_before": list(load_before),
        "backends": {},
    }
    with tempfile.TemporaryDirectory(prefix="cpmp_bench_executors_", dir=settings.folder) as tmp:
        folder = Path(tmp)
        reference: dict[str, object] = {}
        for name in backends:
            small = measure_small(name, settings, folder)
            results = small.pop("results")
            reference.setdefault("small", results)
            small["identical"] = results == reference["small"]
            log(
                f"{name}: small jobs {small['wall_s']:.1f} s (start {small['start_s']:.1f}, "
                f"first round {small['first_round_s']:.1f}, {small['per_job_ms']:.0f} ms/job "
                f"after), identical {small['identical']}"
            )
            entry: dict[str, object] = {"small": small}
            if settings.main_job:
                main_job = measure_main_job(name, settings, folder)
                numbers = main_job.pop("numbers")
                reference.setdefault("main_job", numbers)
                main_job["identical"] = numbers == reference["main_job"]
                wall, same = main_job["wall_s"], main_job["identical"]
                log(f"{name}: main job {wall:.1f} s, identical {same}")
                entry["main_job"] = main_job
            out["backends"][name] = entry
    out["load_after"] = list(os.getloadavg())
    return out


def markdown(result: dict[str, JsonValue]) -> str:
    """The benchmark's table: one row per backend."""
    lines = [
        "| backend | slots | small: wall s | start s | 1st round s | ms/job after | close s "
        "| identical | main job: wall s | identical |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    backends = result["backends"]
    assert isinstance(backends, dict)
    for name, entry in backends.items():
        assert isinstance(entry, dict)
        small = entry["small"]
        main_job = entry.get("main_job") or {}
        assert isinstance(small, dict) and isinstance(main_job, dict)
        wall = f"{main_job['wall_s']:.1f}" if main_job else "-"
        lines.append(
            f"| {name} | {small['slots']} | {small['wall_s']:.1f} | {small['start_s']:.1f} "
            f"| {small['first_round_s']:.1f} | {small['per_job_ms']:.0f} | {small['close_s']:.1f} "
            f"| {small['identical']} | {wall} | {main_job.get('identical', '-')} |"
        )
    lines.append(f"load average before {result['load_before']}, after {result['load_after']}")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    """``scripts/bench_executors.py``: run the executor benchmark, write its JSON and table.

    Args:
        argv: the command line (default ``sys.argv[1:]``).

    Returns:
        The exit status: 0, or 2 after a :class:`~cpmp.errors.CpmpError` (a bad option).
    """
    parser = argparse.ArgumentParser(
        description=(
            "The same jobs (small torch jobs, the main job experiment=tiny) on every "
            "executor backend: wall time, start, cost per job, identical numbers. Writes JSON, "
            "prints a Markdown table."
        )
    )
    parser.add_argument("--out", default="logs/bench_executors.json", help="the JSON file")
    parser.add_argument("--quick", action="store_true", help="4 small jobs, no main job")
    parser.add_argument("--backends", nargs="+", help=f"default: {' '.join(BACKENDS)}")
    parser.add_argument("--jobs", type=int, help="small jobs per round (16)")
    parser.add_argument("--workers", type=int, help="jobs at once (2)")
    parser.add_argument("--no-main-job", action="store_true", help="skip the main job")
    parser.add_argument("--folder", help="where the runs go (default: a temporary folder)")
    args = parser.parse_args(argv)
    options = given_options(args, ("backends", "jobs", "workers", "folder"))
    if args.no_main_job:
        options["main_job"] = False
    return run_settings_benchmark(
        "bench_executors",
        args,
        ExecutorBenchSettings,
        options,
        run_executor_benchmark,
        markdown,
    )
