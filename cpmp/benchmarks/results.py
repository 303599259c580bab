"""The results page and the README's headline table, rendered from the committed benchmark JSON.

Every number of ``docs/results.md`` and of the README's headline table lives in one place: the
JSON a run wrote, committed under ``results/`` (:data:`SECTIONS` names each file, the run that
writes it and the function that renders it). Nothing here measures anything: a section calls
its benchmark's own Markdown renderer (``markdown`` of :mod:`cpmp.benchmarks.synthetic`,
:mod:`cpmp.benchmarks.scale`, :mod:`cpmp.benchmarks.start`; the main job's
:func:`cpmp.experiment.report.render_markdown`) on the committed JSON, under a short text that
says what was run, read from the JSON's own settings, and how to run it again.

``scripts/render_results.py`` (:func:`main`) writes ``docs/results.md`` and the README block
between :data:`BEGIN` and :data:`END`; ``--check`` says whether either is out of date. A
missing or malformed JSON file raises :class:`~cpmp.errors.CpmpFileError` naming the file and
the command that writes it.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from cpmp.errors import ConfigError, CpmpError, CpmpFileError
from cpmp.io import atomic_write_text
from cpmp.records import JsonValue

BEGIN = "<!-- results:begin -->"
"""The line before the README's generated headline table."""
END = "<!-- results:end -->"
"""The line after it."""
RENDER = "python scripts/render_results.py"
"""The command that renders ``docs/results.md`` and the README's table."""


def merge_synthetic(runs: Sequence[tuple[str, Mapping[str, JsonValue]]]) -> dict[str, JsonValue]:
    """One worlds table from several ``bench_synthetic`` runs, later policies replacing earlier.

    A re-run of some policies (after a change that only they see) is merged into the run that
    measured the rest, so the table keeps one row per policy: a later run's policies replace
    the earlier runs' rows of the same policies. The rows are kept as the runs wrote them; the
    summary is :func:`cpmp.benchmarks.synthetic.summarise` of the merged rows (the function the
    bench uses, so ``vs_scripted`` follows the merged scripted rows).

    Args:
        runs: ``(source, result)`` pairs, oldest first: ``source`` names the run (its JSON's
            path), ``result`` is what :func:`~cpmp.benchmarks.synthetic.run_synthetic_benchmark`
            returned. Every run must have the same settings apart from ``policies``.

    Returns:
        The merged result, with ``settings.policies`` the union in first-seen order and
        ``sources``: ``{policy: source}``, the run each policy's rows come from.

    Raises:
        ConfigError: no run, or two runs whose settings differ in more than their policies.
    """
    from cpmp.benchmarks.synthetic import summarise  # lazy: the worlds' and sequencer's imports

    if not runs:
        raise ConfigError("merge_synthetic needs at least one run")
    first_source, first = runs[0]
    base = {k: v for k, v in first["settings"].items() if k != "policies"}
    sources: dict[str, str] = {}
    rows: dict[str, list[dict[str, JsonValue]]] = {}
    for source, result in runs:
        settings = {k: v for k, v in result["settings"].items() if k != "policies"}
        if settings != base:
            raise ConfigError(
                f"{source}: settings differ from {first_source}'s in more than the policies "
                f"({settings} vs {base}); only runs of the same worlds, sizes and seeds merge"
            )
        for policy in result["settings"]["policies"]:
            sources[policy] = source
            rows[policy] = [dict(r) for r in result["rows"] if r["policy"] == policy]
    worlds = list(base["worlds"])
    order = {policy: i for i, policy in enumerate(sources)}
    merged = sorted(
        (r for policy_rows in rows.values() for r in policy_rows),
        key=lambda r: (worlds.index(r["world"]), r["task"], r["D"], r["seed"], order[r["policy"]]),
    )
    families = list(dict.fromkeys(f for _, result in runs for f in result.get("families", [])))
    return {
        "settings": {**first["settings"], "policies": list(sources)},
        "rows": merged,
        "summary": summarise(merged),
        "families": families,
        "sources": sources,
    }


