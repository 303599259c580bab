"""The comparison's report (``compare.md``), its episodes and its timings.

``compare.md`` shows every number of ``compare.json`` (:mod:`cpmp.compare.pooling`) with its
95 % interval: the worlds, the paper's claims, each world's rows and the significance of
every difference between them, the support-count axis, refused fits and the files.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from cpmp.compare.pooling import (
    RATES,
    ClaimRecord,
    CompareResult,
    DifferenceRecord,
    PairRecord,
    RowRecord,
    WorldRecord,
)
from cpmp.compare.rows import FitJob
from cpmp.compare.runs import RowResult
from cpmp.compare.stats import IntervalRecord
from cpmp.experiment.collection import SeedData
from cpmp.experiment.output import PAPER_TABLE_I
from cpmp.records import JsonValue


def job_episodes(
    results: Mapping[str, RowResult], jobs: Mapping[str, FitJob]
) -> list[dict[str, object]]:
    """Every closed-loop episode of every job, labelled with its world, row, seed and D.

    A fit shared by two rows is listed once, under the first.
    """
    out = []
    for key, (spec, seed, d) in jobs.items():
        label = {
            "world": spec.world,
            "predictor": spec.predictor,
            "sequencer": spec.sequencer,
            "option": spec.option,
            "value": spec.value,
            "seed": seed,
            "D": d,
        }
        out += [{**label, "episode": i, **e} for i, e in enumerate(results[key].episodes)]
    return out


def job_timings(
    collected: Mapping[str, SeedData],
    results: Mapping[str, RowResult],
    jobs: Mapping[str, FitJob],
    seconds: float,
    workers: int,
    executor: str = "local",
) -> dict[str, JsonValue]:
    """Wall time of the run; wall and CPU seconds of every collection and job stage.

    With the run's executor and its jobs at once (``workers``).
    These scale the run's cost to other episode or seed counts.
    """
    tasks = []
    for key, (spec, seed, d) in jobs.items():
        r = results[key]
        tasks.append(
            {
                "world": spec.world,
                "group": spec.group,
                "predictor": spec.predictor,
                "sequencer": spec.sequencer,
                "option": spec.option,
                "value": spec.value,
                "seed": seed,
                "D": d,
                "seconds": r.seconds,
                "cpu_seconds": r.cpu_seconds,
                "episodes": len(r.outcomes),
            }
        )
    return {
        "seconds": seconds,
        "executor": executor,
        "workers": workers,
        "collections": [
            {"seed": data.seed, "seconds": data.seconds} for data in collected.values()
        ],
        "jobs": tasks,
        "note": "per-job seconds are wall time inside a worker; cpu_seconds its process time",
    }


# ------------------------------------------------------------------------------ formatting
def seeds_text(seeds: Sequence[int]) -> str:
    """Seeds as a short list: runs of three or more consecutive seeds as ``first-last``.

    E.g. ``[0, 1, ..., 39, 50, 51]`` -> ``"0-39, 50, 51"``.
    """
    parts: list[str] = []
    ordered = sorted(set(seeds))
    start = 0
    for i in range(1, len(ordered) + 1):
        if i == len(ordered) or ordered[i] != ordered[i - 1] + 1:
            run = ordered[start:i]
            parts += [f"{run[0]}-{run[-1]}"] if len(run) >= 3 else [str(x) for x in run]
            start = i
    return ", ".join(parts)


def interval_text(value: IntervalRecord | None, scale: float = 1.0, digits: int = 1) -> str:
    """``estimate [low, high]`` of an interval record, times ``scale`` (``–`` for none)."""
    if value is None:
        return "–"
    est, low, high = (scale * value[k] for k in ("estimate", "low", "high"))
    return f"{est:.{digits}f} [{low:.{digits}f}, {high:.{digits}f}]"


def difference_text(value: DifferenceRecord | None, scale: float = 1.0, digits: int = 1) -> str:
    """A signed difference ``+a [lo, hi]``, bold when significant (``–`` for none)."""
    if value is None:
        return "–"
    est, low, high = (_signed(scale * value[k], digits) for k in ("estimate", "low", "high"))
    text = f"{est} [{low}, {high}]"
    return f"**{text}**" if value["significant"] else text


def _signed(value: float, digits: int) -> str:
    """``value`` with its sign and ``digits`` decimals; one that rounds to 0 is ``+0``."""
    text = f"{value:+.{digits}f}"
    return text.replace("-", "+") if float(text) == 0.0 else text


_ROW_HEADER = (
    "| row | D | W [%] | I [%] | C [%] | MAE | fit [s] | tick [ms] | supports |",
    "| --- | --- | --- | --- | --- | --- | --- | --- | --- |",
)


def _row_line(row: RowRecord) -> str:
    """One row of a world's table: every number with its interval."""
    cells = [interval_text(row[k], 100.0, 0) for k in RATES]
    return (
        f"| `{row['name']}` | {row['D']} | "
        + " | ".join(cells)
        + f" | {interval_text(row['mae'], 1.0, 3)} | {interval_text(row['fit_s'], 1.0, 1)} | "
        f"{interval_text(row['tick_ms'], 1.0, 2)} | {interval_text(row['supports'], 1.0, 0)} |"
    )


