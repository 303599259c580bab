"""The comparison's numbers with their intervals: rows, paired differences and the claims.

Every row (a world, a configuration, a training size D) pools its seeds: the W / I / C rates
over every episode of every seed, the MAE over every held-out sample, fit and tick time and
support points over the seeds, each with its hierarchical bootstrap interval
(:func:`cpmp.compare.stats.interval`). Two rows of one world and D ran the same episodes and
held-out demonstrations, so their difference is a paired bootstrap
(:func:`cpmp.compare.stats.paired_difference`, significant when a sign-flip test agrees);
:func:`pair_rows` gives every pair of a world's
compared rows, :func:`claim_rows` the pairs ``compare.claims`` names, per D and pooled over D.
What :func:`pool` returns is ``compare.json``.
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
from typing_extensions import NotRequired, TypedDict  # NotRequired needs their TypedDict < 3.11

from cpmp.compare.rows import RowGroup, RowSpec
from cpmp.compare.runs import RowResult, table_outcome
from cpmp.compare.settings import ClaimSettings
from cpmp.compare.stats import (
    BootstrapOptions,
    Interval,
    IntervalRecord,
    SeedUnits,
    interval,
    paired_difference,
    sign_flip_p,
)
from cpmp.compare.worlds import World, WorldKind
from cpmp.experiment.output import jsonable
from cpmp.records import JsonValue

Metric = Literal["W", "I", "C", "mae", "fit_s", "tick_ms", "supports"]
"""A number of a row: the rates of wrong starts, incomplete and complete episodes (fractions
of the episodes), the held-out progress MAE, fit time [s], tick time [ms], support points."""
RATES: tuple[Metric, ...] = ("W", "I", "C")
"""The episode rates."""
PER_SEED: tuple[Metric, ...] = ("fit_s", "tick_ms", "supports")
"""Numbers with one value per seed (their interval resamples seeds only)."""
COMPARED: tuple[Metric, ...] = ("W", "I", "C", "mae")
"""The numbers paired differences are taken of."""


class DifferenceRecord(IntervalRecord):
    """A paired difference a − b (:func:`difference_record`): its interval, test and verdict."""

    p: float
    """The paired sign-flip test's p-value (:func:`~cpmp.compare.stats.sign_flip_p`)."""
    significant: bool
    """Whether the interval excludes 0 and ``p`` is below ``1 - level``."""


class Differences(TypedDict):
    """Row a minus row b in every :data:`COMPARED` number (``None``: no seed has it)."""

    W: DifferenceRecord | None
    I: DifferenceRecord | None  # noqa: E741 - Table I's name
    C: DifferenceRecord | None
    mae: DifferenceRecord | None


class PerSeedRecord(TypedDict):
    """A row's numbers seed by seed (``None``: the seed's fit was refused)."""

    seed: list[int]
    W: list[int | None]
    I: list[int | None]  # noqa: E741 - Table I's name
    C: list[int | None]
    mae: list[float | None]
    fit_s: list[float | None]
    tick_ms: list[float | None]
    supports: list[int | None]
    sparsity: NotRequired[list[dict[str, JsonValue]]]
    """What each seed's learned-sparsity fit chose (only where one did)."""


class ReferenceRecord(Differences):
    """A support-axis point minus the swept predictor's own row (``vs_reference``)."""

    reference: str
    """The reference row's name."""


class RowRecord(TypedDict):
    """``compare.json``'s record of one row (:func:`row_record`); rates as fractions."""

    world: str
    group: RowGroup
    predictor: str
    sequencer: str
    D: int
    option: str | None
    value: float | None
    name: str
    seeds: list[int]
    episodes: int
    W: IntervalRecord | None
    I: IntervalRecord | None  # noqa: E741 - Table I's name
    C: IntervalRecord | None
    mae: IntervalRecord | None
    fit_s: IntervalRecord | None
    tick_ms: IntervalRecord | None
    supports: IntervalRecord | None
    diverged: int
    per_seed: PerSeedRecord
    errors: list[str]
    vs_reference: NotRequired[ReferenceRecord]
    """A support-axis point's difference to the reference row (where that row exists)."""


