"""The worlds table (``scripts/bench_synthetic.py``): every registered world x every policy.

For every world of :mod:`cpmp.worlds.registry` (a family's first ``tasks`` members), training
size D and seed, each named policy of :data:`POLICIES` is fitted on D demonstrations of seed
``s`` and run closed-loop on ``episodes`` contexts drawn from ``HELD_OUT_SEED + s``
(:func:`cpmp.worlds.protocol.evaluate`): complete / wrong start / incomplete. The world's own
feature-only scripted policy runs beside the learned ones, so a low score can be told apart
from an impossible task; a family's completions are also given as a fraction of its scripted
policy's. Written as JSON (atomically) with a Markdown table; nothing here asserts a number.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass

from cpmp.benchmarks.cli import given_options, run_settings_benchmark
from cpmp.data import Demonstration
from cpmp.errors import ConfigError
from cpmp.io import to_builtin
from cpmp.records import JsonValue, Policy
from cpmp.sequencer.sequencer import PAPER_OPTIONS, ConcurrentSequencer
from cpmp.worlds.outcomes import OUTCOMES
from cpmp.worlds.protocol import World, evaluate
from cpmp.worlds.registry import entry, members, world_names

HELD_OUT_SEED = 1000
"""Closed-loop contexts of seed ``s`` are drawn with ``HELD_OUT_SEED + s``."""

Make = Callable[[World, Sequence[Demonstration], int], Policy]
"""``make(world, demos, seed)``: a policy fitted on ``demos`` (or the world's own)."""


def _sequencer(predictor: str = "klr", **options: str | bool) -> Make:
    """A :class:`ConcurrentSequencer` fitted with ``predictor`` and ``options``."""

    def make(world: World, demos: Sequence[Demonstration], seed: int) -> Policy:
        return ConcurrentSequencer.fit(list(demos), predictor, seed=seed, logger=None, **options)

    return make


def _scripted(world: World, demos: Sequence[Demonstration], seed: int) -> Policy:
    """The world's feature-only scripted policy (fits nothing)."""
    return world.scripted_policy()


def _goal_nearest(world: World, demos: Sequence[Demonstration], seed: int) -> Policy:
    from cpmp.baselines import GoalNearestSequencer  # lazy: the baselines' own imports

    return GoalNearestSequencer.fit(list(demos), seed=seed)


def _bc(world: World, demos: Sequence[Demonstration], seed: int) -> Policy:
    from cpmp.baselines.bc import BCSequencer  # lazy: the baselines' own imports

    return BCSequencer.fit(list(demos), seed=seed)


POLICIES: dict[str, Make] = {
    "scripted": _scripted,
    "paper": _sequencer("klr", **PAPER_OPTIONS),
    "bc": _bc,
    "goal_nearest": _goal_nearest,
    "defaults": _sequencer(),
    "klr_sparse": _sequencer("klr_sparse"),
    "coupling=none": _sequencer(coupling="none"),
    "switch_rule=paper": _sequencer(switch_rule="paper"),
    "recovery=false": _sequencer(recovery=False),
}
"""The policies by name: the world's scripted policy, the paper's method
(``predictor=paper sequencer=paper``), the behaviour-cloning switcher (``sequencer=bc``), the
goal-nearest baseline, cpmp's defaults (``ConcurrentSequencer.fit(demos)``), ``klr_sparse``
with the default rule, and single options of the defaults switched off."""
TABLE = ("scripted", "paper", "bc", "goal_nearest", "defaults", "klr_sparse")
"""The policies of the worlds table in docs/results.md (the default)."""


@dataclass(frozen=True)
class SyntheticSettings:
    """What :func:`run_synthetic_benchmark` measures.

    Attributes:
        worlds: registered worlds (default: all).
        policies: names of :data:`POLICIES`.
        sizes: training sizes D.
        seeds: seeds of a single world (demonstrations, fit, held-out contexts).
        episodes: closed-loop episodes per world, D and seed.
        tasks: members of a family world, each run at ``family_seeds``.
        family_seeds: seeds of each family member.
        family_episodes: episodes per family member, D and seed.
    """

    worlds: tuple[str, ...] = world_names()
    policies: tuple[str, ...] = TABLE
    sizes: tuple[int, ...] = (3, 6, 9)
    seeds: tuple[int, ...] = (0, 1, 2)
    episodes: int = 20
    tasks: int = 100
    family_seeds: tuple[int, ...] = (0,)
    family_episodes: int = 10

    def __post_init__(self) -> None:
        for name in self.worlds:
            entry(name)  # an unknown world raises, naming the registered ones
        unknown = sorted(set(self.policies) - set(POLICIES))
        if unknown:
            raise ConfigError(f"unknown policies {unknown}; known: {', '.join(POLICIES)}")
        counts = {"episodes": self.episodes, "tasks": self.tasks}
        counts |= {"family_episodes": self.family_episodes}
        counts |= {f"sizes[{i}]": d for i, d in enumerate(self.sizes)}
        for name, value in counts.items():
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ConfigError(f"{name} must be a positive integer, got {value!r}")
        if not self.sizes or not self.seeds or not self.family_seeds:
            raise ConfigError("sizes, seeds and family_seeds must each name at least one")

    @classmethod
    def quick(cls, **options: object) -> SyntheticSettings:
        """Small sizes for a test: D = 3, seed 0, 2 episodes, 2 family members.

        Args:
            **options: fields of :class:`SyntheticSettings` over those (passed through).
        """
        quick = {"sizes": (3,), "seeds": (0,), "episodes": 2, "tasks": 2, "family_episodes": 2}
        return cls(**{**quick, **options})


def world_rows(
    name: str, settings: SyntheticSettings, log: Callable[[str], None] | None = None
) -> list[dict[str, str | int]]:
    """One row per (member, D, seed, policy) of the world ``name``: its outcome counts.

    A row: ``world``, ``task`` (the member), ``D``, ``seed``, ``policy``, the count of each
    outcome (:data:`~cpmp.worlds.outcomes.OUTCOMES`) and ``n_episodes``.
    """
    family = entry(name).family
    seeds = settings.family_seeds if family else settings.seeds
    n = settings.family_episodes if family else settings.episodes
    rows: list[dict[str, str | int]] = []
    for task, world in enumerate(members(name, settings.tasks)):
        for d in settings.sizes:
            for seed in seeds:
                demos = world.demonstrations(d, seed)
                for policy in settings.policies:
                    made = POLICIES[policy](world, demos, seed)
                    counts = evaluate(world, made, n, HELD_OUT_SEED + seed).counts
                    row: dict[str, str | int] = {
                        "world": name,
                        "task": task,
                        "D": d,
                        "seed": seed,
                        "policy": policy,
                    }
                    rows.append({**row, **counts, "n_episodes": n})
                    if log is not None:
                        log(f"{name}#{task} D{d} seed {seed} {policy}: {counts['complete']}/{n}")
    return rows


def summarise(
    rows: Sequence[Mapping[str, str | int]],
) -> dict[str, dict[str, dict[str, dict[str, float]]]]:
    """Per world, policy and D: the outcomes as fractions of the episodes, pooled.

    Args:
        rows: :func:`world_rows`' rows (or read back from the JSON).

    Returns:
        world -> policy -> D (a string) -> the summed counts of each outcome and
        ``n_episodes``, each outcome's ``<outcome>_frac`` of the episodes and, where the
        scripted policy ran and completed any, ``vs_scripted``: complete episodes as a
        fraction of the scripted policy's.
    """
    out: dict[str, dict[str, dict[str, dict[str, float]]]] = {}
    for row in rows:
        key = (str(row["world"]), str(row["policy"]), str(row["D"]))
        cell = out.setdefault(key[0], {}).setdefault(key[1], {}).setdefault(key[2], {})
        for k in (*OUTCOMES, "n_episodes"):
            cell[k] = cell.get(k, 0) + int(row[k])
    for world in out.values():
        for by_d in world.values():
            for d, cell in by_d.items():
                n = cell["n_episodes"]
                for k in OUTCOMES:
                    cell[f"{k}_frac"] = cell[k] / n
                scripted = world.get("scripted", {}).get(d)
                if scripted is not None and scripted["complete"]:
                    cell["vs_scripted"] = cell["complete"] / scripted["complete"]
    return out


def run_synthetic_benchmark(
    settings: SyntheticSettings, log: Callable[[str], None] | None = None
) -> dict[str, JsonValue]:
    """The worlds table of ``settings`` (JSON-ready; the same settings give the same dict).

    Returns:
        ``{"settings", "rows": [...], "summary": {world: {policy: {D: counts and fractions}}},
        "families": [names]}``.
    """
    rows = [row for name in settings.worlds for row in world_rows(name, settings, log)]
    families = [name for name in settings.worlds if entry(name).family]
    return to_builtin(
        {
            "settings": asdict(settings),
            "rows": rows,
            "summary": summarise(rows),
            "families": families,
        }
    )


def markdown(result: Mapping[str, JsonValue]) -> str:
    """The worlds table: one row per world and policy, ``C / W / I`` in % per D.

    A family's rows add its completions as a fraction of the scripted policy's.
    """
    sizes = [str(d) for d in result["settings"]["sizes"]]
    head = "| world | policy | " + " | ".join(f"D={d}: C / W / I %" for d in sizes) + " |"
    lines = [head, "|---|---|" + "---|" * len(sizes)]
    for world, policies in result["summary"].items():
        family = world in result.get("families", ())
        for policy, by_d in policies.items():
            cells = []
            for d in sizes:
                c = by_d.get(d)
                if c is None:
                    cells.append("–")
                    continue
                text = " / ".join(f"{100 * c[f'{k}_frac']:.0f}" for k in OUTCOMES)
                if family and "vs_scripted" in c and policy != "scripted":
                    text += f" ({100 * c['vs_scripted']:.0f} % of scripted)"
                cells.append(text)
            lines.append(f"| {world} | {policy} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    """``scripts/bench_synthetic.py``: the worlds table; writes JSON, prints Markdown.

    Returns:
        0, or 2 after a :class:`~cpmp.errors.CpmpError` (a bad option).
    """
    parser = argparse.ArgumentParser(
        description=(
            "Every registered world x the scripted policy, the paper's method, the BC "
            "switcher, goal_nearest, cpmp's defaults and klr_sparse, at each training size: "
            "complete / wrong start / incomplete. Writes JSON, prints a Markdown table."
        )
    )
    parser.add_argument("--out", default="logs/bench_synthetic.json", help="the JSON file")
    parser.add_argument("--quick", action="store_true", help="SyntheticSettings.quick (a test)")
    parser.add_argument("--worlds", nargs="+", choices=world_names(), help="default: all")
    parser.add_argument("--policies", nargs="+", choices=list(POLICIES), help=f"{TABLE}")
    parser.add_argument("--sizes", type=int, nargs="+", help="training sizes D (3 6 9)")
    parser.add_argument("--seeds", type=int, nargs="+", help="seeds of a single world (0 1 2)")
    parser.add_argument("--episodes", type=int, help="episodes per world, D and seed (20)")
    parser.add_argument("--tasks", type=int, help="members of a family world (100)")
    parser.add_argument("--family-seeds", type=int, nargs="+", help="seeds per member (0)")
    parser.add_argument("--family-episodes", type=int, help="episodes per member (10)")
    args = parser.parse_args(argv)
    names = ("worlds", "policies", "sizes", "seeds", "episodes", "tasks", "family_seeds")
    options = given_options(args, (*names, "family_episodes"))
    return run_settings_benchmark(
        "bench_synthetic", args, SyntheticSettings, options, run_synthetic_benchmark, markdown
    )
