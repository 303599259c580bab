"""The scale benchmark (``scripts/bench_scale.py``): the default fit, a handful to 768 demos.

Issue #34: from a handful to a thousand demonstrations.

Per world and training size D (default two_point and relay at 12 / 48 / 192 / 768
demonstrations of seed ``s``), one fresh Python process draws the demonstrations, fits
:meth:`~cpmp.sequencer.ConcurrentSequencer.fit` with its defaults, and reports the fit's wall
time (``fit_s``, Lightning already imported: the fit imports it lazily, once per process;
``predictor_s``: the predictor's part), its peak resident memory
(``peak_rss_gb``: the process's ``ru_maxrss`` after the fit, imports and demonstrations
included; ``base_rss_gb`` the same before the fit), the training samples, the support points
(``supports``), the held-out progress MAE on ``held_out``
demonstrations of seed ``HELD_OUT_SEED + s`` and the closed-loop completions C of ``episodes``
episodes of that seed. A process per size keeps one fit's memory out of the next one's peak.

The ``lerobot`` leg (``--lerobot N``, default 400, 0 skips it) goes through a user's import:
:data:`LEROBOT_WORLD`'s ``N`` demonstrations of seed ``s`` are written as a LeRobot v3 dataset
(:func:`cpmp.benchmarks.lerobot_data.write_demonstrations`, ``write_s``, ``frames`` and
``files`` data files) with its mapping, ``cpmp-import`` (its console-script function,
:data:`IMPORT_ENTRY_POINT`) imports it in a process of its own (``import_s``: that process's
wall time, interpreter start and Hydra included; ``import_rss_gb``: its peak RSS), and the
imported file is fitted and measured in a further process exactly as a size above (same
held-out demonstrations and episodes). The mapping keeps the world's feature, variable and MP
names, so the world runs the fitted sequencer closed loop and C is measured; the features pass
through LeRobot's float32 ``observation.state``. The row is the JSON's ``lerobot`` (absent
when skipped) and is not part of the exponents. With ``--pythonpath`` the dataset is still
written by this cpmp; the import and the fit are the other checkout's.

Then per world the growth exponents: the least-squares slope of ``log fit_s`` and of
``log peak_rss_gb`` against ``log samples`` over all sizes, and between the last two sizes
(``fit_last``, ``rss_last``); and issue #34's targets where their sizes were run (see
:data:`TARGETS`). ``--pythonpath`` measures another checkout's cpmp the same way (e.g. the
commit before a change): the measuring process uses only the public API, so any cpmp with
``ConcurrentSequencer.fit`` and the worlds runs it. A size whose process fails or runs past
``timeout`` seconds is recorded with its ``error`` and left out of the exponents.

Written as JSON (atomically); nothing here asserts a number.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

from cpmp.benchmarks.cli import given_options, run_settings_benchmark
from cpmp.config import DTYPES
from cpmp.errors import ConfigError
from cpmp.records import JsonValue

WORLDS = ("two_point", "relay")
"""The worlds measured by default."""
SIZES = (12, 48, 192, 768)
"""The training sizes D measured by default."""
HELD_OUT_SEED = 1000
"""Held-out demonstrations and episodes of seed ``s`` are drawn with ``HELD_OUT_SEED + s``."""
LEROBOT_WORLD = "two_point"
"""The world whose demonstrations the ``lerobot`` leg writes and imports (issue #34)."""
LEROBOT_EPISODES = 400
"""The ``lerobot`` leg's default number of episodes (issue #34)."""
LEROBOT_EPISODES_PER_FILE = 50
"""Episodes per data file of the written dataset (LeRobot packs many episodes into a file)."""
IMPORT_ENTRY_POINT = "cpmp.cli.main:import_main"
"""``cpmp-import``'s console-script target (``pyproject.toml``'s ``[project.scripts]``)."""
TARGETS = {
    "fit_s": 60.0,
    "peak_rss_gb": 2.0,
    "supports_ratio": 2.0,
    "fit_exponent": 1.0,
}
"""Issue #34's targets at the largest size (768): fit time [s], peak RSS [GB], supports over
those at 48, the growth exponent of the fit time from 192 to 768; and (not numbers) held-out
MAE and C at 768 no worse than at 192."""

_MEASURE = r"""
import json, resource, sys, time
args = json.loads(sys.argv[1])
import lightning  # the fit imports it lazily: a once-per-process cost kept out of fit_s
import torch
from cpmp.evaluation.offline import activation_progress, progress_errors
from cpmp.sequencer import ConcurrentSequencer
from cpmp.worlds.protocol import evaluate
from cpmp.worlds.registry import make_world

def rss_gb():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024 / 1e9

world = make_world(args["world"])
if args.get("demos_file"):
    from cpmp.data import load_demonstrations
    train = load_demonstrations(args["demos_file"])
else:
    train = world.demonstrations(args["demos"], args["seed"])
test = world.demonstrations(args["held_out"], args["held_out_seed"])
base = rss_gb()
start = time.perf_counter()
dtype = args.get("dtype", "auto")
options = {} if dtype == "auto" else {"dtype": dtype}
if args.get("accelerator", "auto") != "auto":
    options["accelerator"] = args["accelerator"]
seq = ConcurrentSequencer.fit(train, seed=args["seed"], logger=None, **options)
fit_s = time.perf_counter() - start
peak = rss_gb()
mae = float(progress_errors(activation_progress(seq, test))["mae"])
summary = seq.fit_summary  # a FitReport; a dict in a checkout before it (--pythonpath)
fact = summary.get if isinstance(summary, dict) else lambda key: getattr(summary, key)
run = evaluate(world, seq, args["episodes"], args["held_out_seed"])
print("RESULT " + json.dumps({
    "demos": len(train),
    "samples": int(sum(d.n_samples for d in train)),
    "fit_s": fit_s,
    "predictor_s": float(fact("seconds")),
    "peak_rss_gb": peak,
    "base_rss_gb": base,
    "supports": int(fact("n_support_total")),
    "mae": mae,
    "complete": int(run.complete),
    "episodes": args["episodes"],
    "threads": torch.get_num_threads(),
    "dtype": str(getattr(seq.predictor, "dtype_", "")).removeprefix("torch."),
    "device": str(fact("device")),
}))
"""
"""The measuring process's program (public API only, so that another checkout runs it)."""

_IMPORT = r"""
import json, resource, sys
module, function = sys.argv[1].split(":")
sys.argv = ["cpmp-import", *sys.argv[2:]]
status = 0
try:
    getattr(__import__(module, fromlist=[function]), function)()
except SystemExit as stop:
    status = stop.code if isinstance(stop.code, int) else int(stop.code is not None)
rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024 / 1e9
print("RESULT " + json.dumps({"status": status, "rss_gb": rss}), flush=True)
sys.exit(status)
"""
"""The import process's program: ``cpmp-import`` as its console script runs it (the entry
point's function on ``sys.argv``), then the process's exit status and peak RSS [GB]."""


@dataclass
class ScaleSettings:
    """What the scale benchmark runs.

    Attributes:
        worlds: registered synthetic worlds (:mod:`cpmp.worlds.registry`).
        sizes: training sizes D, increasing.
        seed: the training demonstrations' and the fit's seed.
        held_out: held-out demonstrations for the progress MAE.
        episodes: closed-loop episodes for C.
        timeout: seconds a size's process may run (and the ``lerobot`` leg's import).
        pythonpath: another checkout's root to measure (``None``: this cpmp).
        lerobot: episodes of the ``lerobot`` leg (0: no such leg).
        dtype: the progress predictors' floating-point type (the predictor option ``dtype``):
            ``auto`` (cpmp's default: ``float32`` from
            :data:`~cpmp.config.FLOAT32_FROM_SAMPLES` training samples), ``float64`` or
            ``float32``; each row reports the type its fit used.
        accelerator: the fit's Lightning accelerator (the trainer option ``accelerator``):
            ``auto`` (cpmp's default: a GPU where there is one), ``cpu``, ``gpu``, ...; each
            row reports the device its fit ran on (``device``).
    """

    worlds: tuple[str, ...] = WORLDS
    sizes: tuple[int, ...] = SIZES
    seed: int = 0
    held_out: int = 100
    episodes: int = 20
    timeout: float = 1800.0
    pythonpath: str | None = None
    lerobot: int = LEROBOT_EPISODES
    dtype: str = "auto"
    accelerator: str = "auto"

    def __post_init__(self) -> None:
        from cpmp.worlds.registry import world_names

        names = world_names()
        for world in self.worlds:
            if world not in names:
                raise ConfigError(f"unknown world {world!r}; choose from {', '.join(names)}")
        if not self.worlds or not self.sizes:
            raise ConfigError("the scale benchmark needs at least one world and one size")
        for name in ("held_out", "episodes"):
            if int(getattr(self, name)) < 1:
                raise ConfigError(f"{name} must be >= 1, got {getattr(self, name)!r}")
        if any(int(d) < 1 for d in self.sizes) or list(self.sizes) != sorted(set(self.sizes)):
            raise ConfigError(f"sizes must be increasing counts >= 1, got {list(self.sizes)}")
        if int(self.lerobot) < 0:
            raise ConfigError(f"lerobot must be >= 0 episodes (0: skip), got {self.lerobot!r}")
        if self.dtype not in DTYPES:
            raise ConfigError(f"dtype must be one of {', '.join(DTYPES)}, got {self.dtype!r}")
        if not isinstance(self.accelerator, str) or not self.accelerator:
            raise ConfigError(
                f"accelerator must be a name such as 'auto', 'cpu' or 'gpu', got "
                f"{self.accelerator!r}"
            )
        if not self.timeout > 0:
            raise ConfigError(f"timeout must be > 0 seconds, got {self.timeout!r}")
        if self.pythonpath is not None and not (Path(self.pythonpath) / "cpmp").is_dir():
            raise ConfigError(f"--pythonpath {self.pythonpath!r} holds no cpmp package")

    @classmethod
    def quick(cls, **options: object) -> ScaleSettings:
        """A small run for the tests: two_point at 4 and 8 demos, 2 held out, 2 episodes.

        The ``lerobot`` leg runs at 3 episodes.

        Args:
            **options: fields of :class:`ScaleSettings` over those (passed through).
        """
        values: dict[str, object] = {
            "worlds": ("two_point",),
            "sizes": (4, 8),
            "held_out": 2,
            "episodes": 2,
            "timeout": 600.0,
            "lerobot": 3,
        }
        values.update(options)
        return cls(**values)


def _environment(settings: ScaleSettings) -> dict[str, str]:
    """The measuring processes' environment (``PYTHONPATH`` set for ``--pythonpath``)."""
    env = dict(os.environ)
    if settings.pythonpath is not None:
        env["PYTHONPATH"] = str(Path(settings.pythonpath).resolve())
    return env


def _failure(done: subprocess.CompletedProcess[str]) -> str:
    """A failed process's exit status and last lines of output."""
    tail = (done.stderr or done.stdout).strip().splitlines()[-3:]
    return f"exit status {done.returncode}: {' / '.join(tail)}"


def measure_size(
    world: str, demos: int, settings: ScaleSettings, demos_file: str | None = None
) -> dict[str, JsonValue]:
    """One size of one world, measured in a fresh process (see the module docstring).

    Args:
        world: the world's name.
        demos: training demonstrations D.
        settings: the benchmark's settings.
        demos_file: fit the demonstrations of this cpmp file (all of them) instead of drawing
            ``demos`` of ``world``; the held-out demonstrations and episodes are the world's.

    Returns:
        The row: ``world``, ``D`` and the measures, or ``error`` when the process failed.
    """
    args = {
        "world": world,
        "demos": demos,
        "seed": settings.seed,
        "held_out": settings.held_out,
        "held_out_seed": HELD_OUT_SEED + settings.seed,
        "episodes": settings.episodes,
        "demos_file": demos_file,
        "dtype": settings.dtype,
        "accelerator": settings.accelerator,
    }
    env = _environment(settings)
    row: dict[str, JsonValue] = {"world": world, "D": demos}
    try:
        done = subprocess.run(
            [sys.executable, "-c", _MEASURE, json.dumps(args)],
            capture_output=True,
            text=True,
            timeout=settings.timeout,
            env=env,
            cwd=settings.pythonpath or None,
            check=False,
        )
    except subprocess.TimeoutExpired:
        return {**row, "error": f"ran past the timeout of {settings.timeout:g} s"}
    lines = [ln for ln in done.stdout.splitlines() if ln.startswith("RESULT ")]
    if done.returncode != 0 or not lines:
        return {**row, "error": _failure(done)}
    return {**row, **json.loads(lines[-1].removeprefix("RESULT "))}


def run_import(
    mapping: Path, dataset: Path, output: Path, run_dir: Path, settings: ScaleSettings
) -> dict[str, JsonValue]:
    """``cpmp-import mapping=... input=... output=...`` in a process of its own.

    The process calls :data:`IMPORT_ENTRY_POINT` on the command line, as the installed
    ``cpmp-import`` script does (Hydra's run directory is ``run_dir``).

    Args:
        mapping: the mapping's YAML file.
        dataset: the LeRobot dataset's folder.
        output: the cpmp demonstration file to write.
        run_dir: the import's run directory (its ``summary.txt``, Hydra's files).
        settings: the benchmark's settings (``timeout``, ``pythonpath``).

    Returns:
        ``import_s`` (the process's wall time [s]) and ``import_rss_gb`` (its peak RSS [GB]),
        or ``error`` when it failed, ran past the timeout or wrote no file.
    """
    command = [
        sys.executable,
        "-c",
        _IMPORT,
        IMPORT_ENTRY_POINT,
        f"mapping={mapping}",
        f"input={dataset}",
        f"output={output}",
        f"hydra.run.dir={run_dir}",
    ]
    start = time.perf_counter()
    try:
        done = subprocess.run(
            command,
            capture_output=True,
            text=True,
            timeout=settings.timeout,
            env=_environment(settings),
            cwd=settings.pythonpath or None,
            check=False,
        )
    except subprocess.TimeoutExpired:
        return {"error": f"cpmp-import ran past the timeout of {settings.timeout:g} s"}
    seconds = time.perf_counter() - start
    lines = [ln for ln in done.stdout.splitlines() if ln.startswith("RESULT ")]
    if done.returncode != 0 or not lines or not output.is_file():
        return {"error": f"cpmp-import: {_failure(done)}"}
    measured = json.loads(lines[-1].removeprefix("RESULT "))
    return {"import_s": seconds, "import_rss_gb": measured["rss_gb"]}


def measure_lerobot(settings: ScaleSettings) -> dict[str, JsonValue]:
    """The ``lerobot`` leg (see the module docstring): write, ``cpmp-import``, fit, measure.

    Everything is written to a temporary folder, removed afterwards.

    Args:
        settings: the benchmark's settings (``lerobot`` episodes, at least 1).

    Returns:
        The row: ``world``, ``D``, ``source`` (``lerobot``), ``write_s`` [s], ``frames``,
        ``files``, ``import_s`` [s], ``import_rss_gb`` [GB] and the measures of
        :func:`measure_size`, or ``error`` when a step failed.
    """
    row: dict[str, JsonValue] = {"world": LEROBOT_WORLD, "D": settings.lerobot, "source": "lerobot"}
    try:
        from cpmp.benchmarks.lerobot_data import (  # lazy: pyarrow, the import extra
            import_mapping,
            write_demonstrations,
            write_import_mapping,
        )
    except ImportError as err:
        return {**row, "error": f"cannot write LeRobot data ({err}); pip install cpmp[import]"}
    from cpmp.worlds.registry import make_world  # lazy: torch, only for this leg

    demos = make_world(LEROBOT_WORLD).demonstrations(settings.lerobot, settings.seed)
    with tempfile.TemporaryDirectory(prefix="cpmp-scale-lerobot-") as tmp:
        folder = Path(tmp)
        start = time.perf_counter()
        dataset = write_demonstrations(
            folder / "dataset", demos, episodes_per_file=LEROBOT_EPISODES_PER_FILE
        )
        row["write_s"] = time.perf_counter() - start
        row["frames"] = int(sum(d.n_samples for d in demos))
        row["files"] = len(list(dataset.glob("data/*/*.parquet")))
        mapping = write_import_mapping(folder / "mapping.yaml", import_mapping(demos))
        del demos
        output = folder / "demos.hdf5"
        imported = run_import(mapping, dataset, output, folder / "import_run", settings)
        row.update(imported)
        if "error" in imported:
            return row
        measured = measure_size(LEROBOT_WORLD, settings.lerobot, settings, str(output))
    return {**row, **{k: v for k, v in measured.items() if k not in row or k == "error"}}


def growth_exponent(samples: Sequence[float], values: Sequence[float]) -> float | None:
    """Least-squares slope of ``log values`` against ``log samples`` (``None``: < 2 points).

    Args:
        samples: ``(n,)`` sample counts, positive.
        values: ``(n,)`` the measure at each (times [s], memory [GB]), positive.

    Returns:
        The exponent ``k`` of ``value ∝ samples^k``.
    """
    if len(samples) < 2:
        return None
    x = [math.log(s) for s in samples]
    y = [math.log(v) for v in values]
    mx, my = sum(x) / len(x), sum(y) / len(y)
    sxx = sum((a - mx) ** 2 for a in x)
    if sxx == 0.0:
        return None
    return sum((a - mx) * (b - my) for a, b in zip(x, y, strict=True)) / sxx


def summarise(
    rows: Sequence[Mapping[str, JsonValue]],
) -> dict[str, dict[str, dict[str, JsonValue]]]:
    """Per world the growth exponents and, where their sizes were run, the targets.

    Args:
        rows: the measured rows (rows with an ``error`` are left out).

    Returns:
        world -> ``exponents`` (``fit``, ``rss``, ``fit_last``, ``rss_last``) and ``targets``
        (each target's measured value and whether it is met).
    """
    out: dict[str, dict[str, dict[str, JsonValue]]] = {}
    for world in dict.fromkeys(r["world"] for r in rows):
        ok = [r for r in rows if r["world"] == world and "error" not in r]
        samples = [r["samples"] for r in ok]
        last = ok[-2:]
        exponents: dict[str, JsonValue] = {
            "fit": growth_exponent(samples, [r["fit_s"] for r in ok]),
            "rss": growth_exponent(samples, [r["peak_rss_gb"] for r in ok]),
            "fit_last": growth_exponent([r["samples"] for r in last], [r["fit_s"] for r in last]),
            "rss_last": growth_exponent(
                [r["samples"] for r in last], [r["peak_rss_gb"] for r in last]
            ),
        }
        out[world] = {"exponents": exponents, "targets": _targets(ok)}
    return out


def _targets(rows: Sequence[Mapping[str, JsonValue]]) -> dict[str, JsonValue]:
    """Issue #34's targets on one world's rows (those whose sizes were run).

    Returns:
        target -> ``value`` (measured) and ``met``, for the targets whose sizes were run.
    """
    by_d = {r["D"]: r for r in rows}
    out: dict[str, JsonValue] = {}
    big = by_d.get(768)
    if big is None:
        return out
    out["fit_s"] = {"value": big["fit_s"], "met": big["fit_s"] <= TARGETS["fit_s"]}
    rss = big["peak_rss_gb"]
    out["peak_rss_gb"] = {"value": rss, "met": rss <= TARGETS["peak_rss_gb"]}
    if 48 in by_d:
        ratio = big["supports"] / by_d[48]["supports"]
        out["supports_ratio"] = {"value": ratio, "met": ratio <= TARGETS["supports_ratio"]}
    if 192 in by_d:
        mid = by_d[192]
        k = growth_exponent([mid["samples"], big["samples"]], [mid["fit_s"], big["fit_s"]])
        out["fit_exponent"] = {"value": k, "met": k is not None and k <= TARGETS["fit_exponent"]}
        out["mae"] = {"value": [mid["mae"], big["mae"]], "met": big["mae"] <= mid["mae"]}
        out["complete"] = {
            "value": [mid["complete"], big["complete"]],
            "met": big["complete"] >= mid["complete"],
        }
    return out


def run_scale_benchmark(
    settings: ScaleSettings, log: Callable[[str], None] = lambda line: None
) -> dict[str, JsonValue]:
    """Every world and size, then the exponents and targets (see the module docstring).

    Args:
        settings: what to run.
        log: receives one progress line per size.

    Returns:
        ``settings``, ``machine`` (CPUs, load averages before and after), ``rows``,
        ``summary`` (per world, :func:`summarise`) and, unless ``settings.lerobot`` is 0,
        ``lerobot`` (:func:`measure_lerobot`'s row).
    """
    load_before = os.getloadavg()
    rows = []
    for world in settings.worlds:
        for demos in settings.sizes:
            row = measure_size(world, demos, settings)
            rows.append(row)
            log(_line(row))
    lerobot = None
    if settings.lerobot > 0:
        lerobot = measure_lerobot(settings)
        log(_line(lerobot))
    return {
        "settings": asdict(settings),
        "targets": TARGETS,
        "machine": {
            "cpus": os.cpu_count(),
            "load_before": list(load_before),
            "load_after": list(os.getloadavg()),
        },
        "rows": rows,
        "summary": summarise(rows),
        **({"lerobot": lerobot} if lerobot is not None else {}),
    }


def _label(row: Mapping[str, JsonValue]) -> str:
    """A row's world, and how its demonstrations came (``via LeRobot v3``)."""
    return row["world"] + (" via LeRobot v3" if row.get("source") == "lerobot" else "")


def _line(row: Mapping[str, JsonValue]) -> str:
    """One row as a progress line."""
    if "error" in row:
        return f"{_label(row)} D={row['D']}: {row['error']}"
    return (
        f"{_label(row)} D={row['D']}: {row['samples']} samples, fit {row['fit_s']:.1f} s "
        f"on {row.get('device', 'cpu')}, "
        f"peak RSS {row['peak_rss_gb']:.2f} GB, {row['supports']} supports, MAE "
        f"{row['mae']:.4f}, C {row['complete']}/{row['episodes']}"
    )


def markdown(result: Mapping[str, JsonValue]) -> str:
    """The rows as a Markdown table, the exponents per world, the ``lerobot`` leg's import.

    The ``lerobot`` row (when the result has one) is the table's last.
    """
    lines = [
        "| world | D | samples | fit [s] | peak RSS [GB] | supports | held-out MAE | C |",
        "| --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    lerobot = result.get("lerobot")
    for r in [*result["rows"], *([lerobot] if lerobot else [])]:
        if "error" in r:
            lines.append(f"| {_label(r)} | {r['D']} | - | {r['error']} | | | | |")
            continue
        lines.append(
            f"| {_label(r)} | {r['D']} | {r['samples']:,} | {r['fit_s']:.1f} | "
            f"{r['peak_rss_gb']:.2f} | {r['supports']:,} | {r['mae']:.4f} | "
            f"{r['complete']}/{r['episodes']} |"
        )
    for world, s in result["summary"].items():
        e = s["exponents"]
        parts = [f"{k} {v:.2f}" for k, v in e.items() if v is not None]
        lines.append("")
        lines.append(f"{world}: growth exponents against samples: {', '.join(parts)}")
    if lerobot and "import_s" in lerobot:
        lines.append("")
        lines.append(
            f"{_label(lerobot)}: {lerobot['D']} episodes ({lerobot['frames']:,} frames, "
            f"{lerobot['files']} data files) written in {lerobot['write_s']:.1f} s; cpmp-import "
            f"{lerobot['import_s']:.1f} s, peak RSS {lerobot['import_rss_gb']:.2f} GB"
        )
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    """``scripts/bench_scale.py``: run the scale benchmark, write its JSON, print the table.

    Args:
        argv: the command line (default ``sys.argv[1:]``).

    Returns:
        The exit status: 0, or 2 after a :class:`~cpmp.errors.CpmpError` (a bad option).
    """
    parser = argparse.ArgumentParser(
        description=(
            "The default fit at growing numbers of demonstrations: fit time, peak RSS, "
            "supports, held-out progress MAE and closed-loop completions per world and D, "
            "each size in its own process, and the growth exponents against the samples. "
            "Writes JSON, prints a Markdown table."
        )
    )
    parser.add_argument("--out", default="logs/bench_scale.json", help="the JSON file")
    parser.add_argument("--quick", action="store_true", help="ScaleSettings.quick (a test)")
    parser.add_argument("--worlds", nargs="+", help=f"default: {' '.join(WORLDS)}")
    parser.add_argument("--sizes", type=int, nargs="+", help="training sizes D (12 48 192 768)")
    parser.add_argument("--seed", type=int, help="seed of the demonstrations and fit (0)")
    parser.add_argument("--held-out", type=int, help="held-out demonstrations for the MAE (100)")
    parser.add_argument("--episodes", type=int, help="closed-loop episodes (20)")
    parser.add_argument("--timeout", type=float, help="seconds per size (1800)")
    parser.add_argument(
        "--pythonpath", help="measure the cpmp of another checkout (its root directory)"
    )
    parser.add_argument(
        "--lerobot",
        type=int,
        help=f"episodes of {LEROBOT_WORLD} written as LeRobot v3 and read by cpmp-import "
        f"({LEROBOT_EPISODES}; 0: skip)",
    )
    parser.add_argument(
        "--dtype", choices=DTYPES, help="the predictors' float type (auto: cpmp's default)"
    )
    parser.add_argument(
        "--accelerator", help="the fit's Lightning accelerator (auto: a GPU where there is one)"
    )
    args = parser.parse_args(argv)
    names = (
        "worlds",
        "sizes",
        "seed",
        "held_out",
        "episodes",
        "timeout",
        "pythonpath",
        "lerobot",
        "dtype",
        "accelerator",
    )
    return run_settings_benchmark(
        "bench_scale",
        args,
        ScaleSettings,
        given_options(args, names),
        run_scale_benchmark,
        markdown,
    )