def _demote(markdown: str, levels: int) -> str:
    """``markdown`` with every heading ``levels`` deeper (a report's ``#`` under a section)."""
    return "\n".join(
        "#" * levels + line if line.startswith("#") else line for line in markdown.splitlines()
    )


def _simulator(result: Mapping[str, JsonValue]) -> str:
    from cpmp.experiment.report import render_markdown  # lazy: matplotlib, Hydra

    report = render_markdown(result).split("\n## Files\n")[0]  # the run directory's files
    return _demote(report, 2)


def _synthetic(result: Mapping[str, JsonValue]) -> str:
    from cpmp.benchmarks.synthetic import markdown  # lazy: the worlds' and sequencer's imports

    return markdown(result)


def _scale(result: Mapping[str, JsonValue]) -> str:
    from cpmp.benchmarks.scale import markdown  # lazy: a benchmark module

    return markdown(dict(result))


def _clock(result: Mapping[str, JsonValue]) -> str:
    from cpmp.benchmarks.clock import markdown  # lazy: the worlds' and sequencer's imports

    return markdown(result)


def _sparse(result: Mapping[str, JsonValue]) -> str:
    from cpmp.benchmarks.sparse import markdown  # lazy: the worlds' and sequencer's imports

    return markdown(result)


def _about_sparse(r: Mapping[str, JsonValue]) -> str:
    s, t = r["settings"], r["targets"]
    worlds = [
        f"{w} (its first {s['tasks']} tasks, each with every seed)" if w == "procedural" else w
        for w in s["worlds"]
        if w != "sim"
    ]
    bounds = (
        f"MAE ≤ {t['mae']:g}x, supports ≤ {t['supports']:g}x, tick ≤ {t['tick']:g}x, "
        f"fit ≤ {t['fit']:g}x, C ≥ {t['complete']:g}".replace("-", "−")
    )
    return (
        f"`klr_sparse` (its own defaults) against cpmp's default predictor on every world "
        f"({', '.join(worlds)}): per world, D = {' / '.join(map(str, s['sizes']))} "
        f"and seed ({', '.join(map(str, s['seeds']))}), both fitted on the same "
        f"demonstrations, scored on {s['held_out']} held-out demonstrations (progress MAE) "
        f"and {s['episodes']} held-out closed-loop episodes. Each cell is sparse / default "
        "(pooled over seeds), the last column the difference in complete episodes per "
        f"{s['episodes']} (sparse − default); `!` marks a cell outside issue #23's bound "
        f"({bounds})." + _about_sparse_sim(s) + (f" {r['note']}." if r.get("note") else "")
    )


def _about_sparse_sim(s: Mapping[str, JsonValue]) -> str:
    """The sparse section's sentence on its ``sim`` rows (empty for settings without them)."""
    if "sim" not in s["worlds"]:
        return ""
    return (
        f" The `sim` rows: the simulator, the main job's full-run demonstrations of seeds "
        f"{', '.join(map(str, s['sim_seeds']))} (the balanced D of them), {s['sim_boxes']} "
        "reproduction boxes each."
    )


def _about_clock(r: Mapping[str, JsonValue]) -> str:
    s = r["settings"]
    worlds = list(r["worlds"])
    return (
        f"Every single world ({', '.join(worlds)}) with cpmp's defaults under a robot's clock: "
        f"per world and seed ({', '.join(map(str, s['seeds']))}) a fit on {s['demos']} "
        f"demonstrations and {s['episodes']} held-out episodes under each condition — control "
        "rates from 30 Hz to 1 kHz, ±30 % jitter, 10 % dropped ticks, slow sensors (10, 16.7, "
        "25 Hz), a 1 s clock step, NaN bursts — against the worlds' own 100 Hz loop "
        f"(`{r['reference']}`). Each cell: complete / episodes (all seeds) and the mean "
        "absolute switch-time error; the row below a world is its feature-only scripted "
        "policy on the same episodes. " + _clock_scoring(r) + _clock_target(r, named=False)
    )


