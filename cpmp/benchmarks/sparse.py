"""The sparsity benchmark (``scripts/bench_sparse.py``): ``klr_sparse`` against the default.

Issue #23's targets for ``klr_sparse``'s defaults against the default predictor (``klr`` with
cpmp's defaults, as ``ConcurrentSequencer.fit`` uses it): held-out progress MAE within 1.1x,
at most 0.25x the support points, tick cost at most 0.5x, fit at most 2x, closed-loop
completions (C) no more than 1 below, at every training size D. Measured on the synthetic
worlds (every registered one, :mod:`cpmp.worlds.registry`, a family's first ``tasks``
members: D training demonstrations of seed ``s``, held-out demonstrations of seed
``HELD_OUT_SEED + s``, ``episodes`` closed-loop episodes)
and on the simulator (``sim``: the main job's full-run demonstrations of seed ``s``, 9 train /
6 test, the balanced D of them, ``sim_boxes`` reproduction boxes, as ``experiment=full``).

Both predictors are fitted the same way, without validation demonstrations (as
``cpmp-compare`` fits them): ``klr_sparse`` then chooses its level on held-out activations of
its training demonstrations, so the held-out demonstrations it is scored on played no part in
its fit. Per world, D and seed: the fit time (the faster of ``repeats`` fits), supports,
held-out MAE, the tick cost (the predictor's call on one feature vector, as
:meth:`ConcurrentSequencer.step` makes it, and on a batch of :data:`BATCH` vectors as
batched rollouts make it, and a whole ``step()``, each the mean over one held-out
demonstration replayed open loop) and C; then the ratios sparse / default (C: the
difference). The *tick floor* is the single-vector call of the default bank stripped to
one support per node over its full call: the call's fixed cost (input checks, scaling, a dozen
small tensor calls) over its whole cost, the least tick ratio that any sparsity can reach.
Written as JSON (atomically); nothing here asserts a number.
"""

from __future__ import annotations

import argparse
import copy
import json
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import torch

from cpmp.benchmarks.cli import given_options, run_settings_benchmark
from cpmp.config import TaskConfig
from cpmp.data.datafile import load_demonstrations, save_demonstrations
from cpmp.data.demonstration import Demonstration
from cpmp.errors import ConfigError
from cpmp.evaluation.offline import activation_progress, progress_errors
from cpmp.experiment.collection import SeedData
from cpmp.experiment.reproduction import reproduce_seed, summarize_episodes
from cpmp.experiment.strategies import balanced_subset, split_by_strategy, strategy_signatures
from cpmp.io import atomic_write_text, to_builtin
from cpmp.records import JsonValue
from cpmp.sequencer import ConcurrentSequencer
from cpmp.sim import Box, record_demonstrations, sample_box
from cpmp.sim.collect import sample_boxes
from cpmp.worlds.protocol import World
from cpmp.worlds.protocol import evaluate as evaluate_world
from cpmp.worlds.registry import members, world_names

SYNTHETIC_WORLDS = world_names()
"""Every registered synthetic world (:mod:`cpmp.worlds.registry`)."""
WORLDS = (*SYNTHETIC_WORLDS, "sim")
PREDICTORS = ("klr", "klr_sparse")
"""The default predictor (``ConcurrentSequencer.fit``'s) and the sparse one."""
HELD_OUT_SEED = 1000
"""Held-out demonstrations and episodes of seed ``s`` are drawn with ``HELD_OUT_SEED + s``."""
TARGETS = {"mae": 1.1, "supports": 0.25, "tick": 0.5, "fit": 2.0, "complete": -1.0}
"""Issue #23's bounds on the ratios sparse / default (``complete``: on the difference)."""
BATCH = 256
"""Feature vectors per call of the batched tick cost (``batch_ms``)."""
SIM_DEMOS_PER_STRATEGY, SIM_TRAIN_PER_STRATEGY = 5, 3
"""The main job's full run (``experiment=full``): 15 demonstrations, 9 train / 6 test."""


