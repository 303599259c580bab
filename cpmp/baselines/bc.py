"""A behaviour-cloning sequencing baseline: classify stay / successor from the state.

``sequencer=bc`` answers the first question a reviewer asks of learned progress: why not
classify the next MP from the state? It learns, per control variable and MP, which MP the
demonstrator runs at the next tick, from every demonstrated tick:

* **training data**: for each node (variable ``v``, MP ``m``) of the sequence graphs
  (:func:`cpmp.graph.build_graphs`), every demonstrated tick ``i`` whose label of ``v`` is
  ``m`` is one sample, its scaled features ``z_i`` (``feature_scaling``, as the progress
  predictors scale them). Its class is the label of ``v`` at tick ``i + 1``: the demonstrator
  decides on ``x_i`` and the switch shows at the next sample. So every activation gives one
  switch sample (its last tick, class = the successor it went to) and stay samples for the
  rest; the last tick of a demonstration is a stay. A node without successors always stays.
* **classifier**: multinomial kernel logistic regression over the classes ``stay`` and the
  node's successors, on the progress predictors' kernel features: an RBF kernel
  ``exp(-γ ||z - s||²)`` on the scaled features against support points ``s``, which are up to
  ``max_supports`` of the node's samples evenly spaced in tick order plus every switch sample.
  The loss is the class-weighted mean cross-entropy (``class_weight: balanced`` makes the
  classes of a node weigh alike: one switch tick per activation against hundreds of stay
  ticks) plus ``½ l2 ||W||²`` on the kernel weights; ``stay`` is the reference class (logit 0)
  and each successor has an unpenalised intercept. The loss is convex; it is minimised by
  damped Newton steps in float64 (deterministic: no random draws).
* **switching**: at each tick, a variable switches to its active MP's most probable
  successor when that successor's probability exceeds ``threshold``; no waiting, no coupling,
  no stall recovery. ``last_tick.transition_probs`` holds the successors' probabilities, so
  recordings show them.
* **start**: per variable, the initial MP of the nearest training entry state (the first
  sample of each demonstration; Euclidean in the scaled space), a 1-nearest-neighbour
  classifier of the start, as the ``goal_nearest`` baseline starts; so the two baselines differ
  in when and where they switch only.

It has no progress predictor; for offline evaluation :meth:`BCSequencer.progress` gives the
nearest-neighbour estimate (:class:`~cpmp.baselines.NearestProgress`, as ``goal_nearest``
does), which the switching never uses. Its options are :class:`~cpmp.config.BCConfig`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from time import perf_counter
from typing import NamedTuple

import numpy as np
import torch

from cpmp.baselines.episodic import EpisodicBaseline, baseline_data
from cpmp.baselines.nearest_progress import NearestProgress
from cpmp.config.bc import KIND, BCConfig, bc_options
from cpmp.config.validation import OptionValue
from cpmp.data import Demonstration
from cpmp.errors import ConfigError, DataError, NotFittedError
from cpmp.graph import SequenceGraph
from cpmp.io import CheckpointPayload, CheckpointSpec, load_checkpoint, save_checkpoint
from cpmp.records import BaselineFitReport, SequencerNote, TickInfo, TransitionEvent
from cpmp.sequencer import checked_features, checked_time

CHECKPOINT_FORMAT = "cpmp-bc"
CHECKPOINT_VERSION = 1
CHECKPOINT = CheckpointSpec(
    CHECKPOINT_FORMAT,
    (CHECKPOINT_VERSION,),
    "bc",
    "load a file written by BCSequencer.save, or fit it again with BCSequencer.fit",
)
"""The bc checkpoint kind."""

STAY = "(stay)"
"""The class of keeping the current MP (column 0 of :meth:`NodeClassifier.probabilities`)."""

_NEWTON_TOL = 1e-10
"""Stop Newton once half the squared Newton decrement (the estimated gap to the optimal loss)
is below this."""
_ARMIJO = 1e-4
_MAX_HALVINGS = 40
_JITTER = 1e-10
"""Added to the Hessian's diagonal so that the unpenalised intercepts keep it definite."""


