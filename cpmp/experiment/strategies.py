"""The task's strategies: which one a demonstration used, splits, and the strategy map.

Train/test splits and training subsets are balanced over the strategies; each strategy's
initial MPs are its signature, which tells which strategy a sequencer chose at the start of an
episode; the strategy map (Fig. 7) shows that choice over a grid of boxes.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from cpmp.config.task import TaskConfig
from cpmp.data.demonstration import Demonstration
from cpmp.errors import DataError
from cpmp.experiment.console import progress_bar
from cpmp.sequencer.sequencer import ConcurrentSequencer
from cpmp.sim import Box, Simulation, correct_strategy

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
    """First ``train_per_strategy`` demos of each strategy train, the rest test.

    Returns:
        ``(train, test)``.

    Raises:
        DataError: a strategy has no more than ``train_per_strategy`` demos.
    """
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


@dataclass
class StrategyMap:
    """The initial strategy chosen over a width x depth grid of boxes (Fig. 7).

    Attributes:
        widths: box widths [m], shape (n_widths,).
        depths: box depths [m], shape (n_depths,).
        chosen: the strategy the sequencer chose, shape (n_depths, n_widths).
        correct: the correct strategy of each box, shape (n_depths, n_widths).
        accuracy: the fraction of cells where the two agree.
    """

    widths: np.ndarray
    depths: np.ndarray
    chosen: np.ndarray
    correct: np.ndarray
    accuracy: float


def strategy_map(
    seq: ConcurrentSequencer,
    task: TaskConfig,
    signatures: Mapping[str, Mapping[str, str]],
    grid: Sequence[int],
) -> StrategyMap:
    """Fig. 7: the initial strategy chosen over a width x depth grid against the correct one.

    Args:
        seq: the fitted sequencer (``reset`` on each box's first features).
        task: the task (box size ranges and height).
        signatures: initial MP per variable of each strategy (:func:`strategy_signatures`).
        grid: ``(n_widths, n_depths)``.
    """
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
    return StrategyMap(
        widths=widths,
        depths=depths,
        chosen=chosen.astype(str),
        correct=correct.astype(str),
        accuracy=float(np.mean(chosen == correct)),
    )
