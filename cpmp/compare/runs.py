"""The jobs of the comparison (``cpmp-compare``) and their scheduler.

A simulated world's seeds are collected once each (:func:`cpmp.experiment.collection.
collect_seed`: the demonstrations and the demonstrator's runs on the reproduction boxes; worlds
whose task and sizes agree share one collection, each adding its own feature noise); a
synthetic world's data is made inside each job (it takes milliseconds). Each (world, seed, row,
D) is then one job: fit on D training demos, progress MAE on the held-out demos (per
demonstration, for the intervals), mean ``step()`` time over one held-out demonstration
replayed open loop, and the closed loop (:func:`run_sim_row`: every reproduction box;
:func:`run_synthetic_row`: the world's seeded episodes). :func:`run_jobs` runs them on an
executor (:mod:`cpmp.experiment.executors`: this process, spawned worker processes, submitit's
local processes or SLURM jobs); every job seeds itself and depends only on its own inputs, so
the numbers do not depend on the executor, the worker count or the order.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import math
import time
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple, TypeAlias

import torch
from omegaconf import OmegaConf

from cpmp.baselines.bc import BCSequencer
from cpmp.baselines.goal_nearest import GoalNearestSequencer
from cpmp.compare.rows import FitJob, RowSpec
from cpmp.compare.worlds import EPISODE_SEED_OFFSET, TEST_SEED_OFFSET, World, synthetic_run
from cpmp.config import TaskConfig
from cpmp.data import Demonstration
from cpmp.data.augment import add_feature_noise
from cpmp.errors import CpmpError
from cpmp.evaluation.offline import activation_progress
from cpmp.experiment.collection import SeedData, collect_seed
from cpmp.experiment.executors import JobExecutor, Submission, run_queue
from cpmp.experiment.fitting import fit_sequencer
from cpmp.experiment.reproduction import reproduce_seed
from cpmp.experiment.settings import ExperimentSettings, to_dict
from cpmp.experiment.strategies import balanced_subset
from cpmp.records import FitReport, JsonValue
from cpmp.sequencer.sequencer import ConcurrentSequencer

log = logging.getLogger(__name__)

Fitted: TypeAlias = "ConcurrentSequencer | GoalNearestSequencer | BCSequencer"
"""A row's fitted sequencer: the learned one or a baseline
(:func:`~cpmp.experiment.fitting.fit_sequencer`)."""


@dataclass(frozen=True)
class DemoError:
    """The progress error on one held-out demonstration.

    Attributes:
        demo: its name.
        mae: mean ``|φ - eq. 1|`` over its samples of known nodes.
        samples: how many samples that mean is over (its weight in the pooled MAE).
    """

    demo: str
    mae: float
    samples: int


@dataclass
class RowResult:
    """The numbers of one (world, seed, row, D) job.

    A refused fit leaves every number ``None`` and says why in ``error``.

    Attributes:
        outcomes: each closed-loop episode's outcome (``complete``, ``wrong_start``,
            ``incomplete``, and the simulator's ``diverged``), in episode order: episode ``i``
            is the same box or episode in every row of the world.
        demo_errors: the progress error of each held-out demonstration, in their order.
        mae: progress MAE over every held-out sample, in [0, 1].
        fit_s: wall time of the fit [s].
        tick_ms: mean wall time of one ``step()`` [ms] (:func:`tick_ms`).
        supports: support points of all nodes (``None`` for a sequencer without them).
        error: the refused fit's error (``"ConfigError: ..."``), else ``None``.
        sparsity: what a learned-sparsity fit chose (:data:`SPARSITY_KEYS` of its fit
            summary: the level, the fixed rule's count, the path), else empty.
        episodes: one summary dict per episode (outcome, reason or strategy, ...).
        seconds: wall time [s] per stage (``fit``, ``evaluate``, ``reproduce``).
        cpu_seconds: process time [s] per stage.
    """

    outcomes: list[str] = field(default_factory=list)
    demo_errors: list[DemoError] = field(default_factory=list)
    mae: float | None = None
    fit_s: float | None = None
    tick_ms: float | None = None
    supports: int | None = None
    error: str | None = None
    sparsity: dict[str, JsonValue] = field(default_factory=dict)
    episodes: list[dict[str, object]] = field(default_factory=list)
    seconds: dict[str, float] = field(default_factory=dict)
    cpu_seconds: dict[str, float] = field(default_factory=dict)

    def count(self, outcome: str) -> int:
        """Episodes of ``W`` (wrong start), ``C`` (complete) or ``I`` (any other outcome)."""
        return sum(table_outcome(o) == outcome for o in self.outcomes)


SPARSITY_KEYS = (
    "sparsity_level",
    "sparsity_gamma_scale",
    "sparsity_validation",
    "n_support_rule",
    "sparsity_path",
    "refine",
)
"""The fit-summary entries of ``klr_sparse`` a comparison keeps (its chosen level and path
and its refinement)."""


def table_outcome(outcome: str) -> str:
    """An episode's outcome as Table I counts it: ``W``, ``C`` or ``I`` (diverged is ``I``)."""
    return {"wrong_start": "W", "complete": "C"}.get(outcome, "I")


class CompareRuns(NamedTuple):
    """What :func:`run_jobs` returns."""

    collected: dict[str, SeedData]
    """The collected data of the simulated worlds, by collection key."""
    results: dict[str, RowResult]
    """Each job's result by fit key."""


# ------------------------------------------------------------------------ simulated worlds
def world_config(plain: Mapping[str, JsonValue], world: World) -> dict[str, JsonValue]:
    """The job's config (plain containers) as a simulated ``world`` runs it.

    Its ``task`` options over the job's, its seeds, sizes and boxes in the ``experiment`` group;
    feature noise 0 (the world adds its own after the shared collection).
    """
    experiment = {
        **plain["experiment"],
        "seeds": list(world.seeds),
        "train_sizes": list(world.train_sizes),
        "n_boxes": world.episodes,
        "feature_noise": 0.0,
    }
    return {**plain, "experiment": experiment, "task": {**plain["task"], **world.options}}


def collection_key(plain: Mapping[str, JsonValue], world: World, seed: int) -> str:
    """What a simulated world's seed collects: equal keys, one collection."""
    cfg = world_config(plain, world)
    sizes = {k: cfg["experiment"][k] for k in ("demos_per_strategy", "train_per_strategy")}
    more = {k: cfg["experiment"][k] for k in ("n_boxes", "box_seed_offset", "max_time")}
    return json.dumps(
        {"task": cfg["task"], **sizes, **more, "seed": seed}, sort_keys=True, default=str
    )


def _collect(cfg: dict[str, JsonValue], run_dir: Path, seed: int) -> SeedData:
    """One seed's demonstrations and reproduction boxes (``cfg``: plain containers)."""
    return collect_seed(OmegaConf.create(cfg), run_dir, seed)


def world_data(data: SeedData, world: World) -> SeedData:
    """A shared collection as ``world`` uses it: its feature noise on the training demos.

    The noise is drawn as :func:`~cpmp.experiment.collection.collect_seed` draws it (the
    seed's generator), so a world with noise equals the main job run with that noise.
    """
    if not world.feature_noise:
        return data
    train = add_feature_noise(data.train, world.feature_noise, seed=data.seed)
    return dataclasses.replace(data, train=train)


def tick_ms(seq: Fitted, demo: Demonstration) -> float:
    """Mean wall time [ms] of one ``step()`` over ``demo``'s feature stream replayed open loop.

    The sequencer is ``reset`` on the demonstration's first sample first.
    """
    seq.reset(float(demo.time[0]), demo.features[0])
    elapsed = 0.0
    for t, x in zip(demo.time[1:], demo.features[1:], strict=True):
        start = time.perf_counter()
        seq.step(float(t), x)
        elapsed += time.perf_counter() - start
    return 1e3 * elapsed / max(len(demo.time) - 1, 1)


def demo_errors(seq: Fitted, demos: Sequence[Demonstration]) -> list[DemoError]:
    """The progress error of each of ``demos``, in their order.

    From :func:`~cpmp.evaluation.offline.activation_progress`; their sample-weighted mean is
    the MAE over every held-out sample.
    """
    sums: dict[str, float] = {}
    counts: dict[str, int] = {}
    for record in activation_progress(seq, demos):
        sums[record.demo] = sums.get(record.demo, 0.0) + float(
            abs(record.predicted - record.expected).sum()
        )
        counts[record.demo] = counts.get(record.demo, 0) + len(record.expected)
    return [DemoError(name, sums[name] / counts[name], counts[name]) for name in sums]


class _Stages:
    """Wall and process time of a job's stages, into a :class:`RowResult`."""

    def __init__(self, out: RowResult) -> None:
        self.out = out

    @contextmanager
    def __call__(self, key: str) -> Iterator[None]:
        """Time the ``with`` block as stage ``key``."""
        start, start_cpu = time.perf_counter(), time.process_time()
        try:
            yield
        finally:
            self.out.seconds[key] = time.perf_counter() - start
            self.out.cpu_seconds[key] = time.process_time() - start_cpu


def _fit_and_score(
    cfg: Mapping[str, JsonValue],
    spec: RowSpec,
    train: Sequence[Demonstration],
    test: Sequence[Demonstration],
    seed: int,
    out: RowResult,
) -> Fitted | None:
    """Fit ``spec`` on ``train``, score it on ``test`` into ``out``; the sequencer or ``None``.

    A refused fit (:class:`~cpmp.errors.CpmpError`) is ``out.error`` and returns ``None``.
    """
    torch.manual_seed(seed)  # fits draw from their own generators; this is a safety net
    trainer = {**to_dict(cfg.get("trainer")), "progress_bar": False}  # no log_dir: no logger
    stage = _Stages(out)
    try:
        with stage("fit"):
            seq = fit_sequencer(train, spec.predictor_cfg, spec.sequencer_cfg, trainer, seed)
    except CpmpError as err:
        out.error = f"{type(err).__name__}: {err}"
        return None
    out.fit_s = out.seconds["fit"]
    report = seq.fit_summary
    out.supports = None if report is None else report.n_support_total
    facts = report.predictor_facts if isinstance(report, FitReport) else {}
    out.sparsity = {k: facts[k] for k in SPARSITY_KEYS if k in facts}
    with stage("evaluate"):
        out.demo_errors = demo_errors(seq, test)
        total = sum(e.samples for e in out.demo_errors)
        out.mae = sum(e.mae * e.samples for e in out.demo_errors) / total
        out.tick_ms = tick_ms(seq, test[0])
    return seq


def run_sim_row(cfg: Mapping[str, JsonValue], spec: RowSpec, data: SeedData, d: int) -> RowResult:
    """One (simulated world, seed, row, D) job: fit, MAE, tick time, every reproduction box.

    Args:
        cfg: the world's config as plain containers (:func:`world_config`).
        spec: the row.
        data: the seed's collected data with the world's noise (:func:`world_data`).
        d: the training size.

    Returns:
        The row's numbers for this seed (a refused fit: its ``error``).
    """
    settings = ExperimentSettings.from_cfg(cfg["experiment"])
    task = TaskConfig.from_dict(cfg["task"])
    out = RowResult()
    seq = _fit_and_score(cfg, spec, balanced_subset(data.train, d), data.test, data.seed, out)
    if seq is None:
        return out
    with _Stages(out)("reproduce"):
        episodes = reproduce_seed(
            seq,
            data,
            task,
            record="none",
            max_time=settings.max_time,
            label=f"seed {data.seed} D{d} {spec.label()}: ",
        )
    out.outcomes = [e.outcome for e in episodes]
    out.episodes = [e.to_dict() for e in episodes]
    return out


def run_synthetic_row(
    cfg: Mapping[str, JsonValue], spec: RowSpec, world: World, seed: int, d: int
) -> RowResult:
    """One (synthetic world, seed, row, D) job: fit, MAE, tick time, the world's episodes.

    The training demonstrations are the first ``d`` of the world's seed ``seed``, the held-out
    ones ``world.test_demos`` of seed ``seed + TEST_SEED_OFFSET``, the episodes
    ``world.episodes`` drawn from ``seed + EPISODE_SEED_OFFSET`` (the same in every row).

    Args:
        cfg: the job's config as plain containers (its ``trainer`` group).
        spec: the row.
        world: the synthetic world.
        seed: the seed.
        d: the training size.

    Returns:
        The row's numbers for this seed (a refused fit: its ``error``).
    """
    out = RowResult()
    run = synthetic_run(str(world.world), world.options, seed, max(world.train_sizes))
    test = synthetic_run(
        str(world.world), world.options, seed + TEST_SEED_OFFSET, world.test_demos
    ).demonstrations
    train = run.demonstrations[:d]
    if world.feature_noise:
        train = add_feature_noise(train, world.feature_noise, seed=seed)
    seq = _fit_and_score(cfg, spec, train, test, seed, out)
    if seq is None:
        return out
    with _Stages(out)("reproduce"):
        episodes = run.evaluate(seq, world.episodes, seed + EPISODE_SEED_OFFSET)
    out.outcomes = [e.outcome for e in episodes]
    out.episodes = [{"outcome": e.outcome, "strategy": e.strategy} for e in episodes]
    return out


# ----------------------------------------------------------------------------- scheduler
def _say(text: str) -> None:
    """A progress line (the Hydra entry points show the ``cpmp`` log on the console)."""
    log.info("%s", text)


class _Task(NamedTuple):
    """One unit of work of the scheduler: a collection or a job."""

    kind: str
    """``collect`` or ``row``."""
    key: str
    """The collection key or the fit key."""


def run_jobs(
    plain: dict[str, JsonValue],
    run_dir: Path,
    worlds: Mapping[str, World],
    jobs: Mapping[str, FitJob],
    executor: JobExecutor,
    started: float,
) -> CompareRuns:
    """Collect every simulated seed, run every job, on ``executor``.

    ``executor.slots`` tasks run at once, each slot given the next task as it frees up:
    collections first, then the job expected to take longest (with several slots the same
    world, row and D of an earlier seed tells; rows not yet measured go first, largest D
    first; with one slot the order is fixed: world by world, largest D first). The order
    changes no number.

    Args:
        plain: the job's composed config as plain containers (what the workers get).
        run_dir: where each simulated seed's ``<world>/seed_<s>/demos.h5`` goes.
        worlds: the worlds by name.
        jobs: fit key -> its job, one entry per fit (:func:`~cpmp.compare.rows.fit_jobs`).
        executor: an entered executor (:func:`~cpmp.experiment.executors.make_executor`).
        started: ``time.perf_counter()`` at the run's start (for the progress lines).

    Returns:
        The collected data by collection key, and each job's result by fit key.
    """
    configs = {name: world_config(plain, w) for name, w in worlds.items() if w.kind == "sim"}
    needs: dict[str, str] = {}  # fit key -> collection key (simulated worlds)
    first: dict[str, tuple[str, int]] = {}  # collection key -> (world, seed) collecting it
    for key, job in jobs.items():
        world = worlds[job.spec.world]
        if world.kind == "sim":
            needs[key] = collection_key(plain, world, job.seed)
            first.setdefault(needs[key], (world.name, job.seed))
    collected: dict[str, SeedData] = {}
    results: dict[str, RowResult] = {}
    by_size = sorted(jobs, key=lambda k: -jobs[k].d)
    order = {key: i for i, key in enumerate(by_size)}
    if executor.slots == 1:  # world by world, largest D first
        names = list(worlds)
        fixed = sorted(jobs, key=lambda k: (names.index(jobs[k].spec.world), order[k]))
        order = {key: i for i, key in enumerate(fixed)}
    done = 0

    def report(key: str, result: RowResult) -> None:
        nonlocal done
        done += 1
        spec, seed, d = jobs[key]
        if result.error:
            what = f"refused: {result.error}"
        else:
            counts = "/".join(str(result.count(k)) for k in ("W", "I", "C"))
            what = (
                f"W/I/C {counts} of {len(result.outcomes)}, MAE {result.mae:.3f}, "
                f"fit {result.fit_s:.1f} s, tick {result.tick_ms:.2f} ms"
            )
        elapsed = time.perf_counter() - started
        _say(f"[{done}/{len(jobs)}] seed {seed} D={d} {spec.label()}: {what} ({elapsed:.0f} s)")

    def identity(key: str) -> tuple[str, str, str, str, str, int]:
        spec, _, d = jobs[key]
        return (spec.world, spec.group, spec.predictor, spec.sequencer, spec.point(), d)

    measured: dict[tuple[str, str, str, str, str, int], float] = {}
    to_collect = list(first)
    ready = [k for k in jobs if k not in needs]

    def next_job() -> Submission[_Task, SeedData | RowResult] | None:
        if to_collect:
            ckey = to_collect.pop(0)
            name, seed = first[ckey]
            args = (configs[name], run_dir / name, seed)
            return Submission(_Task("collect", ckey), _collect, args, f"{name} seed {seed}")
        if not ready:
            return None
        if executor.slots == 1:
            key = min(ready, key=lambda k: order[k])
        else:
            key = min(ready, key=lambda k: (-measured.get(identity(k), math.inf), order[k]))
        ready.remove(key)
        spec, seed, d = jobs[key]
        world = worlds[spec.world]
        label = f"seed {seed} D={d} {spec.label()}"
        if world.kind == "sim":
            data = world_data(collected[needs[key]], world)
            args: tuple[object, ...] = (configs[world.name], spec, data, d)
            return Submission(_Task("row", key), run_sim_row, args, label)
        return Submission(
            _Task("row", key), run_synthetic_row, (plain, spec, world, seed, d), label
        )

    def finished(task: _Task, result: SeedData | RowResult) -> None:
        if task.kind == "row":
            assert isinstance(result, RowResult)  # a row's job
            results[task.key] = result
            measured.setdefault(identity(task.key), sum(result.seconds.values()))
            report(task.key, result)
            return
        assert isinstance(result, SeedData)  # a collection
        collected[task.key] = result
        name, seed = first[task.key]
        _say(
            f"{name} seed {seed}: demonstrations collected ({time.perf_counter() - started:.0f} s)"
        )
        ready.extend(k for k in jobs if needs.get(k) == task.key)

    run_queue(executor, next_job, finished)
    return CompareRuns(collected, results)
