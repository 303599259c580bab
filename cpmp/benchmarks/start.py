"""How good can the start decision be? Wrong starts of cpmp's start rules against classifiers.

The initial MPs are chosen from the first feature vector alone, so the start decision can be
scored on far more boxes than a rollout can afford. For each seed this records the main job's
training demonstrations, draws ``n_boxes`` fresh boxes, and counts wrong starts of

- cpmp's start rules (the defaults, the paper's, ``joint`` on the nodes' own progress
  predictors), and
- classifiers fitted on the same training boxes: the nearest training box in the sequencer's
  scaled features, and classifiers handed the *true* box width x depth (an oracle of what the
  features encode): nearest neighbour, multinomial logistic regression, an RBF SVM and a decision
  tree (axis-aligned cuts, the shape of the demonstrator's strategy regions).

Wrong starts are reported per 20 boxes, like Table I.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import NamedTuple

import numpy as np
from sklearn.base import ClassifierMixin
from sklearn.linear_model import LogisticRegression
from sklearn.neighbors import KNeighborsClassifier
from sklearn.svm import SVC
from sklearn.tree import DecisionTreeClassifier

from cpmp.config.task import TaskConfig
from cpmp.data.demonstration import Demonstration
from cpmp.experiment.strategies import (
    balanced_subset,
    classify_start,
    split_by_strategy,
    strategy_of,
    strategy_signatures,
)
from cpmp.records import JsonValue
from cpmp.sequencer.sequencer import PAPER_OPTIONS, ConcurrentSequencer
from cpmp.sim import record_demonstration, sample_box
from cpmp.sim.collect import sample_boxes
from cpmp.sim.scene import Box, correct_strategy
from cpmp.sim.simulation import Simulation

SEQUENCER_RULES: dict[str, dict[str, str | bool]] = {
    "cpmp defaults": {},
    "paper (PAPER_OPTIONS)": dict(PAPER_OPTIONS),
    "joint, shared kernel": {"start_rule": "joint"},
}
"""cpmp start rules scored, as fit options of :meth:`ConcurrentSequencer.fit`. ``joint,
shared kernel`` reads the nodes' own progress predictors (the name of results/start.json's
row, from when ``start_kernel`` chose between them and isotropic start heads)."""


class StartRow(NamedTuple):
    """The wrong starts of one rule or classifier, for one seed and training size.

    Attributes:
        seed: the seed of the demonstrations, the scored boxes and the fits.
        D: training demonstrations.
        rule: the start rule or classifier (a key of :data:`SEQUENCER_RULES`, or a
            classifier's name).
        wrong: wrong starts on the scored boxes.
        per_20: wrong starts per 20 boxes (as Table I counts them).
    """

    seed: int
    D: int
    rule: str
    wrong: int
    per_20: float


def _classifiers(seed: int) -> dict[str, Callable[[], ClassifierMixin]]:
    return {
        "oracle size: nearest training box": lambda: KNeighborsClassifier(n_neighbors=1),
        "oracle size: logistic regression": lambda: LogisticRegression(C=1e4, max_iter=5000),
        "oracle size: RBF SVM": lambda: SVC(kernel="rbf", C=1e4, gamma=2.0),
        "oracle size: decision tree": lambda: DecisionTreeClassifier(random_state=seed),
    }


def _box_size(demo_or_box: Demonstration | Box, scale: tuple[float, float]) -> list[float]:
    if isinstance(demo_or_box, Demonstration):
        w, d = demo_or_box.metadata["box_width"], demo_or_box.metadata["box_depth"]
    else:
        w, d = demo_or_box.width, demo_or_box.depth
    return [w / scale[0], d / scale[1]]


def _first_features(sim: Simulation) -> np.ndarray:
    sim.reset()
    return sim.features()


def wrong_starts(
    train: Sequence[Demonstration],
    first_features: np.ndarray,
    boxes: Sequence[Box],
    correct: Sequence[str],
    seed: int,
    size_scale: tuple[float, float] = (1.0, 1.0),
) -> dict[str, int]:
    """Wrong starts of every rule and classifier on ``boxes`` for one training set.

    Args:
        train: the training demonstrations (their metadata holds ``box_width``/``box_depth``).
        first_features: ``(n, d)`` feature vector at t = 0 of each scored box.
        boxes: the ``n`` scored boxes (``.width``, ``.depth`` [m]).
        correct: the demonstrator's strategy for each box.
        seed: seed of the fits.
        size_scale: widths and depths are divided by these before the oracle classifiers
            (the span of each range, so both dimensions count alike) [m].
    Returns: ``{rule name: number of wrong starts}``.
    """
    x0 = np.asarray(first_features, dtype=np.float64)
    truth = np.asarray(correct)
    signatures = strategy_signatures(train)
    out: dict[str, int] = {}
    fitted = {
        name: ConcurrentSequencer.fit(train, seed=seed, logger=None, **options)
        for name, options in SEQUENCER_RULES.items()
    }
    for name, seq in fitted.items():
        chosen = [classify_start(seq.reset(0.0, x), signatures) for x in x0]
        out[name] = int(np.sum(np.asarray(chosen) != truth))
    seq = fitted["cpmp defaults"]
    labels = np.asarray([strategy_of(d) for d in train])
    scaled = seq.predictor.scaler.transform
    z_train = scaled(np.stack([d.features[0] for d in train]))
    nearest = np.argmin(((scaled(x0)[:, None] - z_train[None]) ** 2).sum(-1), axis=1)
    out["nearest training box, scaled features"] = int(np.sum(labels[nearest] != truth))
    size_train = np.asarray([_box_size(d, size_scale) for d in train])
    size_test = np.asarray([_box_size(b, size_scale) for b in boxes])
    for name, make in _classifiers(seed).items():
        predicted = make().fit(size_train, labels).predict(size_test)
        out[name] = int(np.sum(predicted != truth))
    return out


def analyse_starts(
    seeds: Sequence[int],
    sizes: Sequence[int],
    n_boxes: int,
    task: TaskConfig | None = None,
    demos_per_strategy: int = 5,
    train_per_strategy: int = 3,
) -> dict[str, JsonValue]:
    """Record each seed's demonstrations like the main job and score the start decision.

    Returns ``{"n_boxes": n_boxes, "seeds": [...], "rows": [{"seed", "D", "rule", "wrong",
    "per_20"}...], "mean_per_20": {D: {rule: W per 20 averaged over seeds}}}`` (the rows are
    :class:`StartRow` as dicts; ``D`` as a string key, as JSON writes it).
    """
    task = task if task is not None else TaskConfig()
    scale = (
        task.width_range[1] - task.width_range[0],
        task.depth_range[1] - task.depth_range[0],
    )
    rows: list[StartRow] = []
    for seed in seeds:
        rng = np.random.default_rng(seed)
        demo_boxes = sample_boxes(rng, task, 3 * demos_per_strategy, balanced=True)
        demos = [
            record_demonstration(b, task, name=f"demo_{i:03d}") for i, b in enumerate(demo_boxes)
        ]
        train, _ = split_by_strategy(demos, train_per_strategy)
        box_rng = np.random.default_rng(seed + 5000)
        boxes = [sample_box(box_rng, task) for _ in range(n_boxes)]
        x0 = np.stack([_first_features(Simulation(task, b)) for b in boxes])
        correct = [correct_strategy(b, task) for b in boxes]
        for d in sizes:
            counts = wrong_starts(balanced_subset(train, d), x0, boxes, correct, seed, scale)
            for rule, wrong in counts.items():
                rows.append(StartRow(seed, d, rule, wrong, 20.0 * wrong / n_boxes))
    mean: dict[str, dict[str, float]] = {}
    for d in sizes:
        for rule in dict.fromkeys(r.rule for r in rows):
            values = [r.per_20 for r in rows if r.D == d and r.rule == rule]
            mean.setdefault(str(d), {})[rule] = round(float(np.mean(values)), 2)
    return {
        "n_boxes": n_boxes,
        "seeds": list(seeds),
        "rows": [r._asdict() for r in rows],
        "mean_per_20": mean,
    }


def markdown(result: Mapping[str, JsonValue]) -> str:
    """The ``mean_per_20`` table as Markdown (rules as rows, D as columns)."""
    sizes = list(result["mean_per_20"])
    rules = list(next(iter(result["mean_per_20"].values())))
    lines = [
        "| start rule | " + " | ".join(f"D = {d}" for d in sizes) + " |",
        "| --- |" + " --- |" * len(sizes),
    ]
    for rule in rules:
        cells = " | ".join(f"{result['mean_per_20'][d][rule]:.1f}" for d in sizes)
        lines.append(f"| {rule} | {cells} |")
    return "\n".join(lines) + "\n"
