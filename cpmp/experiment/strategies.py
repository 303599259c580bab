"""The task's strategies: which one a demonstration used, train/test splits and training
subsets balanced over them, the initial MPs of each (its signature), which one a sequencer
chose at the start of an episode, and the strategy map (Fig. 7).
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from cpmp.errors import DataError
from cpmp.experiment.console import progress_bar

if TYPE_CHECKING:
    from cpmp.data.demonstration import Demonstration
    from cpmp.sequencer.sequencer import ConcurrentSequencer
    from cpmp.sim import TaskConfig

OTHER = "other"
"""Strategy label of an initial MP set that matches no demonstrated strategy."""


def strategy_of(demo: Demonstration) -> str:
    """The strategy a demonstration used (``metadata["strategy"]``)."""
    strategy = (demo.metadata or {}).get("strategy")
    if not strategy:
        raise DataError(f"{demo.name}: metadata has no 'strategy'; cannot balance by strategy")
    return str(strategy)


def by_strategy(demos: Sequence[Demonstration]) -> dict[str, list[Demonstration]]:
    """Demonstrations grouped by strategy, each group in the given order."""
    groups: dict[str, list[Demonstration]] = defaultdict(list)
    for demo in demos:
        groups[strategy_of(demo)].append(demo)
    return dict(sorted(groups.items()))


def split_by_strategy(
    demos: Sequence[Demonstration], train_per_strategy: int
) -> tuple[list[Demonstration], list[Demonstration]]:
    """First ``train_per_strategy`` demos of each strategy train, the rest test."""
    train, test = [], []
    for strategy, group in by_strategy(demos).items():
        if len(group) <= train_per_strategy:
            raise DataError(
                f"strategy {strategy!r} has {len(group)} demos; need more than "
                f"{train_per_strategy} to keep some for testing"
            )
        train += group[:train_per_strategy]
        test += group[train_per_strategy:]
    return train, test


def balanced_subset(demos: Sequence[Demonstration], size: int) -> list[Demonstration]:
    """``size`` demos taken round-robin over strategies (so 3 = one per strategy)."""
    groups = list(by_strategy(demos).values())
    out: list[Demonstration] = []
    k = 0
    while len(out) < size:
        if all(k >= len(g) for g in groups):
            raise DataError(f"asked for {size} training demos, only {len(out)} available")
        out += [g[k] for g in groups if k < len(g)][: size - len(out)]
        k += 1
    return out


def strategy_signatures(demos: Sequence[Demonstration]) -> dict[str, dict[str, str]]:
    """Initial MP per variable of each demonstrated strategy."""
    out: dict[str, dict[str, str]] = {}
    for demo in demos:
        out.setdefault(strategy_of(demo), {v: str(demo.labels[v][0]) for v in demo.variables})
    return out


def classify_start(initial: Mapping[str, str], signatures: Mapping[str, Mapping[str, str]]) -> str:
    """The strategy whose initial MPs equal ``initial``, else :data:`OTHER`."""
    for strategy, sig in signatures.items():
        if all(initial.get(v) == mp for v, mp in sig.items()):
            return strategy
    return OTHER


def strategy_map(
    seq: ConcurrentSequencer,
    task: TaskConfig,
    signatures: Mapping[str, Mapping[str, str]],
    grid: Sequence[int],
) -> dict[str, Any]:
    """Fig. 7: the initial strategy chosen over a width x depth grid against the correct one."""
    from cpmp.sim import Box, Simulation, correct_strategy

    widths = np.linspace(*task.width_range, grid[0])
    depths = np.linspace(*task.depth_range, grid[1])
    chosen = np.empty((len(depths), len(widths)), dtype=object)
    correct = np.empty_like(chosen)
    for j, depth in enumerate(progress_bar(list(depths), "strategy map rows")):
        for i, width in enumerate(widths):
            box = Box(float(width), float(depth), task.box_height)
            x0 = Simulation(task, box).features()
            chosen[j, i] = classify_start(seq.reset(0.0, x0), signatures)
            correct[j, i] = correct_strategy(box, task)
    return {
        "widths": widths,
        "depths": depths,
        "chosen": chosen.astype(str),
        "correct": correct.astype(str),
        "accuracy": float(np.mean(chosen == correct)),
    }