def _clock_target(r: Mapping[str, JsonValue], named: bool = True) -> str:
    """Issue #32's target for a clock section, then the run's note.

    ``named``: the target names the reference condition.
    """
    reference = f" (`{r['reference']}`)" if named else ""
    return (
        " Issue #32's target: every condition within 1 episode per 20 of the 100 Hz run"
        f"{reference}." + (f" {r['note']}" if r.get("note") else "")
    )


def _clock_scoring(r: Mapping[str, JsonValue]) -> str:
    """How the clock run counted a complete episode (its ``scoring``; none: the older bench)."""
    if r.get("scoring") == "world":
        return (
            "Episodes are scored as in the worlds table (the goal reached; for the strict "
            "worlds also with the demonstrator's MP sequences); the switch-time error is over "
            "the complete episodes that ran the demonstrator's sequences."
        )
    return (
        "This run predates the worlds' scoring in bench_clock: an episode counted as complete "
        "only if it reached the goal with the demonstrator's MP sequences (it stopped at the "
        "first switch that left them), so these counts can be below the worlds table's. " + _EARLIER
    )


_EARLIER = (
    "It is also a run of the sequencer before its speed envelopes, ambient features and joint "
    "switches by target (session 19): the current defaults are not measured here yet."
)


def _about_clock_sim(r: Mapping[str, JsonValue]) -> str:
    s = r["settings"]
    seeds = ", ".join(map(str, s["sim_seeds"]))
    return (
        f"The simulator with cpmp's defaults under the same conditions: per seed ({seeds}) a "
        f"fit on {s['sim_demos']} simulated demonstrations and {s['sim_boxes']} held-out boxes "
        "under each condition, the simulator stepped at the condition's control rate (jittered "
        "ticks: at 500 Hz, the policy woken on the jittered schedule). Each cell: complete / "
        "episodes (all seeds) and the mean absolute switch-time error."
        + _clock_target(r)
        + ("" if r.get("scoring") == "world" else " " + _EARLIER)
    )


def _about_clock_procedural(r: Mapping[str, JsonValue]) -> str:
    s = r["settings"]
    return (
        f"The procedural family with cpmp's defaults under the same conditions: its first "
        f"{s['tasks']} tasks, per task and seed ({', '.join(map(str, s['seeds']))}) a fit on "
        f"{s['demos']} demonstrations and {s['episodes']} held-out episodes under each "
        "condition, pooled over the tasks; the row below is the family's feature-only scripted "
        "policy on the same episodes. " + _clock_scoring(r) + _clock_target(r)
    )


def _start(result: Mapping[str, JsonValue]) -> str:
    from cpmp.benchmarks.start import markdown  # lazy: scikit-learn, MuJoCo

    return markdown(dict(result))


def _about_simulator(r: Mapping[str, JsonValue]) -> str:
    e = r["experiment"]
    demos = 3 * e["demos_per_strategy"]
    train = 3 * e["train_per_strategy"]
    return (
        f"The main job, `experiment={e['name']}`, with cpmp's defaults in the MuJoCo two-arm "
        f"world: per seed ({', '.join(map(str, e['seeds']))}) {demos} scripted demonstrations "
        f"({train} train / {demos - train} test), a sequencer trained on D = "
        f"{' / '.join(map(str, e['train_sizes']))} of them, and {e['n_boxes']} random boxes "
        "per D run closed loop (W / I / C = wrong start / incomplete / complete, of "
        f"{e['n_boxes']}, mean ± std over the seeds), beside the paper's Table I."
    )