def _paper_line(world: WorldRecord, sizes: Sequence[int]) -> list[str]:
    """The paper's Table I as rates, under the default simulated world (else nothing)."""
    if world["kind"] != "sim" or world["options"] or world["feature_noise"]:
        return []
    out = []
    for d in sizes:
        p = PAPER_TABLE_I.get(str(d))
        if p:
            rates = " | ".join(f"{100 * p[k] / 20:.0f}" for k in RATES)
            out.append(f"| paper, Table I (of 20 boxes) | {d} | {rates} | – | – | – | – |")
    return out


def _pairs_table(pairs: Sequence[PairRecord]) -> list[str]:
    """Every pair's paired differences; bold cells exclude 0."""
    lines = [
        "| D | a − b | ΔW [pp] | ΔI [pp] | ΔC [pp] | ΔMAE |",
        "| --- | --- | --- | --- | --- | --- |",
    ]
    for p in pairs:
        cells = [difference_text(p[k], 100.0, 0) for k in RATES]
        lines.append(
            f"| {p['D']} | `{p['a']}` − `{p['b']}` | "
            + " | ".join(cells)
            + f" | {difference_text(p['mae'], 1.0, 3)} |"
        )
    return lines


def _claims_table(claims: Sequence[ClaimRecord]) -> list[str]:
    """Each claim's paired differences in every world and D."""
    lines = [
        "| claim (a − b) | world | D | ΔC [pp] | ΔI [pp] | ΔW [pp] | ΔMAE |",
        "| --- | --- | --- | --- | --- | --- | --- |",
    ]
    for c in claims:
        lines.append(
            f"| {c['claim']} (`{c['a']}` − `{c['b']}`) | {c['world']} | {c['D']} | "
            f"{difference_text(c['C'], 100.0, 0)} | {difference_text(c['I'], 100.0, 0)} | "
            f"{difference_text(c['W'], 100.0, 0)} | {difference_text(c['mae'], 1.0, 3)} |"
        )
    return lines


