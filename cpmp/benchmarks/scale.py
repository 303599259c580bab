"""The scale benchmark (``scripts/bench_scale.py``): the default fit, a handful to 768 demos.

Issue #34: from a handful to a thousand demonstrations.

Per world and training size D (default two_point and relay at 12 / 48 / 192 / 768
demonstrations of seed ``s``), one fresh Python process draws the demonstrations, fits
:meth:`~cpmp.sequencer.ConcurrentSequencer.fit` with its defaults, and reports the fit's wall
time (``fit_s``; ``predictor_s``: the predictor's part), its peak resident memory
(``peak_rss_gb``: the process's ``ru_maxrss`` after the fit, imports and demonstrations
included; ``base_rss_gb`` the same before the fit), the training samples, the support points
(``supports``, start heads included), the held-out progress MAE on ``held_out``
demonstrations of seed ``HELD_OUT_SEED + s`` and the closed-loop completions C of ``episodes``
episodes of that seed. A process per size keeps one fit's memory out of the next one's peak.

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
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from cpmp.benchmarks.cli import given_options, run_settings_benchmark
from cpmp.errors import ConfigError

WORLDS = ("two_point", "relay")
"""The worlds measured by default."""
SIZES = (12, 48, 192, 768)
"""The training sizes D measured by default."""
HELD_OUT_SEED = 1000
"""Held-out demonstrations and episodes of seed ``s`` are drawn with ``HELD_OUT_SEED + s``."""
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
import torch
from cpmp.evaluation.offline import activation_progress, progress_errors
from cpmp.sequencer import ConcurrentSequencer
from cpmp.worlds.protocol import evaluate
from cpmp.worlds.registry import make_world

def rss_gb():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024 / 1e9

world = make_world(args["world"])
train = world.demonstrations(args["demos"], args["seed"])
test = world.demonstrations(args["held_out"], args["held_out_seed"])
base = rss_gb()
start = time.perf_counter()
seq = ConcurrentSequencer.fit(train, seed=args["seed"], logger=None)
fit_s = time.perf_counter() - start
peak = rss_gb()
mae = float(progress_errors(activation_progress(seq, test))["mae"])
run = evaluate(world, seq, args["episodes"], args["held_out_seed"])
print("RESULT " + json.dumps({
    "samples": int(sum(d.n_samples for d in train)),
    "fit_s": fit_s,
    "predictor_s": float(seq.fit_summary.seconds),
    "peak_rss_gb": peak,
    "base_rss_gb": base,
    "supports": int(seq.fit_summary.n_support_total),
    "mae": mae,
    "complete": int(run.complete),
    "episodes": args["episodes"],
    "threads": torch.get_num_threads(),
}))
"""
"""The measuring process's program (public API only, so that another checkout runs it)."""


@dataclass
class ScaleSettings:
    """What the scale benchmark runs.

    Attributes:
        worlds: registered synthetic worlds (:mod:`cpmp.worlds.registry`).
        sizes: training sizes D, increasing.
        seed: the training demonstrations' and the fit's seed.
        held_out: held-out demonstrations for the progress MAE.
        episodes: closed-loop episodes for C.
        timeout: seconds a size's process may run.
        pythonpath: another checkout's root to measure (``None``: this cpmp).
    """

    worlds: tuple[str, ...] = WORLDS
    sizes: tuple[int, ...] = SIZES
    seed: int = 0
    held_out: int = 20
    episodes: int = 20
    timeout: float = 1800.0
    pythonpath: str | None = None

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
        if not self.timeout > 0:
            raise ConfigError(f"timeout must be > 0 seconds, got {self.timeout!r}")
        if self.pythonpath is not None and not (Path(self.pythonpath) / "cpmp").is_dir():
            raise ConfigError(f"--pythonpath {self.pythonpath!r} holds no cpmp package")

    @classmethod
    def quick(cls, **options: Any) -> ScaleSettings:
        """A small run for the tests: two_point at 4 and 8 demos, 2 held out, 2 episodes."""
        values: dict[str, Any] = {
            "worlds": ("two_point",),
            "sizes": (4, 8),
            "held_out": 2,
            "episodes": 2,
            "timeout": 600.0,
        }
        values.update(options)
        return cls(**values)