class NodeFit(NamedTuple):
    """How one node's classifier fit went.

    Attributes:
        iterations: Newton steps taken.
        converged: the Newton decrement test held (else ``max_iter`` or the line search
            ended it).
        loss: the penalised, class-weighted mean cross-entropy at the solution.
        n_samples: training ticks of the node.
        n_switches: of them, switch ticks (class other than stay).
        train_accuracy: share of the node's training ticks classified as labelled at
            ``threshold`` (a stay unless a successor's probability exceeds it).
        switch_recall: share of the switch ticks classified as the demonstrated successor
            (``nan`` without switch ticks).
    """

    iterations: int
    converged: bool
    loss: float
    n_samples: int
    n_switches: int
    train_accuracy: float
    switch_recall: float


@dataclass(frozen=True, eq=False)
class NodeClassifier:
    """The stay / successor classifier of one node (variable, MP) with successors.

    Attributes:
        variable: the control variable.
        mp: the MP.
        successors: the ``C`` successors in the graph (sorted), the classes besides stay.
        supports: ``(S, d)`` support points in the scaled feature space.
        weights: ``(S, C)`` kernel weights of the successors' logits (stay's logit is 0).
        bias: ``(C,)`` the successors' intercepts.
    """

    variable: str
    mp: str
    successors: tuple[str, ...]
    supports: np.ndarray
    weights: np.ndarray
    bias: np.ndarray

    def __post_init__(self) -> None:
        s, c = len(self.supports), len(self.successors)
        if self.supports.ndim != 2 or s == 0:
            raise DataError(f"bc {self.variable}/{self.mp}: no support points")
        if self.weights.shape != (s, c) or self.bias.shape != (c,):
            raise DataError(
                f"bc {self.variable}/{self.mp}: weights {tuple(self.weights.shape)} and bias "
                f"{tuple(self.bias.shape)} do not match {s} supports and {c} successors"
            )

    def probabilities(self, z: np.ndarray, gamma: float) -> np.ndarray:
        """Class probabilities ``(n, 1 + C)`` (stay, then each successor) of ``z (n, d)``.

        Args:
            z: scaled features ``(n, d)``.
            gamma: the RBF kernel parameter γ [1 / scaled units²].
        """
        k = rbf(z, self.supports, gamma)
        logits = np.concatenate([np.zeros((len(z), 1)), k @ self.weights + self.bias], axis=1)
        logits -= logits.max(axis=1, keepdims=True)
        p = np.exp(logits)
        return p / p.sum(axis=1, keepdims=True)


def rbf(z: np.ndarray, supports: np.ndarray, gamma: float) -> np.ndarray:
    """RBF kernel ``exp(-γ ||z - s||²)`` ``(n, S)`` of ``z (n, d)`` against ``supports (S, d)``."""
    sq = (z * z).sum(axis=1)[:, None] + (supports * supports).sum(axis=1)[None, :]
    sq -= 2.0 * z @ supports.T
    return np.exp(-gamma * np.maximum(sq, 0.0))


def support_rows(y: np.ndarray, max_supports: int) -> np.ndarray:
    """Which of a node's samples are support points: evenly spaced ones and every switch.

    Args:
        y: ``(n,)`` class of each sample in tick order (0: stay).
        max_supports: at most this many evenly spaced samples.

    Returns:
        Sorted unique sample indices.
    """
    n = len(y)
    even = np.round(np.linspace(0, n - 1, min(max_supports, n))).astype(int)
    return np.union1d(even, np.flatnonzero(y > 0))


def class_weights(y: np.ndarray, n_classes: int, mode: str) -> np.ndarray:
    """Per-sample weights ``(n,)``: ``balanced`` gives every present class the same total."""
    if mode == "none":
        return np.ones(len(y))
    counts = np.bincount(y, minlength=n_classes).astype(float)
    present = int((counts > 0).sum())
    return len(y) / (present * counts[y])


