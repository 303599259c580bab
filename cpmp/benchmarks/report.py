"""What ``scripts/bench.py`` writes besides the numbers: the machine, the table, the plot.

The machine it ran on (:func:`machine_facts`, :func:`load_average`, :func:`package_version`),
``bench.md`` (:func:`bench_markdown`) and ``bench_scaling.png`` (:func:`plot_scaling`).
"""

from __future__ import annotations

import os
import platform
from collections.abc import Mapping
from pathlib import Path

import torch

from cpmp.benchmarks.sequencer import TICK_TARGET_MS
from cpmp.experiment.plots import new_figure, save_figure
from cpmp.records import JsonValue


# ------------------------------------------------------------------------- machine facts
def package_version(module: str) -> str | None:
    """``module.__version__`` (``None`` when it is not installed)."""
    try:
        return __import__(module).__version__
    except ImportError:
        return None


def load_average() -> list[float] | None:
    """The machine's load average over 1, 5 and 15 min (``None`` where the OS has none)."""
    try:
        return [round(v, 2) for v in os.getloadavg()]
    except OSError:
        return None


def machine_facts(threads: int) -> dict[str, JsonValue]:
    """The machine, for ``bench.json``: cores, threads, versions, platform, load average.

    ``threads`` (torch and BLAS), the Python, torch and scikit-learn versions, and the load
    average at the start.
    """
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:
        cores = os.cpu_count()
    return {
        "cores": cores,
        "threads": threads,
        "python": platform.python_version(),
        "torch": torch.__version__,
        "sklearn": package_version("sklearn"),
        "platform": platform.platform(),
        "load_average_start": load_average(),
        "note": "load average: other processes on the machine (1, 5, 15 min); timings taken "
        "under load are slower than on an idle machine",
    }


# ------------------------------------------------------------------------ plot, markdown
def plot_scaling(scaling: Mapping[str, JsonValue], path: str | Path) -> Path:
    """Log-log plot of the ``scaling`` section; returns ``path``.

    Fit time (klr fit, Newton solve, scikit-learn peer) [s] and tick cost (single, batched)
    [ms] against demonstrations and features.
    """
    figure = new_figure(10, 7)
    axes = figure.subplots(2, 2)
    for col, (key, label) in enumerate((("demos", "n_demos"), ("features", "n_features"))):
        rows = scaling[key]
        x = [row[label] for row in rows]
        fit_ax, tick_ax = axes[0, col], axes[1, col]
        for field_name, name in (
            ("fit_seconds", "klr fit (Lightning)"),
            ("solve_seconds", "klr Newton solve"),
            ("sklearn_seconds", "scikit-learn newton-cholesky"),
        ):
            fit_ax.loglog(x, [row[field_name] for row in rows], marker="o", label=name)
        for field_name, name in (
            ("tick_single_ms", "one episode"),
            ("tick_batched_ms", f"{scaling['batch']} episodes batched"),
        ):
            tick_ax.loglog(x, [row[field_name] for row in rows], marker="o", label=name)
        tick_ax.axhline(TICK_TARGET_MS, color="grey", linestyle="--", label="target 0.1 ms")
        other = (
            f"{scaling['demos_at_features']} features"
            if key == "demos"
            else f"{scaling['features_at_demos']} demos"
        )
        fit_ax.set(xlabel=f"{key} ({other})", ylabel="fit time [s]")
        tick_ax.set(xlabel=f"{key} ({other})", ylabel="sequencer [ms per episode-tick]")
        for ax in (fit_ax, tick_ax):
            ax.set_xticks(x, [str(v) for v in x])
            ax.set_xticks([], minor=True)
            ax.grid(alpha=0.3, which="both")
            ax.legend(fontsize="small")
    figure.suptitle("Scaling on the synthetic relay task (log-log)")
    return save_figure(figure, path)