def measure_size(world: str, demos: int, settings: ScaleSettings) -> dict[str, Any]:
    """One size of one world, measured in a fresh process (see the module docstring).

    Args:
        world: the world's name.
        demos: training demonstrations D.
        settings: the benchmark's settings.

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
    }
    env = dict(os.environ)
    if settings.pythonpath is not None:
        env["PYTHONPATH"] = str(Path(settings.pythonpath).resolve())
    row: dict[str, Any] = {"world": world, "D": demos}
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
        tail = (done.stderr or done.stdout).strip().splitlines()[-3:]
        return {**row, "error": f"exit status {done.returncode}: {' / '.join(tail)}"}
    return {**row, **json.loads(lines[-1].removeprefix("RESULT "))}


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


def summarise(rows: Sequence[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """Per world the growth exponents and, where their sizes were run, the targets.

    Args:
        rows: the measured rows (rows with an ``error`` are left out).

    Returns:
        world -> ``exponents`` (``fit``, ``rss``, ``fit_last``, ``rss_last``) and ``targets``
        (each target's measured value and whether it is met).
    """
    out: dict[str, dict[str, Any]] = {}
    for world in dict.fromkeys(r["world"] for r in rows):
        ok = [r for r in rows if r["world"] == world and "error" not in r]
        samples = [r["samples"] for r in ok]
        last = ok[-2:]
        exponents = {
            "fit": growth_exponent(samples, [r["fit_s"] for r in ok]),
            "rss": growth_exponent(samples, [r["peak_rss_gb"] for r in ok]),
            "fit_last": growth_exponent([r["samples"] for r in last], [r["fit_s"] for r in last]),
            "rss_last": growth_exponent(
                [r["samples"] for r in last], [r["peak_rss_gb"] for r in last]
            ),
        }
        out[world] = {"exponents": exponents, "targets": _targets(ok)}
    return out


def _targets(rows: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Issue #34's targets on one world's rows (those whose sizes were run)."""
    by_d = {r["D"]: r for r in rows}
    out: dict[str, Any] = {}
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
) -> dict[str, Any]:
    """Every world and size, then the exponents and targets (see the module docstring).

    Args:
        settings: what to run.
        log: receives one progress line per size.

    Returns:
        ``settings``, ``machine`` (CPUs, load averages before and after), ``rows`` and
        ``summary`` (per world, :func:`summarise`).
    """
    load_before = os.getloadavg()
    rows = []
    for world in settings.worlds:
        for demos in settings.sizes:
            row = measure_size(world, demos, settings)
            rows.append(row)
            log(_line(row))
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
    }


def _line(row: dict[str, Any]) -> str:
    """One row as a progress line."""
    if "error" in row:
        return f"{row['world']} D={row['D']}: {row['error']}"
    return (
        f"{row['world']} D={row['D']}: {row['samples']} samples, fit {row['fit_s']:.1f} s, "
        f"peak RSS {row['peak_rss_gb']:.2f} GB, {row['supports']} supports, MAE "
        f"{row['mae']:.4f}, C {row['complete']}/{row['episodes']}"
    )


def markdown(result: dict[str, Any]) -> str:
    """The rows as a Markdown table and the exponents per world, then the JSON's path line."""
    lines = [
        "| world | D | samples | fit [s] | peak RSS [GB] | supports | held-out MAE | C |",
        "| --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for r in result["rows"]:
        if "error" in r:
            lines.append(f"| {r['world']} | {r['D']} | - | {r['error']} | | | | |")
            continue
        lines.append(
            f"| {r['world']} | {r['D']} | {r['samples']:,} | {r['fit_s']:.1f} | "
            f"{r['peak_rss_gb']:.2f} | {r['supports']:,} | {r['mae']:.4f} | "
            f"{r['complete']}/{r['episodes']} |"
        )
    for world, s in result["summary"].items():
        e = s["exponents"]
        parts = [f"{k} {v:.2f}" for k, v in e.items() if v is not None]
        lines.append("")
        lines.append(f"{world}: growth exponents against samples: {', '.join(parts)}")
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
    parser.add_argument("--held-out", type=int, help="held-out demonstrations for the MAE (20)")
    parser.add_argument("--episodes", type=int, help="closed-loop episodes (20)")
    parser.add_argument("--timeout", type=float, help="seconds per size (1800)")
    parser.add_argument(
        "--pythonpath", help="measure the cpmp of another checkout (its root directory)"
    )
    args = parser.parse_args(argv)
    names = ("worlds", "sizes", "seed", "held_out", "episodes", "timeout", "pythonpath")
    return run_settings_benchmark(
        "bench_scale",
        args,
        ScaleSettings,
        given_options(args, names),
        run_scale_benchmark,
        markdown,
    )