def fit_multinomial(
    k: np.ndarray, y: np.ndarray, c: np.ndarray, n_classes: int, l2: float, max_iter: int
) -> tuple[np.ndarray, np.ndarray, int, bool, float]:
    """Weighted, L2-penalised multinomial logistic regression on kernel features, by Newton.

    Minimises ``Σ c_i CE_i / Σ c_i + ½ l2 ||W||²`` with logits ``[0, K W + b]`` (class 0 is
    the reference), by Newton steps with an Armijo backtracking line search, in float64.

    Args:
        k: ``(n, S)`` kernel features.
        y: ``(n,)`` classes in ``[0, n_classes)``.
        c: ``(n,)`` sample weights.
        n_classes: ``1 + C``.
        l2: the penalty on ``W``.
        max_iter: at most this many Newton steps.

    Returns:
        ``W (S, C)``, ``b (C,)``, the steps taken, whether the decrement test held, the loss.
    """
    a = torch.from_numpy(np.concatenate([k, np.ones((len(k), 1))], axis=1))
    n, width = a.shape
    classes = n_classes - 1
    onehot = torch.nn.functional.one_hot(torch.from_numpy(y), n_classes).double()[:, 1:]
    cw = torch.from_numpy(c / c.sum())
    penalty = torch.full((width,), float(l2), dtype=torch.float64)
    penalty[-1] = 0.0
    theta = torch.zeros(width, classes, dtype=torch.float64)

    def loss_of(th: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        logits = torch.cat([torch.zeros(n, 1, dtype=torch.float64), a @ th], dim=1)
        logp = torch.log_softmax(logits, dim=1)
        ce = -(logp[:, 1:] * onehot).sum(dim=1) - logp[:, 0] * (1.0 - onehot.sum(dim=1))
        value = (cw * ce).sum() + 0.5 * (penalty[:, None] * th * th).sum()
        return value, logp[:, 1:].exp()

    loss, p = loss_of(theta)
    converged = False
    steps = 0
    for steps in range(1, max_iter + 1):  # noqa: B007 - the count is returned
        grad = a.T @ (cw[:, None] * (p - onehot)) + penalty[:, None] * theta
        hess = torch.zeros(classes, width, classes, width, dtype=torch.float64)
        for i in range(classes):
            for j in range(classes):
                w = cw * p[:, i] * (float(i == j) - p[:, j])
                hess[i, :, j, :] = (a * w[:, None]).T @ a
            hess[i, :, i, :] += torch.diag(penalty + _JITTER)
        g = grad.T.reshape(-1)
        h = hess.reshape(classes * width, classes * width)
        try:
            direction = torch.linalg.solve(h, g)
        except RuntimeError:  # numerically singular: fall back to least squares
            direction = torch.linalg.lstsq(h, g[:, None]).solution[:, 0]
        decrement = float(g @ direction)
        if decrement / 2.0 < _NEWTON_TOL:
            converged = True
            break
        step = direction.reshape(classes, width).T
        scale = 1.0
        for _ in range(_MAX_HALVINGS):
            trial = theta - scale * step
            trial_loss, trial_p = loss_of(trial)
            if float(trial_loss) <= float(loss) - _ARMIJO * scale * decrement:
                break
            scale *= 0.5
        else:
            break  # no descent left at float64 precision
        theta, loss, p = trial, trial_loss, trial_p
    return theta[:-1].numpy(), theta[-1].numpy(), steps, converged, float(loss)


class _NodeData(NamedTuple):
    """One node's training ticks: scaled features and classes (0: stay)."""

    z: np.ndarray
    y: np.ndarray


class BCSequencer(EpisodicBaseline):
    """The behaviour-cloning baseline (see the module doc).

    Build with :meth:`fit` or :meth:`load`; drive with :meth:`reset` then :meth:`step` once per
    control tick, like :class:`~cpmp.sequencer.ConcurrentSequencer`.

    Attributes:
        graphs: variable -> sequence graph (structure only after :meth:`load`).
        feature_names: the ``d`` feature names.
        config: the options.
        predictor: the nearest-neighbour progress estimate (offline evaluation only).
        classifiers: ``(variable, MP)`` -> the node's classifier, for every node with
            successors.
        starts: ``(variable, MP)`` -> ``(n, d)`` scaled first samples of the demonstrations
            starting with that MP, for every initial node.
        fit_summary: what the fit reported (``nodes``: ``"variable/MP"`` -> :class:`NodeFit`
            as a dict); ``None`` for one built by hand.
        active, events, notes, last_tick: the current episode (as the learned sequencer's).
    """

    kind = KIND

    def __init__(
        self,
        graphs: Mapping[str, SequenceGraph],
        feature_names: Sequence[str],
        config: BCConfig,
        predictor: NearestProgress,
        classifiers: Mapping[tuple[str, str], NodeClassifier],
        starts: Mapping[tuple[str, str], np.ndarray],
        fit_summary: BaselineFitReport | None = None,
    ) -> None:
        self.graphs = dict(graphs)
        self.feature_names = list(feature_names)
        self.config = config
        self.predictor = predictor
        self.classifiers = dict(classifiers)
        self.starts = {k: np.asarray(s, dtype=np.float64) for k, s in starts.items()}
        self.fit_summary = fit_summary
        d = len(self.feature_names)
        for v, g in self.graphs.items():
            for mp in g.nodes:
                clf = self.classifiers.get((v, mp))
                successors = tuple(sorted(g.successors(mp)))
                if successors and (clf is None or clf.successors != successors):
                    raise ConfigError(f"bc: no classifier of {v}/{mp} over {successors}")
                if clf is not None and clf.supports.shape[1] != d:
                    raise ConfigError(f"bc: the classifier of {v}/{mp} is not over {d} features")
            for mp in g.initial_nodes:
                if self.starts.get((v, mp), np.zeros((0, 0))).shape[1:] != (d,):
                    raise ConfigError(f"bc: no start states of {d} features for {v}/{mp}")
        self._new_episode()

    def _new_episode(self) -> None:
        """Forget the current episode (a fresh state; the fitted data stays shared)."""
        self.active: dict[str, str] = {}
        self.events: list[TransitionEvent] = []
        self.notes: list[SequencerNote] = []
        self.last_tick: TickInfo | None = None
        self._last_t: float | None = None

    # ----------------------------------------------------------------------------- fitting
    @classmethod
    def fit(
        cls,
        demos: Sequence[Demonstration],
        *,
        seed: int = 0,
        variables: Sequence[str] | None = None,
        **options: OptionValue,
    ) -> BCSequencer:
        """Build the graphs and fit every node's stay / successor classifier.

        Args:
            demos: labelled demonstrations sharing feature names and control variables.
            seed: accepted for a uniform interface (the fit is deterministic and draws
                nothing).
            variables: the control variables to sequence (``None``: all).
            **options: :class:`~cpmp.config.BCConfig` fields.

        Returns:
            The fitted baseline.
        """
        started = perf_counter()
        config = bc_options(options)
        data = baseline_data(demos, variables, config.feature_scaling, "BCSequencer.fit")
        demos, feature_names, graphs, predictor = (
            data.demos,
            data.feature_names,
            data.graphs,
            data.predictor,
        )
        starts: dict[tuple[str, str], list[np.ndarray]] = {}
        node_data: dict[tuple[str, str], _NodeData] = {}
        for v, mp in data.node_keys:
            successors = sorted(graphs[v].successors(mp))
            index = {s: i + 1 for i, s in enumerate(successors)}
            zs, ys = [], []
            for a, z in zip(graphs[v].activations[mp], data.scaled[(v, mp)], strict=True):
                demo = demos[a.demo]
                y = np.zeros(len(z), dtype=np.int64)
                if a.stop < demo.n_samples:
                    y[-1] = index[str(demo.labels[v][a.stop])]
                if a.start == 0:
                    starts.setdefault((v, mp), []).append(z[0])
                zs.append(z)
                ys.append(y)
            if successors:
                node_data[(v, mp)] = _NodeData(np.concatenate(zs), np.concatenate(ys))
        classifiers, fits = {}, {}
        for (v, mp), nd in node_data.items():
            clf, info = cls._fit_node(v, mp, sorted(graphs[v].successors(mp)), nd, config)
            classifiers[(v, mp)] = clf
            fits[f"{v}/{mp}"] = info._asdict()
        summary = BaselineFitReport(
            kind=KIND,
            n_demos=len(demos),
            n_support_total=sum(len(c.supports) for c in classifiers.values()),
            seconds=perf_counter() - started,
            nodes=fits,
            warnings=tuple(
                f"bc: the classifier of {key} did not converge in {f['iterations']} Newton steps"
                for key, f in fits.items()
                if not f["converged"]
            ),
        )
        return cls(
            graphs,
            feature_names,
            config,
            predictor,
            classifiers,
            {k: np.stack(s) for k, s in starts.items()},
            summary,
        )

    @staticmethod
    def _fit_node(
        v: str, mp: str, successors: list[str], data: _NodeData, config: BCConfig
    ) -> tuple[NodeClassifier, NodeFit]:
        """Fit one node's classifier on its training ticks."""
        n_classes = 1 + len(successors)
        rows = support_rows(data.y, config.max_supports)
        supports = data.z[rows]
        k = rbf(data.z, supports, config.gamma)
        c = class_weights(data.y, n_classes, config.class_weight)
        w, b, steps, converged, loss = fit_multinomial(
            k, data.y, c, n_classes, config.l2, config.max_iter
        )
        clf = NodeClassifier(v, mp, tuple(successors), supports, w, b)
        decided = _decide(clf.probabilities(data.z, config.gamma), config.threshold)
        switches = data.y > 0
        recall = float((decided[switches] == data.y[switches]).mean()) if switches.any() else np.nan
        info = NodeFit(
            steps,
            converged,
            loss,
            len(data.y),
            int(switches.sum()),
            float((decided == data.y).mean()),
            recall,
        )
        return clf, info

    # ----------------------------------------------------------------------------- inference
    def switch_probabilities(self, variable: str, mp: str, x: np.ndarray) -> np.ndarray:
        """Class probabilities ``(n, 1 + C)`` (stay, then the sorted successors) of a node.

        Args:
            variable: the control variable.
            mp: the MP (a node with successors).
            x: raw features ``(n, d)`` or ``(d,)``.
        """
        z = self.predictor.scaler.transform(checked_features(x, self.feature_names))
        return self.classifiers[(variable, mp)].probabilities(
            z.reshape(-1, len(self.feature_names)), self.config.gamma
        )

    def reset(self, t: float, x: np.ndarray) -> dict[str, str]:
        """Start each variable at the initial MP with the nearest demonstrated first sample."""
        t = checked_time(t)
        z = self.predictor.scaler.transform(checked_features(x, self.feature_names).reshape(-1))
        self.active = {}
        for v in sorted(self.graphs):
            initial = sorted(self.graphs[v].initial_nodes)
            best = [
                float(np.min(np.linalg.norm(self.starts[(v, mp)] - z, axis=1))) for mp in initial
            ]
            self.active[v] = initial[int(np.argmin(best))]
        self.events = []
        self.notes = []
        self._last_t = t
        self.last_tick = TickInfo(t, {}, {v: {} for v in self.graphs}, dict(self.active))
        return dict(self.active)

    def step(self, t: float, x: np.ndarray) -> dict[str, str]:
        """Advance one tick at time ``t`` [s] with features ``x (d,)``; returns the active MPs.

        Each variable whose active MP's most probable successor has a probability above
        ``threshold`` switches to it.
        """
        if not self.active or self._last_t is None:
            raise NotFittedError("call reset(t, x) before step(t, x)")
        t = checked_time(t)
        if t < self._last_t:
            raise DataError(f"time went backwards: step at t={t} after t={self._last_t}")
        state = checked_features(x, self.feature_names).reshape(-1)
        z = self.predictor.scaler.transform(state)[None, :]
        probs: dict[str, dict[str, float]] = {}
        for v in sorted(self.graphs):
            current = self.active[v]
            clf = self.classifiers.get((v, current))
            if clf is None:
                probs[v] = {}
                continue
            p = clf.probabilities(z, self.config.gamma)[0]
            probs[v] = {s: float(q) for s, q in zip(clf.successors, p[1:], strict=True)}
            best = int(np.argmax(p[1:]))
            if p[1 + best] > self.config.threshold:
                target = clf.successors[best]
                self.events.append(
                    TransitionEvent(t, v, current, target, float(p[1 + best]), state.copy())
                )
                self.active[v] = target
        self._last_t = t
        self.last_tick = TickInfo(t, {}, probs, dict(self.active))
        return dict(self.active)

    def describe(self) -> str:
        """The options, then the graphs, each classified node with its supports and fit."""
        c = self.config
        parts = [
            f"bc: per node, kernel logistic regression of stay / successor (RBF γ={c.gamma:g} on "
            f"{c.feature_scaling}-scaled features, l2={c.l2:g}, class weight {c.class_weight}); "
            f"switch when a successor's probability > {c.threshold:g}; start at the nearest "
            "demonstrated first sample"
        ]
        nodes = (None if self.fit_summary is None else self.fit_summary.nodes) or {}
        for v in sorted(self.graphs):
            parts.append(self.graphs[v].to_text())
            for mp in self.graphs[v].ordered_nodes():
                clf = self.classifiers.get((v, mp))
                if clf is None:
                    parts.append(f"  {mp}: always stays (no successor)")
                    continue
                line = f"  {mp}: {len(clf.supports)} supports over {', '.join(clf.successors)}"
                fit = nodes.get(f"{v}/{mp}")
                if fit:
                    line += (
                        f"; {fit['n_switches']} switch / {fit['n_samples']} ticks, training "
                        f"accuracy {fit['train_accuracy']:.3f}, switch recall "
                        f"{fit['switch_recall']:.2f}"
                    )
                parts.append(line)
        return "\n".join(parts)

    # ----------------------------------------------------------------------------- persistence
    def save(self, path: str | Path) -> Path:
        """Write a checkpoint atomically to ``path`` (read it with :meth:`load`)."""
        return save_checkpoint(
            path,
            {
                "format": CHECKPOINT_FORMAT,
                "version": CHECKPOINT_VERSION,
                "config": dataclasses.asdict(self.config),
                "feature_names": self.feature_names,
                "graphs": {v: g.to_dict() for v, g in self.graphs.items()},
                "node_keys": [list(k) for k in self.predictor.node_keys],
                "predictor": self.predictor.state_dict(),
                "classifiers": [
                    {
                        "variable": v,
                        "mp": mp,
                        "successors": list(clf.successors),
                        "supports": torch.from_numpy(clf.supports),
                        "weights": torch.from_numpy(clf.weights),
                        "bias": torch.from_numpy(clf.bias),
                    }
                    for (v, mp), clf in sorted(self.classifiers.items())
                ],
                "starts": [
                    {"variable": v, "mp": mp, "states": torch.from_numpy(s)}
                    for (v, mp), s in sorted(self.starts.items())
                ],
                "fit_summary": (
                    {}
                    if self.fit_summary is None
                    else {k: v for k, v in self.fit_summary.to_dict().items() if k != "warnings"}
                ),
            },
        )

    @classmethod
    def load(cls, path: str | Path) -> BCSequencer:
        """Load a checkpoint written by :meth:`save`."""
        return load_checkpoint(path, CHECKPOINT, cls._from_payload)

    @classmethod
    def _from_payload(cls, payload: CheckpointPayload, version: int) -> BCSequencer:
        """Rebuild from a checkpoint payload (of :data:`CHECKPOINT_VERSION`)."""
        graphs = {v: SequenceGraph.from_dict(g) for v, g in payload["graphs"].items()}
        state = payload["predictor"]
        predictor = NearestProgress(
            [tuple(k) for k in payload["node_keys"]],
            len(payload["feature_names"]),
            int(state["samples"].shape[0]),
        )
        predictor.load_state_dict(state)
        classifiers = {
            (r["variable"], r["mp"]): NodeClassifier(
                r["variable"],
                r["mp"],
                tuple(r["successors"]),
                r["supports"].numpy(),
                r["weights"].numpy(),
                r["bias"].numpy(),
            )
            for r in payload["classifiers"]
        }
        starts = {(r["variable"], r["mp"]): r["states"].numpy() for r in payload["starts"]}
        summary = payload.get("fit_summary") or {}
        return cls(
            graphs,
            payload["feature_names"],
            bc_options(payload["config"]),
            predictor,
            classifiers,
            starts,
            BaselineFitReport.from_dict(summary) if summary else None,
        )


def _decide(p: np.ndarray, threshold: float) -> np.ndarray:
    """The class ``(n,)`` each row of probabilities ``(n, 1 + C)`` decides.

    The most probable successor where its probability exceeds ``threshold``, else stay (0).
    """
    best = np.argmax(p[:, 1:], axis=1)
    top = p[np.arange(len(p)), 1 + best]
    return np.where(top > threshold, 1 + best, 0)