@dataclass
class SparseSettings:
    """What the sparsity benchmark runs.

    Attributes:
        worlds: of :data:`WORLDS`.
        sizes: training sizes D.
        seeds: seeds of the synthetic worlds.
        sim_seeds: seeds of the simulator's full-run demonstrations.
        held_out: held-out demonstrations per synthetic world and seed.
        episodes: closed-loop episodes per synthetic world, D and seed.
        sim_boxes: reproduction boxes per simulator seed (the main job's full run: 20).
        repeats: fits per predictor; the fastest counts.
        options: extra ``klr_sparse`` options (e.g. ``{"level": 0.1}``).
        tasks: members run of a family world (the procedural one); pooled like seeds.
        cache: a directory for the simulator's demonstrations and reproduction runs
            (reused when present), or ``None``.
    """

    worlds: tuple[str, ...] = WORLDS
    sizes: tuple[int, ...] = (3, 6, 9)
    seeds: tuple[int, ...] = (0, 1, 2)
    sim_seeds: tuple[int, ...] = (0,)
    held_out: int = 6
    episodes: int = 20
    sim_boxes: int = 20
    repeats: int = 2
    options: dict[str, JsonValue] = field(default_factory=dict)
    tasks: int = 10
    cache: str | None = None

    def __post_init__(self) -> None:
        unknown = sorted(set(self.worlds) - set(WORLDS))
        if unknown:
            raise ConfigError(f"unknown world(s) {unknown}; known: {', '.join(WORLDS)}")
        counts = {"held_out": self.held_out, "episodes": self.episodes, "tasks": self.tasks}
        counts |= {"sim_boxes": self.sim_boxes, "repeats": self.repeats}
        for name, value in counts.items():
            if int(value) < 1:
                raise ConfigError(f"{name} must be >= 1, got {value}")
        if not self.sizes or min(self.sizes) < 1:
            raise ConfigError(f"sizes must be training sizes >= 1, got {self.sizes}")

    @classmethod
    def quick(cls, **options: object) -> SparseSettings:
        """A tiny run (the tests): two_point, D = 3, one seed, 4 episodes, one fit each.

        Args:
            **options: fields of :class:`SparseSettings` over those (passed through).
        """
        base = {"worlds": ("two_point",), "sizes": (3,), "seeds": (0,), "held_out": 2}
        base |= {"episodes": 4, "repeats": 1}
        return cls(**{**base, **options})


@dataclass
class _World:
    """A world's data for one seed: demonstrations to train on and to score, and its C."""

    train: list[Demonstration]
    test: list[Demonstration]
    complete: Callable[[ConcurrentSequencer], int]
    subset: Callable[[int], list[Demonstration]]


@dataclass(frozen=True)
class SparseRow:
    """One world, task, D and seed of the benchmark: both predictors measured, and the ratios.

    Attributes:
        world: the world's name (``sim``: the simulator).
        task: the member of a family world (0 otherwise).
        D: training demonstrations.
        seed: the seed of the demonstrations and fits.
        default: the default predictor's measures (:func:`measure`).
        sparse: ``klr_sparse``'s measures.
        facts: ``klr_sparse``'s chosen ``level``, ``gamma_scale`` and its ``validation``.
        ratios: sparse / default per measure and the targets met (:func:`ratios`).
    """

    world: str
    task: int
    D: int
    seed: int
    default: dict[str, float]
    sparse: dict[str, float]
    facts: dict[str, JsonValue]
    ratios: dict[str, float | dict[str, bool]]

    def to_dict(self) -> dict[str, JsonValue]:
        """The JSON row (as ``bench_sparse.json`` holds it).

        ``world``, ``task``, ``D``, ``seed``, ``default``, ``sparse`` (the measures, then the
        facts) and ``ratios``.
        """
        return {
            "world": self.world,
            "task": self.task,
            "D": self.D,
            "seed": self.seed,
            "default": self.default,
            "sparse": {**self.sparse, **self.facts},
            "ratios": self.ratios,
        }


def _synthetic(world: World, seed: int, settings: SparseSettings) -> _World:
    """A synthetic world's demonstrations of ``seed`` and its closed-loop completions."""
    held_out = world.demonstrations(settings.held_out, HELD_OUT_SEED + seed)

    def complete(seq: ConcurrentSequencer) -> int:
        return evaluate_world(world, seq, settings.episodes, HELD_OUT_SEED + seed).complete

    return _World([], held_out, complete, lambda d: world.demonstrations(d, seed))