def _sources(r: Mapping[str, JsonValue]) -> str:
    by_source: dict[str, list[str]] = {}
    for policy, source in r.get("sources", {}).items():
        by_source.setdefault(source, []).append(f"`{policy}`")
    if len(by_source) < 2:
        return ""
    parts = [f"{', '.join(p)} from `{s}`" for s, p in by_source.items()]
    return f" Merged from {len(by_source)} runs (`sources` in the JSON): " + "; ".join(parts) + "."


def _about_worlds(r: Mapping[str, JsonValue]) -> str:
    s = r["settings"]
    return (
        f"Every single world ({', '.join(s['worlds'])}) x the policies "
        f"{', '.join(f'`{p}`' for p in s['policies'])}: per world, D = "
        f"{' / '.join(map(str, s['sizes']))} and seed ({', '.join(map(str, s['seeds']))}), "
        f"{s['episodes']} closed-loop episodes in held-out contexts; C / W / I in % of the "
        f"{len(s['seeds']) * s['episodes']} episodes per world, policy and D. `scripted` is the "
        "world's feature-only scripted policy (the yardstick), `paper` the paper's method "
        "(`predictor=paper sequencer=paper`), `bc` the behaviour-cloning switcher, "
        "`goal_nearest` the baseline without learned progress, `defaults` "
        "`ConcurrentSequencer.fit(demos)`." + _sources(r)
    )


def _about_procedural(r: Mapping[str, JsonValue]) -> str:
    s = r["settings"]
    n = s["tasks"] * len(s["family_seeds"]) * s["family_episodes"]
    return (
        f"The procedural family's first {s['tasks']} tasks, seed "
        f"{', '.join(map(str, s['family_seeds']))}, {s['family_episodes']} held-out episodes per "
        f"task and D = {' / '.join(map(str, s['sizes']))}: C / W / I in % of the {n:,} episodes "
        "per D, and C as a share of the scripted policy's." + _sources(r)
    )


def _about_scale(r: Mapping[str, JsonValue]) -> str:
    s = r["settings"]
    machine = r.get("machine", {})
    cores = f" on {machine['cpus']} cores" if "cpus" in machine else ""
    return (
        f"The default fit at {' / '.join(map(str, s['sizes']))} demonstrations of "
        f"{' and '.join(s['worlds'])} (seed {s['seed']}), each size in its own process{cores}: "
        f"fit time, peak resident memory, support points, held-out progress MAE on "
        f"{s['held_out']} demonstrations and C of {s['episodes']} closed-loop episodes; then the "
        "growth exponents of fit time and memory against the training samples. `fit_s` is the "
        "fit alone (Lightning, which the fit imports lazily, is imported first); `machine` in "
        "the JSON has the load averages before and after." + _about_dtype(r) + _about_lerobot(r)
    )


def _about_dtype(r: Mapping[str, JsonValue]) -> str:
    """The scale section's sentence on the predictors' float type (empty if not recorded)."""
    dtype = r["settings"].get("dtype")
    if dtype is None:
        return ""
    used = sorted({str(row["dtype"]) for row in r["rows"] if row.get("dtype")})
    if dtype != "auto":
        return f" Every fit in {dtype} (`--dtype {dtype}`)."
    from cpmp.config import FLOAT32_FROM_SAMPLES

    return (
        " The predictors' float type is cpmp's default `dtype=auto`: float64 below "
        f"{FLOAT32_FROM_SAMPLES:,} training samples, float32 from there on "
        f"({' and '.join(used)} in these rows)."
    )


def _about_lerobot(r: Mapping[str, JsonValue]) -> str:
    """The scale section's sentence on its ``lerobot`` row (empty for a JSON without one)."""
    row = r.get("lerobot")
    if not row:
        return ""
    return (
        f" The last row: {row['D']} demonstrations of {row['world']} written as a LeRobot v3 "
        "dataset (float32 `observation.state`, per-frame label columns), imported by "
        "`cpmp-import` and fitted the same way; the import's time and peak memory (its own "
        "process) follow the table." + (f" It was {row['note']}." if row.get("note") else "")
    )