class PairRecord(Differences):
    """Two rows of one world and D and their paired differences (:func:`pair_rows`)."""

    world: str
    D: int
    a: str
    b: str


class ClaimRecord(Differences):
    """A claim's paired differences in one world (:func:`claim_rows`)."""

    claim: str
    a: str
    b: str
    world: str
    D: int | str
    """The training size, or ``"all"``: every D pooled."""


class WorldRecord(TypedDict):
    """``compare.json``'s record of one world."""

    name: str
    label: str
    kind: WorldKind
    world: str | None
    options: dict[str, JsonValue]
    feature_noise: float
    seeds: list[int]
    train_sizes: list[int]
    episodes: int
    test_demos: int | None


class BootstrapRecord(TypedDict):
    """The bootstrap's settings."""

    samples: int
    level: float
    seed: int


class CompareResult(TypedDict):
    """``compare.json`` (:func:`pool`)."""

    worlds: list[WorldRecord]
    bootstrap: BootstrapRecord
    rows: list[RowRecord]
    pairs: list[PairRecord]
    claims: list[ClaimRecord]


@dataclass(frozen=True)
class PooledRow:
    """One row's results over its seeds, before pooling.

    Attributes:
        world: its world.
        spec: its configuration.
        d: its training size.
        results: ``(seed, result)`` for every seed of the world, in seed order.
    """

    world: World
    spec: RowSpec
    d: int
    results: list[tuple[int, RowResult]]

    @property
    def ok(self) -> list[tuple[int, RowResult]]:
        """The seeds whose fit succeeded."""
        return [(s, r) for s, r in self.results if not r.error]

    def name(self) -> str:
        """``predictor`` (a baseline: its sequencer; a support-axis point: ``option=value``)."""
        base = self.spec.sequencer if self.spec.group == "baselines" else self.spec.predictor
        return f"{base} {self.spec.point()}".strip()


def units(result: RowResult, metric: Metric) -> SeedUnits | None:
    """One seed's units of ``metric`` (``None``: the seed has no such number).

    Rates: one 0/1 unit per episode; ``mae``: one unit per held-out demonstration weighted by
    its samples; per-seed numbers: one unit.
    """
    if metric in RATES:
        if not result.outcomes:
            return None
        return SeedUnits.of([float(table_outcome(o) == metric) for o in result.outcomes])
    if metric == "mae":
        if not result.demo_errors:
            return None
        return SeedUnits.of(
            [e.mae for e in result.demo_errors], [e.samples for e in result.demo_errors]
        )
    value = getattr(result, metric)
    return None if value is None else SeedUnits.of([float(value)])


def _interval(
    results: Sequence[RowResult], metric: Metric, options: BootstrapOptions
) -> Interval | None:
    """``metric`` pooled over ``results`` (one per seed) with its interval, if any seed has it."""
    seeds = [u for r in results if (u := units(r, metric)) is not None]
    return interval(seeds, options) if seeds else None


def row_record(row: PooledRow, options: BootstrapOptions) -> RowRecord:
    """``compare.json``'s record of one row: every :data:`Metric` with its interval.

    Rates are fractions of the episodes; ``per_seed`` keeps each seed's counts and numbers,
    ``errors`` the refused fits.
    """
    ok = [r for _, r in row.ok]
    spec = row.spec
    record: dict[str, object] = {
        "world": row.world.name,
        "group": spec.group,
        "predictor": spec.predictor,
        "sequencer": spec.sequencer,
        "D": row.d,
        "option": spec.option,
        "value": spec.value,
        "name": row.name(),
        "seeds": [s for s, _ in row.ok],
        "episodes": row.world.episodes,
    }
    for metric in (*RATES, "mae", *PER_SEED):
        found = _interval(ok, metric, options)
        record[metric] = None if found is None else found.to_dict()
    record["diverged"] = sum(sum(o == "diverged" for o in r.outcomes) for r in ok)
    per_seed: dict[str, object] = {
        "seed": [s for s, _ in row.results],
        **{k: [r.count(k) if not r.error else None for _, r in row.results] for k in RATES},
        **{k: [getattr(r, k) for _, r in row.results] for k in ("mae", *PER_SEED)},
    }
    record["per_seed"] = per_seed
    if any(r.sparsity for _, r in row.results):
        per_seed["sparsity"] = [r.sparsity for _, r in row.results]
    record["errors"] = [f"seed {s}: {r.error}" for s, r in row.results if r.error]
    return jsonable(record)