def _sim_data(seed: int, settings: SparseSettings) -> SeedData:
    """The simulator's full-run demonstrations of ``seed`` and the demonstrator's runs.

    As the main job collects them (boxes from ``seed``, reproduction boxes from ``seed +
    1000``); read from / written to ``settings.cache`` when it is set.
    """
    task = TaskConfig()
    cache = None if settings.cache is None else Path(settings.cache) / f"sim_seed_{seed}"
    demos_file = None if cache is None else cache / "demos.h5"
    boxes_file = None if cache is None else cache / f"boxes_{settings.sim_boxes}.json"
    expected_file = None if cache is None else cache / f"expected_{settings.sim_boxes}.h5"
    if demos_file is not None and demos_file.exists():
        train = load_demonstrations(demos_file, split="train")
        test = load_demonstrations(demos_file, split="test")
    else:
        n = 3 * SIM_DEMOS_PER_STRATEGY
        boxes = sample_boxes(np.random.default_rng(seed), task, n, balanced=True)
        demos = record_demonstrations(boxes, task, [f"demo_{i:03d}" for i in range(n)])
        train, test = split_by_strategy(demos, SIM_TRAIN_PER_STRATEGY)
        if demos_file is not None:
            demos_file.parent.mkdir(parents=True, exist_ok=True)
            splits = {"train": [d.name for d in train], "test": [d.name for d in test]}
            save_demonstrations(demos_file, demos, splits=splits)
    if boxes_file is not None and boxes_file.exists() and expected_file.exists():
        boxes = [Box(**b) for b in json.loads(boxes_file.read_text())]
        expected = load_demonstrations(expected_file)
    else:
        rng = np.random.default_rng(seed + HELD_OUT_SEED)
        boxes = [sample_box(rng, task) for _ in range(settings.sim_boxes)]
        expected = record_demonstrations(boxes, task)
        if boxes_file is not None:
            atomic_write_text(boxes_file, json.dumps([asdict(b) for b in boxes]))
            save_demonstrations(expected_file, expected)
    return SeedData(seed, train, test, boxes, expected, strategy_signatures(train))


def _sim(seed: int, settings: SparseSettings) -> _World:
    """The simulator's world of ``seed``: C over the reproduction boxes."""
    data = _sim_data(seed, settings)
    task = TaskConfig()

    def complete(seq: ConcurrentSequencer) -> int:
        return int(summarize_episodes(reproduce_seed(seq, data, task, record="none"))["C"])

    return _World(data.train, data.test, complete, lambda d: balanced_subset(data.train, d))


def tick_costs(seq: ConcurrentSequencer, demo: Demonstration) -> dict[str, float]:
    """Mean wall time [ms] per tick over ``demo`` replayed open loop.

    Returns:
        ``predictor_ms``: the predictor's call on one feature vector (as a control tick
        evaluates it); ``floor_ms``: the same call after the bank is
        stripped (on a copy) to one support per node, the call's fixed cost, below which no
        sparsity brings ``predictor_ms``; ``batch_ms``: on :data:`BATCH` vectors at once
        (the demonstration's rows, repeated as needed); ``step_ms``: a whole
        :meth:`ConcurrentSequencer.step`.
    """
    x = torch.as_tensor(np.ascontiguousarray(demo.features))
    batch = x[torch.arange(BATCH) % x.shape[0]]
    stripped = copy.deepcopy(seq.predictor)
    mask = stripped.support_mask
    stripped.keep_supports(mask & (torch.cumsum(mask.long(), 1) == 1))
    out = {
        "predictor_ms": _call_ms(seq.predictor, list(x)),
        "floor_ms": _call_ms(stripped, list(x)),
        "batch_ms": _call_ms(seq.predictor, [batch] * len(x)),
    }
    seq.reset(float(demo.time[0]), demo.features[0])
    start = time.perf_counter()
    for t, row in zip(demo.time[1:], demo.features[1:], strict=True):
        seq.step(float(t), row)
    out["step_ms"] = 1e3 * (time.perf_counter() - start) / max(len(demo.time) - 1, 1)
    return out


def _call_ms(predictor: torch.nn.Module, inputs: list[torch.Tensor]) -> float:
    """Mean wall time [ms] of ``predictor(v)`` over ``inputs[1:]`` (the first warms up).

    A 1-d input is one feature vector (called as ``(1, d)``).
    """
    batches = [v[None] if v.dim() == 1 else v for v in inputs]
    with torch.no_grad():
        predictor(batches[0])  # caches built
        start = time.perf_counter()
        for v in batches[1:]:
            predictor(v)
        return 1e3 * (time.perf_counter() - start) / max(len(batches) - 1, 1)