def _about_start(r: Mapping[str, JsonValue]) -> str:
    return (
        f"The start decision alone, on {r['n_boxes']} fresh boxes per seed "
        f"({', '.join(map(str, r['seeds']))}): wrong starts per 20 boxes (as in Table I), mean "
        "over the seeds, of cpmp's start rules and of classifiers fitted on the same training "
        "boxes (the `oracle size` rows are handed the true box width x depth)."
    )


@dataclass(frozen=True)
class Section:
    """One section of ``docs/results.md``: a committed JSON file and how it is rendered.

    Attributes:
        file: the JSON's name under the results folder.
        title: the section's heading.
        command: the command that writes the JSON.
        keys: top-level keys the JSON must have.
        about: what was run, read from the JSON.
        table: the benchmark's own Markdown renderer.
        copy: what of the command's output to copy to ``file`` ("": it writes ``file``).
    """

    file: str
    title: str
    command: str
    keys: tuple[str, ...]
    about: Callable[[Mapping[str, JsonValue]], str]
    table: Callable[[Mapping[str, JsonValue]], str]
    copy: str = ""

    def rerun(self, path: Path) -> str:
        """How to write ``path`` again and render: the command, a copy if needed, the render."""
        copy = f", copy {self.copy} to {path}" if self.copy else ""
        return f"run `{self.command}`{copy}, then `{RENDER}`"


SINGLE_WORLDS = "two_point relay paced_relay repetition peg slip"
SECTIONS: tuple[Section, ...] = (
    Section(
        "simulator.json",
        "The simulator: Table I",
        "python scripts/experiment.py experiment=full",
        ("experiment", "reproduction", "progress"),
        _about_simulator,
        _simulator,
        "its run directory's report.json",
    ),
    Section(
        "worlds.json",
        "Synthetic worlds",
        f"python scripts/bench_synthetic.py --worlds {SINGLE_WORLDS} --out results/worlds.json",
        ("settings", "summary"),
        _about_worlds,
        _synthetic,
    ),
    Section(
        "procedural.json",
        "Procedural tasks",
        "python scripts/bench_synthetic.py --worlds procedural --out results/procedural.json",
        ("settings", "summary"),
        _about_procedural,
        _synthetic,
    ),
    Section(
        "clock.json",
        "Every world on a robot's clock",
        f"python scripts/bench_clock.py --worlds {SINGLE_WORLDS} --out results/clock.json",
        ("settings", "conditions", "reference", "worlds"),
        _about_clock,
        _clock,
    ),
    Section(
        "clock_procedural.json",
        "The procedural family on a robot's clock",
        "python scripts/bench_clock.py --worlds procedural --seeds 0 --tasks 10 "
        "--out results/clock_procedural.json",
        ("settings", "conditions", "reference", "worlds"),
        _about_clock_procedural,
        _clock,
    ),
    Section(
        "clock_sim.json",
        "The simulator on a robot's clock",
        "python scripts/bench_clock.py --worlds sim --sim-seeds 0 1 2 3 4 --sim-boxes 20 "
        "--out results/clock_sim.json",
        ("settings", "conditions", "reference", "worlds"),
        _about_clock_sim,
        _clock,
    ),
    Section(
        "sparse.json",
        "`klr_sparse` as a drop-in on every world",
        f"python scripts/bench_sparse.py --worlds {SINGLE_WORLDS} procedural sim --sim-seeds 0 1 "
        "--repeats 1 "
        "--out results/sparse.json",
        ("settings", "targets", "rows", "summary"),
        _about_sparse,
        _sparse,
    ),
    Section(
        "start.json",
        "The start decision",
        "python scripts/bench_start.py --out results/start.json",
        ("n_boxes", "seeds", "mean_per_20"),
        _about_start,
        _start,
    ),
    Section(
        "scale.json",
        "From a handful to 768 demonstrations",
        "python scripts/bench_scale.py --out results/scale.json",
        ("settings", "rows", "summary"),
        _about_scale,
        _scale,
    ),
)
"""The sections of ``docs/results.md``, in order."""