def _concat(parts: Sequence[SeedUnits]) -> SeedUnits:
    """Units of one seed over several training sizes, in order."""
    return SeedUnits(
        np.concatenate([p.values for p in parts]), np.concatenate([p.weights for p in parts])
    )


def difference_record(
    a: PooledRow | Sequence[PooledRow],
    b: PooledRow | Sequence[PooledRow],
    options: BootstrapOptions,
) -> Differences:
    """Row ``a`` minus row ``b`` in every :data:`COMPARED` number, paired, with intervals.

    A sequence of rows (one per D) pools their episodes and demonstrations per seed, each
    seed's units in D order in both. A difference is ``significant`` when its interval
    excludes 0 and the paired sign-flip test (:func:`~cpmp.compare.stats.sign_flip_p`, its
    ``p``) is below ``1 - level``.

    Returns:
        ``{metric: {"estimate", "low", "high", ..., "p", "significant"} | None}``.
    """
    rows_a = [a] if isinstance(a, PooledRow) else list(a)
    rows_b = [b] if isinstance(b, PooledRow) else list(b)
    out: dict[str, DifferenceRecord | None] = {}
    for metric in COMPARED:
        paired = _paired_units(rows_a, rows_b, metric)
        if paired is None:
            out[metric] = None
            continue
        found = paired_difference(*paired, options)
        p = sign_flip_p(*paired, options.samples, options.seed)
        significant = found.excludes(0.0) and p < 1.0 - options.level
        out[metric] = {**found.to_dict(), "p": p, "significant": significant}
    return Differences(W=out["W"], I=out["I"], C=out["C"], mae=out["mae"])


def _paired_units(
    rows_a: Sequence[PooledRow], rows_b: Sequence[PooledRow], metric: Metric
) -> tuple[list[SeedUnits], list[SeedUnits]] | None:
    """Both sides' units of ``metric``, seed by seed (rows at the same D in the same order).

    Over the seeds where every row's fit succeeded and has the number (``None``: no seed).
    """
    seeds = set.intersection(*({s for s, _ in r.ok} for r in (*rows_a, *rows_b)))
    left, right = [], []
    for seed in sorted(seeds):
        ua = [units(dict(r.ok)[seed], metric) for r in rows_a]
        ub = [units(dict(r.ok)[seed], metric) for r in rows_b]
        if any(u is None for u in (*ua, *ub)):
            continue
        left.append(_concat(ua))  # type: ignore[arg-type]  # None excluded above
        right.append(_concat(ub))  # type: ignore[arg-type]
    return (left, right) if left else None


def pair_rows(rows: Sequence[PooledRow], options: BootstrapOptions) -> list[PairRecord]:
    """Every pair of compared rows (predictors and baselines) of one world and D.

    Returns:
        One record per pair: ``world``, ``D``, ``a``, ``b`` (row names) and the differences
        ``a - b`` (:func:`difference_record`).
    """
    out = []
    compared = [r for r in rows if r.spec.group != "support_sweep"]
    groups: dict[tuple[str, int], list[PooledRow]] = {}
    for row in compared:
        groups.setdefault((row.world.name, row.d), []).append(row)
    for (world, d), members in groups.items():
        for a, b in itertools.combinations(members, 2):
            record = {"world": world, "D": d, "a": a.name(), "b": b.name()}
            out.append(jsonable({**record, **difference_record(a, b, options)}))
    return out