def measure(
    kind: str,
    demos: Sequence[Demonstration],
    world: _World,
    seed: int,
    settings: SparseSettings,
) -> tuple[dict[str, float], dict[str, JsonValue]]:
    """Fit ``kind`` on ``demos`` and measure it (see the module docstring).

    Returns:
        The measures: ``fit_s`` [s], ``supports``, held-out ``mae``, the tick costs of
        :func:`tick_costs` [ms] and ``complete`` (C); and for ``klr_sparse`` the fit's
        ``level``, ``gamma_scale`` and ``validation`` (empty for the others).
    """
    options = dict(settings.options) if kind == "klr_sparse" else {}
    times = []
    for _ in range(settings.repeats):
        start = time.perf_counter()
        seq = ConcurrentSequencer.fit(list(demos), kind, seed=seed, logger=None, **options)
        times.append(time.perf_counter() - start)
    report = seq.fit_summary
    row: dict[str, float] = {
        "fit_s": min(times),
        "supports": int(report.n_support_total),
        "mae": float(progress_errors(activation_progress(seq, world.test))["mae"]),
        **tick_costs(seq, world.test[0]),
        "complete": world.complete(seq),
    }
    facts: dict[str, JsonValue] = {}
    if kind == "klr_sparse":
        predictor_facts = report.predictor_facts
        facts["level"] = predictor_facts.get("sparsity_level")
        facts["gamma_scale"] = predictor_facts.get("sparsity_gamma_scale")
        facts["validation"] = predictor_facts.get("sparsity_validation")
    return row, facts


def ratios(
    default: Mapping[str, float], sparse: Mapping[str, float]
) -> dict[str, float | dict[str, bool]]:
    """Sparse / default per measure (``complete``: sparse − default) and the targets met.

    Returns:
        ``mae``, ``supports``, ``tick``, ``tick_floor``, ``batch``, ``step``, ``fit``,
        ``complete``, and ``met``: each target of :data:`TARGETS` met.
    """
    out = {
        "mae": sparse["mae"] / default["mae"],
        "supports": sparse["supports"] / default["supports"],
        "tick": sparse["predictor_ms"] / default["predictor_ms"],
        "tick_floor": default["floor_ms"] / default["predictor_ms"],
        "batch": sparse["batch_ms"] / default["batch_ms"],
        "step": sparse["step_ms"] / default["step_ms"],
        "fit": sparse["fit_s"] / default["fit_s"],
        "complete": sparse["complete"] - default["complete"],
    }
    met = {
        name: (out[name] >= bound if name == "complete" else out[name] <= bound)
        for name, bound in TARGETS.items()
    }
    return {**out, "met": met}


def run_sparse_benchmark(
    settings: SparseSettings, log: Callable[[str], None] | None = None
) -> dict[str, JsonValue]:
    """The benchmark of ``settings``.

    Returns:
        ``{"settings", "targets", "rows": [...], "summary": {world: {D: ...}}}``: a row per
        world, D and seed (``default``, ``sparse``, ``ratios``); the summary pools the seeds
        (means of the measures, ratios of the means, C as the mean difference) and says
        which targets are met.
    """
    rows: list[SparseRow] = []
    for name in settings.worlds:
        seeds = settings.sim_seeds if name == "sim" else settings.seeds
        for seed in seeds:
            if name == "sim":
                worlds = [_sim(seed, settings)]
            else:
                worlds = [_synthetic(w, seed, settings) for w in members(name, settings.tasks)]
            for task, world in enumerate(worlds):
                for d in settings.sizes:
                    demos = world.subset(d)
                    default, _ = measure("klr", demos, world, seed, settings)
                    sparse, facts = measure("klr_sparse", demos, world, seed, settings)
                    ratio = ratios(default, sparse)
                    row = SparseRow(name, task, d, seed, default, sparse, facts, ratio)
                    rows.append(row)
                    if log is not None:
                        log(_line(row))
    return to_builtin(
        {
            "settings": asdict(settings),
            "targets": TARGETS,
            "rows": [row.to_dict() for row in rows],
            "summary": summarise(rows),
        }
    )


def summarise(rows: Sequence[SparseRow]) -> dict[str, dict[str, dict[str, JsonValue]]]:
    """Per world and D, the seeds pooled: mean measures and the ratios of the means.

    Returns:
        world -> D (a string) -> ``seeds``, ``default`` and ``sparse`` (the mean measures)
        and ``ratios`` (:func:`ratios` of the means).
    """
    out: dict[str, dict[str, dict[str, JsonValue]]] = {}
    keys = ("fit_s", "supports", "mae", "predictor_ms", "floor_ms", "batch_ms")
    keys += ("step_ms", "complete")
    for name in dict.fromkeys(r.world for r in rows):
        for d in dict.fromkeys(r.D for r in rows if r.world == name):
            group = [r for r in rows if r.world == name and r.D == d]
            mean = {
                "default": {k: float(np.mean([r.default[k] for r in group])) for k in keys},
                "sparse": {k: float(np.mean([r.sparse[k] for r in group])) for k in keys},
            }
            out.setdefault(name, {})[str(d)] = {
                "seeds": len(group),
                **mean,
                "ratios": ratios(mean["default"], mean["sparse"]),
            }
    return out