def _section(name: str) -> Section:
    return next(s for s in SECTIONS if s.file == name)


def load_result(results_dir: str | Path, name: str) -> dict[str, JsonValue]:
    """The committed JSON ``results_dir/name`` (one of :data:`SECTIONS`' files).

    Raises:
        CpmpFileError: the file is missing, not JSON, or lacks a key its section reads; the
            message names the file and the command that writes it.
    """
    section = _section(name)
    path = Path(results_dir) / name
    rerun = section.rerun(path)
    if not path.is_file():
        raise CpmpFileError(f"{path}: missing; {rerun}")
    try:
        result = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise CpmpFileError(f"{path}: not readable JSON ({err}); {rerun}") from err
    missing = [k for k in section.keys if not isinstance(result, dict) or k not in result]
    if missing:
        raise CpmpFileError(f"{path}: no {', '.join(missing)} (not its benchmark's JSON); {rerun}")
    return result


def _rendered(section: Section, result: Mapping[str, JsonValue], path: Path) -> tuple[str, str]:
    """``(about, table)`` of one section; a key the renderer misses names the file."""
    try:
        return section.about(result), section.table(result)
    except (KeyError, TypeError, ValueError, IndexError, AttributeError) as err:
        raise CpmpFileError(
            f"{path}: malformed ({type(err).__name__}: {err}); {section.rerun(path)}"
        ) from err


def render_results(results_dir: str | Path) -> str:
    """``docs/results.md``: every section of :data:`SECTIONS` from ``results_dir``."""
    lines = [
        "# Results",
        "",
        f"<!-- Generated by `{RENDER}` from results/*.json; edit those or the renderer "
        "(cpmp/benchmarks/results.py), not this page. -->",
        "",
        "Each table is rendered from the JSON its run wrote, committed under `results/`, so "
        "every number lives in one place. To refresh one: run its command, copy the JSON into "
        f"`results/`, then `{RENDER}` (which also updates the README's headline table; "
        "`--check` fails while either is out of date). The history of these numbers, and the "
        "measurements behind design choices, are in [history.md](history.md) and "
        "[benchmarks.md](benchmarks.md).",
    ]
    for section in SECTIONS:
        path = Path(results_dir) / section.file
        about, table = _rendered(section, load_result(results_dir, section.file), path)
        lines += [
            "",
            f"## {section.title}",
            "",
            f"{about} From `results/{section.file}`; to refresh it, "
            f"{section.rerun(Path('results') / section.file)}.",
            "",
            table.rstrip("\n"),
        ]
    return "\n".join(lines) + "\n"


def _pct(cell: Mapping[str, JsonValue] | None) -> str:
    return "–" if cell is None else f"{100 * cell['complete_frac']:.0f}"


