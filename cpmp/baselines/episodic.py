"""What the sequencing baselines share: batches, replay and their offline progress.

:class:`EpisodicBaseline` is the part of :class:`~cpmp.baselines.GoalNearestSequencer` and
:class:`~cpmp.baselines.bc.BCSequencer` that does not depend on how they switch: ``N``
independent episodes (:meth:`EpisodicBaseline.batched`), an open-loop replay, and the
nearest-neighbour progress (:class:`~cpmp.baselines.NearestProgress`) that offline
evaluation reads and the switching never uses.
"""

from __future__ import annotations

import copy
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
import torch

from cpmp.baselines.batch import GoalNearestBatch
from cpmp.baselines.nearest_progress import NearestProgress
from cpmp.data import Demonstration
from cpmp.graph import SequenceGraph, build_graphs
from cpmp.progress import expected_progress
from cpmp.records import ReplayResult, TransitionEvent
from cpmp.sequencer import EpisodeBatch, checked_demonstrations, checked_features


class BaselineData(NamedTuple):
    """What a baseline's fit starts from (:func:`baseline_data`).

    Attributes:
        demos: the checked demonstrations.
        feature_names: their ``d`` feature names.
        graphs: variable -> sequence graph.
        node_keys: (variable, MP) of every node, in graph order.
        predictor: the nearest-neighbour progress, fitted (scaler, samples, eq. 1 targets).
        scaled: (variable, MP) -> the scaled features ``(n_a, d)`` of each of the node's
            activations, in the graph's order.
        features: every demonstration's features stacked ``(N, d)`` (raw).
    """

    demos: list[Demonstration]
    feature_names: list[str]
    graphs: dict[str, SequenceGraph]
    node_keys: list[tuple[str, str]]
    predictor: NearestProgress
    scaled: dict[tuple[str, str], list[np.ndarray]]
    features: np.ndarray


def baseline_data(
    demos: Sequence[Demonstration],
    variables: Sequence[str] | None,
    feature_scaling: str,
    where: str,
) -> BaselineData:
    """The graphs, the scaled activations and the fitted nearest-neighbour progress.

    Args:
        demos: labelled demonstrations sharing feature names and control variables.
        variables: the control variables to sequence (``None``: all).
        feature_scaling: the scaling of the features (as the progress predictors scale them).
        where: the fit's name, for error messages.

    Returns:
        The data every baseline's fit starts from.
    """
    demos, feature_names = checked_demonstrations(demos, where)
    graphs = build_graphs(demos, variables)
    all_x = np.concatenate([d.features for d in demos], axis=0)
    node_keys = [(v, mp) for v in sorted(graphs) for mp in graphs[v].ordered_nodes()]
    n_samples = sum(a.n_samples for v, mp in node_keys for a in graphs[v].activations[mp])
    predictor = NearestProgress(node_keys, len(feature_names), n_samples)
    predictor.scaler.fit(all_x, feature_scaling)
    scaled: dict[tuple[str, str], list[np.ndarray]] = {}
    samples, targets, node = [], [], []
    for k, (v, mp) in enumerate(node_keys):
        scaled[(v, mp)] = []
        for a in graphs[v].activations[mp]:
            z = predictor.scaler.transform(a.features)
            scaled[(v, mp)].append(z)
            samples.append(z)
            targets.append(expected_progress(z, a.time))
            node.append(np.full(len(z), k))
    predictor.samples.copy_(torch.from_numpy(np.concatenate(samples)))
    predictor.targets.copy_(torch.from_numpy(np.concatenate(targets)))
    predictor.node.copy_(torch.from_numpy(np.concatenate(node)))
    return BaselineData(list(demos), feature_names, graphs, node_keys, predictor, scaled, all_x)


class EpisodicBaseline:
    """The shared surface of a baseline that decides one episode on its own.

    A subclass has ``predictor`` (its :class:`NearestProgress`), ``feature_names``, ``events``
    and ``_new_episode()``, ``reset(t, x)`` and ``step(t, x)``.
    """

    predictor: NearestProgress
    feature_names: list[str]
    events: list[TransitionEvent]

    def _new_episode(self) -> None:
        """Forget the current episode (a fresh state; the fitted data stays shared)."""
        raise NotImplementedError

    def reset(self, t: float, x: np.ndarray) -> dict[str, str]:
        """Start an episode at time ``t`` [s] with features ``x (d,)``; the initial MPs."""
        raise NotImplementedError

    def step(self, t: float, x: np.ndarray) -> dict[str, str]:
        """One tick at time ``t`` [s] with features ``x (d,)``; the active MPs after it."""
        raise NotImplementedError

    def batched(self, n: int) -> GoalNearestBatch:
        """``n`` independent episodes of this baseline, stepped together.

        A :class:`~cpmp.baselines.GoalNearestBatch` (it steps any single-episode policy), the
        batched policy :func:`cpmp.sim.run_episodes` drives; each episode is a copy of this
        baseline sharing its fitted data.
        """
        episodes: list[EpisodicBaseline] = []
        for _ in range(EpisodeBatch.checked_count(n)):
            episode = copy.copy(self)
            episode._new_episode()
            episodes.append(episode)
        return GoalNearestBatch(episodes)

    @property
    def node_keys(self) -> list[tuple[str, str]]:
        """(variable, MP) of every node, in the order of :meth:`progress`'s columns."""
        return list(self.predictor.node_keys)

    def progress(self, x: np.ndarray | torch.Tensor) -> np.ndarray:
        """Nearest-neighbour progress ``(..., K)`` of every node for features ``x (..., d)``.

        For offline evaluation; the switching does not use it.
        """
        xn = checked_features(x, self.feature_names)
        with torch.no_grad():
            return self.predictor(torch.from_numpy(np.ascontiguousarray(xn))).numpy()

    def replay(self, time: np.ndarray, features: np.ndarray) -> ReplayResult:
        """Run open-loop over a recorded feature stream.

        Args:
            time: ``(n,)`` sample times [s].
            features: ``(n, d)`` features.

        Returns:
            The MP sequence per variable and the transition events.
        """
        seqs = {v: [mp] for v, mp in self.reset(time[0], features[0]).items()}
        for t, x in zip(time[1:], features[1:], strict=True):
            for v, mp in self.step(t, x).items():
                if mp != seqs[v][-1]:
                    seqs[v].append(mp)
        return ReplayResult(seqs, list(self.events))