def _line(row: SparseRow) -> str:
    """One row as a progress line."""
    r = row.ratios
    return (
        f"{row.world} D{row.D} seed {row.seed}: mae x{r['mae']:.2f}, supports "
        f"x{r['supports']:.2f}, tick x{r['tick']:.2f} (floor "
        f"x{r['tick_floor']:.2f}, batch "
        f"x{r['batch']:.2f}, step x{r['step']:.2f}), fit "
        f"x{r['fit']:.2f}, C {row.sparse['complete']} vs {row.default['complete']}"
    )


def markdown(result: Mapping[str, JsonValue]) -> str:
    """The pooled ratios as a Markdown table (a target missed is marked ``!``).

    ``tick floor x``: the default bank's call stripped to one support per node over its
    call: with this call path, the least tick ratio any sparsity can reach. A result written
    while the sequencer could add start heads (before issue #32 removed them) also has their
    supports counted in (``supports_all``): its table keeps that column, ``all supports x``.
    """
    summaries = [s for by_d in result["summary"].values() for s in by_d.values()]
    with_all = any("supports_all" in s["ratios"] for s in summaries)
    columns = ["world", "D", "MAE x", "supports x", *(["all supports x"] * with_all)]
    columns += ["tick x", "tick floor x", "batch tick x", "step x", "fit x", "C sparse - default"]
    lines = ["| " + " | ".join(columns) + " |", "|" + " --- |" * len(columns)]
    for name, by_d in result["summary"].items():
        for d, s in by_d.items():
            r, met = s["ratios"], s["ratios"]["met"]

            def cell(key: str, fmt: str, r: Mapping[str, JsonValue] = r, met: dict = met) -> str:
                return format(r[key], fmt) + ("" if met.get(key, True) else " !")

            cells = [name, d, cell("mae", ".2f"), cell("supports", ".2f")]
            if with_all:
                cells.append(format(r["supports_all"], ".2f"))
            cells += [cell("tick", ".2f"), format(r["tick_floor"], ".2f")]
            cells += [format(r["batch"], ".2f"), format(r["step"], ".2f"), cell("fit", ".2f")]
            cells.append(cell("complete", "+.1f"))
            lines.append("| " + " | ".join(map(str, cells)) + " |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    """``scripts/bench_sparse.py``: run the sparsity benchmark, write its JSON, print the table.

    Args:
        argv: the command line (default ``sys.argv[1:]``).

    Returns:
        The exit status: 0, or 2 after a :class:`~cpmp.errors.CpmpError` (a bad option).
    """
    parser = argparse.ArgumentParser(
        description=(
            "klr_sparse's defaults against the default predictor on the synthetic worlds and "
            "the simulator's full-run demonstrations: held-out MAE, supports, tick cost, fit "
            "time and closed-loop completions, as ratios per world and D. Writes JSON, prints "
            "a Markdown table."
        )
    )
    parser.add_argument("--out", default="logs/bench_sparse.json", help="the JSON file")
    parser.add_argument("--quick", action="store_true", help="SparseSettings.quick (a test)")
    parser.add_argument("--worlds", nargs="+", choices=WORLDS, help=f"default: {WORLDS}")
    parser.add_argument("--sizes", type=int, nargs="+", help="training sizes D (3 6 9)")
    parser.add_argument("--seeds", type=int, nargs="+", help="synthetic seeds (0 1 2)")
    parser.add_argument("--sim-seeds", type=int, nargs="+", help="simulator seeds (0)")
    parser.add_argument("--episodes", type=int, help="synthetic closed-loop episodes (20)")
    parser.add_argument("--sim-boxes", type=int, help="simulator reproduction boxes (20)")
    parser.add_argument("--repeats", type=int, help="fits per predictor, fastest counts (2)")
    parser.add_argument("--level", type=float, help="klr_sparse's level (default: chosen)")
    parser.add_argument("--cache", help="directory caching the simulator's demonstrations")
    parser.add_argument("--tasks", type=int, help="members of a family world (10)")
    args = parser.parse_args(argv)
    names = ("worlds", "sizes", "seeds", "sim_seeds", "episodes", "sim_boxes", "repeats", "cache")
    names += ("tasks",)
    options = given_options(args, names)
    if args.level is not None:
        options["options"] = {"level": args.level}
    return run_settings_benchmark(
        "bench_sparse", args, SparseSettings, options, run_sparse_benchmark, markdown
    )