def claim_rows(
    rows: Sequence[PooledRow], claims: Sequence[ClaimSettings], options: BootstrapOptions
) -> list[ClaimRecord]:
    """Each claim's difference ``a - b`` in every world that runs both rows.

    Per D, and over all of the world's D together (``D`` = ``"all"``: each seed's episodes and
    demonstrations of every D pooled, paired).
    """
    out = []
    compared = [r for r in rows if r.spec.group == "predictors"]
    worlds = list(dict.fromkeys(r.world.name for r in compared))
    for claim in claims:
        for world in worlds:
            mine = [r for r in compared if r.world.name == world]
            side_a = sorted((r for r in mine if r.spec.predictor == claim.a), key=lambda r: r.d)
            side_b = sorted((r for r in mine if r.spec.predictor == claim.b), key=lambda r: r.d)
            if not side_a or [r.d for r in side_a] != [r.d for r in side_b]:
                continue
            label = {"claim": claim.name, "a": claim.a, "b": claim.b, "world": world}
            for a, b in zip(side_a, side_b, strict=True):
                out.append(jsonable({**label, "D": a.d, **difference_record(a, b, options)}))
            if len(side_a) > 1:
                pooled = difference_record(side_a, side_b, options)
                out.append(jsonable({**label, "D": "all", **pooled}))
    return out


def pooled_rows(
    specs: Sequence[RowSpec], worlds: Mapping[str, World], results: Mapping[str, RowResult]
) -> list[PooledRow]:
    """One :class:`PooledRow` per spec and D, its seeds' results gathered by fit key."""
    out = []
    for spec in specs:
        world = worlds[spec.world]
        for d in spec.train_sizes:
            per_seed = [(s, results[spec.fit_key(s, d)]) for s in world.seeds]
            out.append(PooledRow(world, spec, d, per_seed))
    return out


def pool(
    specs: Sequence[RowSpec],
    worlds: Mapping[str, World],
    results: Mapping[str, RowResult],
    claims: Sequence[ClaimSettings],
    options: BootstrapOptions,
    reference: str | None = None,
) -> CompareResult:
    """``compare.json``: the worlds, every row, every pair's and every claim's differences.

    Rates are fractions of the episodes (``W``, ``I``, ``C``), the MAE in [0, 1]; every
    number is ``{"estimate", "low", "high", "level", "seeds", "units"}``. Each point of the
    support axis also gets its paired difference to ``reference``'s row of the same world and
    D (``vs_reference``; the swept predictor at its own options), where that row exists.
    """
    rows = pooled_rows(specs, worlds, results)
    records = [row_record(r, options) for r in rows]
    compared = {
        (r.world.name, r.d): r
        for r in rows
        if r.spec.group == "predictors" and r.spec.predictor == reference
    }
    for row, record in zip(rows, records, strict=True):
        base = compared.get((row.world.name, row.d))
        if row.spec.group == "support_sweep" and base is not None:
            record["vs_reference"] = jsonable(
                {"reference": base.name(), **difference_record(row, base, options)}
            )
    return {
        "worlds": [
            jsonable(
                {
                    "name": w.name,
                    "label": w.label(),
                    "kind": w.kind,
                    "world": w.world,
                    "options": w.options,
                    "feature_noise": w.feature_noise,
                    "seeds": list(w.seeds),
                    "train_sizes": list(w.train_sizes),
                    "episodes": w.episodes,
                    "test_demos": w.test_demos if w.kind == "synthetic" else None,
                }
            )
            for w in worlds.values()
        ],
        "bootstrap": {"samples": options.samples, "level": options.level, "seed": options.seed},
        "rows": records,
        "pairs": pair_rows(rows, options),
        "claims": claim_rows(rows, claims, options),
    }