def headline(results_dir: str | Path) -> str:
    """The README's one table, per D: the simulator against the paper's Table I, and the worlds.

    The simulator's W / I / C beside the paper's, then cpmp's defaults' complete episodes in %
    on every synthetic world.
    """
    path = Path(results_dir)
    sim = load_result(path, "simulator.json")
    worlds = load_result(path, "worlds.json")
    procedural = load_result(path, "procedural.json")
    try:
        sizes = [str(d) for d in sim["experiment"]["train_sizes"]]
        rep = sim["reproduction"]
        seeds = len(sim["experiment"]["seeds"])
        lines = [
            "| | " + " | ".join(f"D = {d}" for d in sizes) + " |",
            "| --- |" + " --- |" * len(sizes),
            "| simulator, the paper's Table I: W / I / C of 20 | "
            + " | ".join(
                f"{rep[d]['paper']['W']} / {rep[d]['paper']['I']} / {rep[d]['paper']['C']}"
                for d in sizes
            )
            + " |",
            f"| simulator, cpmp's defaults: W / I / C of {sim['experiment']['n_boxes']}, "
            f"mean of {seeds} seeds | "
            + " | ".join(
                f"{rep[d]['W']:.1f} / {rep[d]['I']:.1f} / **{rep[d]['C']:.1f}**" for d in sizes
            )
            + " |",
        ]
        for result in (worlds, procedural):
            for world, policies in result["summary"].items():
                defaults = policies["defaults"]
                lines.append(
                    f"| {world}, cpmp's defaults: C % | "
                    + " | ".join(_pct(defaults.get(d)) for d in sizes)
                    + " |"
                )
    except (KeyError, TypeError, ValueError) as err:
        raise CpmpFileError(
            f"{path}: a results file lacks what the headline reads ({type(err).__name__}: "
            f"{err}); re-run its command (docs/results.md) and `{RENDER}`"
        ) from err
    s, p = worlds["settings"], procedural["settings"]
    note = (
        f"Synthetic worlds: {len(s['seeds'])} seeds x {s['episodes']} held-out episodes per D; "
        f"procedural: {p['tasks']} generated tasks x {p['family_episodes']} episodes. Every "
        "table, with the baselines: [docs/results.md](docs/results.md)."
    )
    return "\n".join(lines) + "\n\n" + note + "\n"


def replace_block(text: str, block: str, where: str = "README.md") -> str:
    """``text`` with the lines between :data:`BEGIN` and :data:`END` replaced by ``block``.

    Raises:
        CpmpFileError: ``text`` lacks the marker pair (``where`` names the file).
    """
    start, stop = text.find(BEGIN), text.find(END)
    if start < 0 or stop < start:
        raise CpmpFileError(f"{where}: no `{BEGIN}` ... `{END}` pair to put the table between")
    head = text[: start + len(BEGIN)]
    return head + "\n" + block.rstrip("\n") + "\n" + text[stop:]


def render_files(
    results_dir: str | Path, page: str | Path, readme: str | Path, check: bool = False
) -> list[Path]:
    """Render ``page`` (docs/results.md) and ``readme``'s headline block from ``results_dir``.

    Returns:
        The files that were out of date (written, unless ``check``).
    """
    page, readme = Path(page), Path(readme)
    try:
        old_readme = readme.read_text(encoding="utf-8")
    except OSError as err:
        raise CpmpFileError(f"{readme}: cannot read it ({err})") from err
    wanted = {
        page: render_results(results_dir),
        readme: replace_block(old_readme, headline(results_dir), str(readme)),
    }
    stale = []
    for path, text in wanted.items():
        current = path.read_text(encoding="utf-8") if path.is_file() else None
        if current != text:
            stale.append(path)
            if not check:
                atomic_write_text(path, text)
    return stale


def main(argv: list[str] | None = None) -> int:
    """``scripts/render_results.py``: write docs/results.md and the README's headline table.

    Returns:
        0; 1 with ``--check`` when a file is out of date; 2 after a
        :class:`~cpmp.errors.CpmpError` (a missing or malformed results file).
    """
    parser = argparse.ArgumentParser(
        description=(
            "Render docs/results.md and the README's headline table from the committed "
            "benchmark JSON in results/. Run from the repository root."
        )
    )
    parser.add_argument("--results", default="results", help="the JSON folder (results)")
    parser.add_argument("--page", default="docs/results.md", help="the page (docs/results.md)")
    parser.add_argument("--readme", default="README.md", help="the README (README.md)")
    parser.add_argument("--check", action="store_true", help="exit 1 if a file is out of date")
    args = parser.parse_args(argv)
    try:
        stale = render_files(args.results, args.page, args.readme, check=args.check)
    except CpmpError as err:
        print(f"render_results: error: {err}", file=sys.stderr)
        return 2
    for path in stale:
        print(f"{path}: {'out of date' if args.check else 'written'}")
    return 1 if args.check and stale else 0
