"""The jobs of ``experiment=compare`` and their scheduler.

Per seed the demonstrations and the demonstrator's runs on the reproduction boxes are collected
once (:func:`cpmp.experiment.collection.collect_seed`); each (seed, row, D) is then one job
(:func:`run_row`): fit on the balanced subset of D training demos, progress MAE on the
held-out demos, mean ``step()`` time over one held-out demonstration replayed open loop, and
the closed-loop reproduction of every box. :func:`run_jobs` runs them serially or on spawned
worker processes; every job seeds itself and depends only on its own inputs, so the numbers do
not depend on the worker count or the order.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

from cpmp.errors import CpmpError
from cpmp.experiment.config import to_dict
from cpmp.experiment.settings import ExperimentSettings
from cpmp.experiment.workers import spawned_pool

if TYPE_CHECKING:
    from cpmp.compare.job import RowSpec
    from cpmp.experiment.collection import SeedData

log = logging.getLogger(__name__)


def _collect(cfg: dict[str, Any], run_dir: Path, seed: int) -> SeedData:
    from omegaconf import OmegaConf

    from cpmp.experiment.collection import collect_seed

    return collect_seed(OmegaConf.create(cfg), run_dir, seed)


def tick_ms(seq: Any, demo: Any) -> float:
    """Mean wall time [ms] of one ``step()`` over ``demo``'s feature stream replayed open
    loop (after a ``reset`` on its first sample).
    """
    seq.reset(float(demo.time[0]), demo.features[0])
    elapsed = 0.0
    for t, x in zip(demo.time[1:], demo.features[1:], strict=True):
        start = time.perf_counter()
        seq.step(float(t), x)
        elapsed += time.perf_counter() - start
    return 1e3 * elapsed / max(len(demo.time) - 1, 1)


def run_row(cfg: Mapping[str, Any], spec: RowSpec, data: SeedData, d: int) -> dict[str, Any]:
    """One (seed, row, D) job: fit, progress MAE, tick time and closed-loop reproduction.

    Returns the row's numbers for this seed (``W``, ``I``, ``C``, ``diverged``, ``mae``,
    ``fit_s``, ``tick_ms``, ``supports``), ``error`` (a refused fit: the numbers are
    ``None``), ``episodes`` (one summary dict per box: outcome, reason, chosen strategy, ...)
    and ``seconds`` / ``cpu_seconds`` per stage.
    """
    import torch

    from cpmp.config import TaskConfig
    from cpmp.evaluation.offline import activation_progress, progress_errors
    from cpmp.experiment.fitting import fit_sequencer
    from cpmp.experiment.reproduction import reproduce_seed, summarize_episodes
    from cpmp.experiment.strategies import balanced_subset

    torch.manual_seed(data.seed)  # fits draw from their own generators; this is a safety net
    settings = ExperimentSettings.from_cfg(cfg["experiment"])
    task = TaskConfig.from_dict(cfg["task"])
    trainer = {**to_dict(cfg.get("trainer")), "logger": None, "progress_bar": False}
    seconds: dict[str, float] = {}
    cpu: dict[str, float] = {}
    out: dict[str, Any] = {key: None for key in ("W", "I", "C", "diverged", "mae", "tick_ms")}
    out.update(error=None, episodes=[], seconds=seconds, cpu_seconds=cpu)

    def timed(key: str, start: float, start_cpu: float) -> None:
        seconds[key] = time.perf_counter() - start
        cpu[key] = time.process_time() - start_cpu

    subset = balanced_subset(data.train, d)
    start, start_cpu = time.perf_counter(), time.process_time()
    try:
        seq = fit_sequencer(subset, spec.predictor_cfg, spec.sequencer_cfg, trainer, data.seed)
    except CpmpError as err:
        timed("fit", start, start_cpu)
        out.update(error=f"{type(err).__name__}: {err}", fit_s=None, supports=None)
        return out
    timed("fit", start, start_cpu)
    out["fit_s"] = seconds["fit"]
    out["supports"] = seq.fit_summary.get("n_support_total")
    start, start_cpu = time.perf_counter(), time.process_time()
    out["mae"] = progress_errors(activation_progress(seq, data.test))["mae"]
    out["tick_ms"] = tick_ms(seq, data.test[0])
    timed("evaluate", start, start_cpu)
    start, start_cpu = time.perf_counter(), time.process_time()
    episodes = reproduce_seed(
        seq,
        data,
        task,
        record="none",
        max_time=settings.max_time,
        label=f"seed {data.seed} D{d} {spec.label()}: ",
    )
    timed("reproduce", start, start_cpu)
    summary = summarize_episodes(episodes)
    out.update({k: summary[k] for k in ("W", "I", "C", "diverged")})
    out["episodes"] = [e.to_dict() for e in episodes]
    return out


# ----------------------------------------------------------------------------- scheduler
def _say(text: str) -> None:
    """A progress line (the Hydra entry points show the ``cpmp`` log on the console)."""
    log.info("%s", text)


def run_jobs(
    plain: dict[str, Any],
    run_dir: Path,
    settings: ExperimentSettings,
    jobs: Mapping[str, tuple[RowSpec, int, int]],
    workers: int,
    started: float,
) -> tuple[dict[int, SeedData], dict[str, dict[str, Any]]]:
    """Collect every seed, then run its jobs; serially in this process with one worker, else
    on ``workers`` spawned processes, each given the next job as it frees up: collections
    first, then the job expected to take longest (the same row and D of an earlier seed tells;
    rows not yet measured go first, largest D first). The order changes no number.

    Args:
        plain: the job's composed config as plain containers (what the workers get).
        run_dir: where each seed's ``seed_<s>/demos.h5`` goes.
        settings: the ``experiment`` group.
        jobs: fit key -> (row, seed, D), one entry per fit.
        workers: worker processes (1: everything in this process).
        started: ``time.perf_counter()`` at the run's start (for the progress lines).

    Returns:
        The collected data by seed, and each job's :func:`run_row` result by fit key.
    """
    collected: dict[int, SeedData] = {}
    results: dict[str, dict[str, Any]] = {}
    order = {key: i for i, key in enumerate(sorted(jobs, key=lambda k: -jobs[k][2]))}
    done = 0

    def report(key: str, result: dict[str, Any]) -> None:
        nonlocal done
        done += 1
        spec, seed, d = jobs[key]
        if result["error"]:
            what = f"refused: {result['error']}"
        else:
            what = (
                f"W/I/C {result['W']}/{result['I']}/{result['C']} of {settings.n_boxes}, "
                f"MAE {result['mae']:.3f}, fit {result['fit_s']:.1f} s, "
                f"tick {result['tick_ms']:.2f} ms"
            )
        elapsed = time.perf_counter() - started
        _say(f"[{done}/{len(jobs)}] seed {seed} D={d} {spec.label()}: {what} ({elapsed:.0f} s)")

    def collected_now(seed: int) -> None:
        _say(f"seed {seed}: demonstrations collected ({time.perf_counter() - started:.0f} s)")

    if workers <= 1:
        for seed in settings.seeds:
            collected[seed] = _collect(plain, run_dir, seed)
            collected_now(seed)
            for key in sorted((k for k in jobs if jobs[k][1] == seed), key=order.__getitem__):
                spec, _, d = jobs[key]
                results[key] = run_row(plain, spec, collected[seed], d)
                report(key, results[key])
        return collected, results

    from concurrent.futures import FIRST_COMPLETED, Future, wait

    def identity(key: str) -> tuple[Any, ...]:
        spec, _, d = jobs[key]
        return (spec.group, spec.predictor, spec.sequencer, spec.support_scale, d)

    measured: dict[tuple[Any, ...], float] = {}
    seeds = list(settings.seeds)
    ready: list[str] = []

    def next_job() -> tuple[str, Any] | None:
        if seeds:
            return "collect", seeds.pop(0)
        if not ready:
            return None
        key = min(ready, key=lambda k: (-measured.get(identity(k), math.inf), order[k]))
        ready.remove(key)
        return "row", key

    pending: dict[Future, tuple[str, Any]] = {}
    with spawned_pool(workers) as pool:

        def fill() -> None:
            while len(pending) < workers and (job := next_job()) is not None:
                what, key = job
                if what == "collect":
                    future = pool.submit(_collect, plain, run_dir, key)
                else:
                    spec, seed, d = jobs[key]
                    future = pool.submit(run_row, plain, spec, collected[seed], d)
                pending[future] = job

        fill()
        while pending:
            finished, _ = wait(pending, return_when=FIRST_COMPLETED)
            for future in sorted(finished, key=lambda f: str(pending[f])):
                what, key = pending.pop(future)
                if what == "row":
                    results[key] = future.result()
                    measured.setdefault(identity(key), sum(results[key]["seconds"].values()))
                    report(key, results[key])
                    continue
                collected[key] = future.result()
                collected_now(key)
                ready.extend(k for k in jobs if jobs[k][1] == key)
            fill()
    return collected, results