def _supports_table(rows: Sequence[RowRecord]) -> list[str]:
    """The support-count axis: every point's supports, MAE, C, tick and fit time."""
    lines = [
        "| world | D | predictor | point | supports | MAE | C [%] | tick [ms] | fit [s] "
        "| ΔC [pp] vs reference | ΔMAE vs reference |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]

    def order(r: RowRecord) -> tuple[str, int, str, float]:
        supports = r["supports"]["estimate"] if r["supports"] else 0.0
        return (r["world"], r["D"], r["predictor"], supports)

    for r in sorted(rows, key=order):
        vs = r.get("vs_reference") or {}
        value = "default" if r["value"] is None else f"{r['value']:g}"
        chosen = [x.get("sparsity_level") for x in r["per_seed"].get("sparsity", []) if x]
        if r["value"] is None and chosen:
            value += f" (chose {', '.join(f'{c:.3g}' for c in chosen)})"
        lines.append(
            f"| {r['world']} | {r['D']} | `{r['predictor']}` | {r['option']}={value} | "
            f"{interval_text(r['supports'], 1.0, 0)} | {interval_text(r['mae'], 1.0, 3)} | "
            f"{interval_text(r['C'], 100.0, 0)} | {interval_text(r['tick_ms'], 1.0, 2)} | "
            f"{interval_text(r['fit_s'], 1.0, 1)} | {difference_text(vs.get('C'), 100.0, 0)} | "
            f"{difference_text(vs.get('mae'), 1.0, 3)} |"
        )
    return lines


def render_compare(result: CompareResult, name: str, seconds: float, workers: int) -> str:
    """``compare.md`` from ``compare.json``'s content (:func:`cpmp.compare.pooling.pool`).

    Args:
        result: the pooled rows, pairs, claims and worlds.
        name: the ``experiment`` option's name.
        seconds: the run's wall time [s].
        workers: its worker processes.

    Returns:
        The Markdown text.
    """
    boot = result["bootstrap"]
    level = f"{100 * boot['level']:.0f} %"
    lines = [
        f"# cpmp comparison `{name}`",
        "",
        f"Every number is the estimate over all seeds with its {level} interval in brackets: "
        f"a hierarchical bootstrap ({boot['samples']} replicates, seed {boot['seed']}) that "
        "resamples the seeds, then each drawn seed's episodes (or held-out demonstrations). "
        "W / I / C = wrong start / incomplete / complete, in % of the episodes (a simulated "
        "world's episodes are its random boxes, the same boxes for every row); MAE = progress "
        "error against eq. 1 over every held-out sample (goal_nearest, bc: their nearest-sample "
        "estimate, which they do not use to switch); fit [s], tick [ms] (mean `step()` over "
        "a held-out demonstration) and support points: intervals over the seeds. "
        f"Wall time {seconds / 60:.1f} min on {workers} worker(s).",
        "",
        "| world | seeds | D | episodes per D and seed | held-out demos per seed |",
        "| --- | --- | --- | --- | --- |",
    ]
    for w in result["worlds"]:
        held = w["test_demos"] if w["test_demos"] is not None else "the experiment's split"
        sizes = ", ".join(map(str, w["train_sizes"]))
        lines.append(
            f"| {w['label']} | {seeds_text(w['seeds'])} | {sizes} | {w['episodes']} | {held} |"
        )
    if result["claims"]:
        lines += [
            "",
            "## The paper's claims",
            "",
            "Paired differences a − b (the same seeds, episodes and held-out demonstrations "
            "in both rows) in percentage points of the episodes and in MAE; **bold**: "
            f"significant (the {level} interval excludes 0 and a paired sign-flip test "
            "agrees). D = all pools each seed's episodes of every D.",
            "",
            *_claims_table(result["claims"]),
        ]
    rows = result["rows"]
    for w in result["worlds"]:
        mine = [r for r in rows if r["world"] == w["name"] and r["group"] != "support_sweep"]
        if not mine:
            continue
        sizes = sorted({r["D"] for r in mine})
        lines += ["", f"## {w['label']}", "", *_ROW_HEADER]
        lines += _paper_line(w, sizes)
        lines += [_row_line(r) for r in sorted(mine, key=lambda r: r["D"])]
        pairs = [p for p in result["pairs"] if p["world"] == w["name"]]
        if pairs:
            lines += [
                "",
                f"Differences between its rows (paired; **bold**: the {level} interval "
                "excludes 0 and a paired sign-flip test agrees; no correction for the number "
                "of pairs):",
                "",
                *_pairs_table(pairs),
            ]
    sweep = [r for r in rows if r["group"] == "support_sweep"]
    if sweep:
        reference = next(
            (r["vs_reference"]["reference"] for r in sweep if "vs_reference" in r), "–"
        )
        lines += [
            "",
            "## Support-count axis",
            "",
            "Held-out MAE, complete episodes and tick cost against the support points (all "
            "nodes) of each point (`compare_supports.png`); `default` is the predictor's own "
            "choice. Δ: the point minus the swept predictor's own row of the same world and D "
            f"(`{reference}`), "
            "paired; **bold**: significant.",
            "",
            *_supports_table(sweep),
        ]
    errors = [(r, e) for r in rows for e in r["errors"]]
    if errors:
        lines += ["", "## Refused fits", ""]
        lines += [
            f"- {r['world']}: `{r['name']}` + `{r['sequencer']}`, D = {r['D']}, {e}"
            for r, e in errors
        ]
    lines += [
        "",
        "## Files",
        "",
        "- `compare.json`: every row, pair and claim with its intervals (rates as fractions)",
        "- `compare_c_vs_d.png`: complete episodes against D per row, one panel per world",
        "- `compare_claims.png`: the claims' paired differences with their intervals",
        "- `compare_supports.png`: MAE, complete episodes and tick cost against support points",
        "- `episodes.json`: every closed-loop episode: world, row, seed, D, outcome",
        "- `timings.json`: wall and CPU seconds of every collection and job",
        "- `<world>/seed_<s>/demos.h5`: a simulated world's demonstrations (mask/train, "
        "mask/test; worlds sharing a collection: the first)",
    ]
    return "\n".join(lines) + "\n"