def bench_markdown(result: Mapping[str, JsonValue]) -> str:
    """The benchmark as Markdown tables."""
    m = result["machine"]
    lines = [
        "# cpmp benchmark",
        "",
        f"{m['cores']} cores, {m['threads']} torch thread(s), torch {m['torch']}, scikit-learn "
        f"{m['sklearn']}, Python {m['python']}; load average at start {m['load_average_start']}, "
        f"at end {m.get('load_average_end')} (other processes slow every timing down). "
        f"Total {result['seconds']:.0f} s.",
    ]
    sections = result["sections"]
    if "fit" in sections:
        f = sections["fit"]
        k, s = f["klr"], f["sklearn"]
        lines += [
            "",
            f"## Convex fit: klr vs scikit-learn ({f['n_demos']} simulated demos, "
            f"{f['n_heads']} heads, {f['n_support_total']} supports, "
            f"{f['n_samples_total']} samples)",
            "",
            "| what | min [s] | median [s] | loss |",
            "| --- | --- | --- | --- |",
            _row("klr: `ConcurrentSequencer.fit`", k["sequencer_fit_seconds"], k["loss"]),
            _row("klr: predictor fit (Lightning, Newton)", k["fit_seconds"], k["loss"]),
            _row("klr: Newton solve alone", k["solve_seconds"], k["solve_loss"]),
            _row("scikit-learn newton-cholesky", s["seconds"], s["loss"]),
        ]
        if "lbfgs" in f:
            lb = f["lbfgs"]
            lines.append(
                f"| klr with `solver=lbfgs` (predictor fit) | {lb['fit_seconds']:.3f} | – | "
                f"{lb['loss']:.6f} |"
            )
        lines += [
            "",
            f"Ratio klr / scikit-learn: predictor fit {f['ratio']['fit_over_sklearn']:.2f}, "
            f"Newton solve {f['ratio']['solve_over_sklearn']:.2f} (< 1: klr faster); relative "
            f"loss difference {f['loss_rel_diff']:.1e}.",
        ]
    if "sequencer" in sections:
        q = sections["sequencer"]
        lines += [
            "",
            f"## Sequencer cost ({q['n_heads']} heads, {q['n_episodes']} episodes x "
            f"{q['ticks']} ticks)",
            "",
            "| mode | ms per episode-tick |",
            "| --- | --- |",
            f"| one episode at a time | {q['single_ms']:.4f} (p95 {q['single_ms_p95']:.4f}) |",
            f"| {q['n_episodes']} batched | {q['batched_ms']:.4f} |",
            "",
            f"Target <= {q['target_ms']} ms batched: {'met' if q['meets_target'] else 'missed'}; "
            f"same transitions single and batched: {q['same_decisions']}.",
        ]
    if "realtime" in sections:
        r = sections["realtime"]
        lines += [
            "",
            f"## Real-time factor ({r['n_episodes']} closed-loop episodes)",
            "",
            "| mode | sim time [s] | wall [s] | real-time factor | physics / kinematics / "
            "policy / other [ms per episode-tick] |",
            "| --- | --- | --- | --- | --- |",
        ]
        for mode in ("single", "batched"):
            t = r[mode]
            ms = t["ms_per_tick"]
            parts = ("physics", "kinematics", "policy", "other")
            cost = " / ".join(f"{ms.get(key, 0.0):.3f}" for key in parts)
            lines.append(
                f"| {mode} | {t['sim_time_s']:.1f} | {t['wall_time_s']:.1f} | "
                f"{t['real_time_factor']:.1f} | {cost} |"
            )
        lines += ["", f"Same outcomes single and batched: {r['same_outcomes']}."]
    if "stages" in sections:
        st = sections["stages"]
        lines += [
            "",
            f"## Main job `{st['command']}` ({st['workers']} worker(s))",
            "",
            f"Process wall time {st['process_wall_s']:.1f} s (the job itself "
            f"{st['job_seconds']:.1f} s).",
            "",
            "| stage | seconds |",
            "| --- | --- |",
        ]
        lines += [f"| {k} | {v:.1f} |" for k, v in st["stages"].items()]
    if "scaling" in sections:
        sc = sections["scaling"]
        lines += ["", "## Scaling (synthetic relay task; `bench_scaling.png`)"]
        for key, label, other in (
            ("demos", "demos", f"{sc['demos_at_features']} features"),
            ("features", "features", f"{sc['features_at_demos']} demos"),
        ):
            lines += [
                "",
                f"By {label} ({other}):",
                "",
                f"| {label} | supports | fit [s] | Newton [s] | scikit-learn [s] | tick single "
                "[ms] | tick batched [ms] |",
                "| --- | --- | --- | --- | --- | --- | --- |",
            ]
            lines += [
                f"| {row['n_' + label]} | {row['n_support_total']} | {row['fit_seconds']:.3f} | "
                f"{row['solve_seconds']:.3f} | {row['sklearn_seconds']:.3f} | "
                f"{row['tick_single_ms']:.4f} | {row['tick_batched_ms']:.4f} |"
                for row in sc[key]
            ]
    if "gradient" in sections:
        g = sections["gradient"]
        lines += [
            "",
            f"## Gradient-trained predictors ({g['n_demos']} synthetic demos)",
            "",
            "| predictor | fit [s] | epochs run | max epochs | loss | step [ms] |",
            "| --- | --- | --- | --- | --- | --- |",
        ]
        lines += [
            f"| {kind} | {p['fit_seconds']:.2f} | {p['epochs']} | {p['max_epochs']} | "
            f"{p['loss']:.5f} | {p['step_ms_mean']:.3f} |"
            for kind, p in g["predictors"].items()
        ]
    return "\n".join(lines) + "\n"


def _row(name: str, seconds: Mapping[str, float], loss: float) -> str:
    return f"| {name} | {seconds['min']:.3f} | {seconds['median']:.3f} | {loss:.6f} |"
