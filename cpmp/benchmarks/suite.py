"""``scripts/bench.py``: benchmarks of fitting, the sequencer, the closed loop and the main job.

:func:`run_bench` runs the sections picked in
:class:`~cpmp.benchmarks.settings.BenchSettings` and writes ``bench.json``, ``bench.md``
and ``bench_scaling.png`` atomically. Every section returns a JSON-ready dict of
measurements; nothing here asserts a speed.

Sections (module in brackets):

* ``fit`` (:mod:`~cpmp.benchmarks.fit`): the convex ``klr`` fit (cpmp's defaults) on
  the full experiment's training demonstrations against scikit-learn's
  ``LogisticRegression(solver="newton-cholesky")`` on the same kernel features: times, ratio,
  both losses.
* ``sequencer`` (:mod:`~cpmp.benchmarks.sequencer`): cost per episode-tick of
  :meth:`ConcurrentSequencer.step` one episode at a time and of :class:`BatchedSequencer`
  over ``batch`` episodes.
* ``realtime`` (:mod:`~cpmp.benchmarks.sim`): real-time factor of closed-loop
  episodes, one at a time and batched.
* ``stages`` (:mod:`~cpmp.benchmarks.sim`): the main job (``scripts/experiment.py``)
  in a fresh process, its wall time and the time of every stage (its ``timings.json``).
* ``scaling`` (:mod:`~cpmp.benchmarks.fit`): fit time and tick cost as demonstrations
  and features grow (synthetic relay task, features padded with constant columns), with a
  log-log plot.
* ``gradient`` (:mod:`~cpmp.benchmarks.sequencer`): the Adam-trained predictors
  (``mlp``) on small data: fit time and epochs run.

The machine facts, ``bench.md`` and the plot: :mod:`~cpmp.benchmarks.report`; the
command lines of every ``scripts/bench*.py``: :mod:`~cpmp.benchmarks.cli`.
"""

from __future__ import annotations

import logging
import time
from dataclasses import asdict
from pathlib import Path

import torch
from threadpoolctl import threadpool_limits

from cpmp.benchmarks.fit import bench_fit, bench_scaling
from cpmp.benchmarks.report import bench_markdown, load_average, machine_facts, plot_scaling
from cpmp.benchmarks.sequencer import bench_gradient, bench_ticks
from cpmp.benchmarks.settings import SECTIONS, BenchSettings
from cpmp.benchmarks.sim import SimData, bench_realtime, bench_stages
from cpmp.experiment.output import write_json
from cpmp.io import atomic_write_text
from cpmp.records import JsonValue
from cpmp.sequencer.sequencer import ConcurrentSequencer
from cpmp.worlds.two_point import make_demonstrations

log = logging.getLogger(__name__)


def run_bench(settings: BenchSettings, out_dir: str | Path) -> Path:
    """Run the sections of ``settings``; returns the path of ``bench.json``.

    Writes ``bench.json``, ``bench.md`` and (with the ``scaling`` section)
    ``bench_scaling.png`` into ``out_dir``.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    torch.set_num_threads(settings.threads)
    started = time.perf_counter()
    machine = machine_facts(settings.threads)
    sections: dict[str, JsonValue] = {}
    result: dict[str, JsonValue] = {
        "settings": asdict(settings),
        "machine": machine,
        "sections": sections,
    }
    scaling: dict[str, JsonValue] | None = None
    sim = SimData(settings)
    with threadpool_limits(settings.threads):
        result["warm_up_seconds"] = _warm_up(settings.seed)
        for name in SECTIONS:
            if name not in settings.sections:
                continue
            log.info("bench section %s: start", name)
            start = time.perf_counter()
            if name == "fit":
                section = bench_fit(sim.train, settings.repeats, settings.seed, settings.lbfgs)
            elif name == "sequencer":
                streams = [demo.features for demo in sim.boxes[1]]
                section = bench_ticks(sim.sequencer, streams, settings.ticks)
                section["n_demos"] = len(sim.train)
            elif name == "realtime":
                section = bench_realtime(sim)
            elif name == "stages":
                section = bench_stages(
                    settings.experiment, settings.threads, settings.experiment_overrides
                )
            elif name == "scaling":
                section = scaling = bench_scaling(
                    settings.scaling_demos,
                    settings.scaling_features,
                    settings.seed,
                    settings.batch,
                    settings.scaling_ticks,
                )
            else:
                section = bench_gradient(settings)
            section["section_seconds"] = time.perf_counter() - start
            sections[name] = section
            log.info("bench section %s: done in %.1f s", name, section["section_seconds"])
    result["seconds"] = time.perf_counter() - started
    machine["load_average_end"] = load_average()
    files: dict[str, JsonValue] = {"bench.json": "every number", "bench.md": "the tables"}
    if scaling is not None:
        plot_scaling(scaling, out / "bench_scaling.png")
        files["bench_scaling.png"] = "log-log: fit time and tick cost against demos and features"
    result["files"] = files
    atomic_write_text(out / "bench.md", bench_markdown(result))
    return write_json(out / "bench.json", result)


def _warm_up(seed: int) -> float:
    """One small untimed fit, so that no section pays for Lightning's first fit; returns [s].

    The modules the sections use (Lightning, scikit-learn) are imported with this one.
    """
    start = time.perf_counter()
    ConcurrentSequencer.fit(make_demonstrations(2, seed=seed), "klr", seed=seed, logger=None)
    return time.perf_counter() - start
