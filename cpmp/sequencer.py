"""The concurrent sequencer: one sequence graph per control variable, coupled by features.

Transition rule (paper section III): at the start each graph activates the initial node with
the highest entry probability ``1 - φ``. At every tick, for each successor ``s`` of the current
node ``c`` the transition probability is ``p_s = φ_c(x) · (1 - φ_s(x))``; the sequencer switches
to the best successor once its ``p`` exceeds ``threshold`` and has not improved by more than
``min_improvement`` for ``patience`` seconds.

The graphs are independent; they are coupled only because every node's progress is predicted
from the same global feature vector ``x``.
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import torch

from cpmp.errors import ConfigError, CpmpFileError, DataError, NotFittedError, UnknownMPError
from cpmp.graph import SequenceGraph, build_graphs
from cpmp.io import atomic_path, to_builtin
from cpmp.predictors import (
    START_PREFIX,
    NodeData,
    ProgressPredictor,
    make_predictor,
    predictor_from_spec,
    predictor_options,
)
from cpmp.progress import expected_progress
from cpmp.training import TrainerConfig, fit_predictor

if TYPE_CHECKING:
    from cpmp.data import Demonstration

log = logging.getLogger(__name__)

CHECKPOINT_FORMAT = "cpmp-sequencer"
CHECKPOINT_VERSION = 1


@dataclass
class SequencerConfig:
    """The transition rule's parameters.

    Attributes:
        threshold: a transition fires only when ``p > threshold`` (paper: 0.65).
        patience: seconds ``p`` must go without improving before the switch fires (paper: 50 ms).
        min_improvement: an increase of ``p`` smaller than this does not count as improving.
            Attractors converge asymptotically, so ``p`` keeps creeping up by tiny amounts; with
            a strict comparison (``0``) such a transition might never fire.
        min_exit: a transition also needs the current node's exit probability ``φ`` above this
            (0 = the paper's rule). ``p = φ (1 - φ_next)`` can pass the threshold with ``φ``
            well below 1 when the successor's entry probability is near 1, e.g. a grasp that
            lasts through lift, carry and lower is left at the end of carry; the gate keeps an
            MP active until it has (nearly) run its course.
        start_kernel: ``shared`` (paper): the initial node is chosen with the nodes' progress
            predictors. ``isotropic``: with extra heads for the initial nodes, fitted in the same
            run on the same data but always with the isotropic kernel. Meant for
            ``feature_weighting=path``, which de-weights features that stay constant along an
            activation, such as box size; those are exactly what decides the strategy.
        start_rule: ``independent`` (paper): each graph starts at its own initial node of
            highest entry probability. ``joint``: choose among the combinations of initial MPs
            seen together in a demonstration the one with the highest summed log entry
            probability, so graphs cannot start in a mixture of strategies that was never
            demonstrated (the coupling the paper's discussion proposes).
    """

    threshold: float = 0.65
    patience: float = 0.05
    min_improvement: float = 1e-3
    min_exit: float = 0.0
    start_kernel: str = "shared"
    start_rule: str = "independent"

    def __post_init__(self) -> None:
        if not 0.0 <= self.threshold < 1.0:
            raise ConfigError(f"threshold must be in [0, 1), got {self.threshold}")
        if self.patience < 0.0:
            raise ConfigError(f"patience must be >= 0 seconds, got {self.patience}")
        if self.min_improvement < 0.0:
            raise ConfigError(f"min_improvement must be >= 0, got {self.min_improvement}")
        if not 0.0 <= self.min_exit < 1.0:
            raise ConfigError(f"min_exit must be in [0, 1), got {self.min_exit}")
        if self.start_kernel not in ("shared", "isotropic"):
            raise ConfigError(
                f"start_kernel must be 'shared' or 'isotropic', got {self.start_kernel!r}"
            )
        if self.start_rule not in ("independent", "joint"):
            raise ConfigError(
                f"start_rule must be 'independent' or 'joint', got {self.start_rule!r}"
            )


@dataclass(frozen=True)
class TransitionEvent:
    """A switch of one control variable.

    Attributes:
        t: time [s] of the tick at which the switch fired.
        variable: control variable.
        source: MP active before.
        target: MP active after.
        probability: transition probability ``p`` at that tick.
        state: (d,) feature vector at that tick.
    """

    t: float
    variable: str
    source: str
    target: str
    probability: float
    state: np.ndarray = field(repr=False)


@dataclass
class TickInfo:
    """What the sequencer computed at the last tick (for inspection and recordings).

    Attributes:
        t: time [s].
        progress: variable -> MP -> φ (every node).
        transition_probs: variable -> successor -> ``p`` (successors of the active MP).
        active: variable -> active MP after the tick.
    """

    t: float
    progress: dict[str, dict[str, float]]
    transition_probs: dict[str, dict[str, float]]
    active: dict[str, str]


@dataclass
class _Candidate:
    target: str
    best: float
    since: float


def _split_options(options: dict[str, Any], kind: str) -> tuple[dict, dict, dict, dict]:
    """Route ``fit`` options to the predictor, sequencer, trainer and fit itself."""
    pred_names = set(predictor_options(kind))
    seq_names = {f.name for f in dataclasses.fields(SequencerConfig)}
    trainer_names = {f.name for f in dataclasses.fields(TrainerConfig)}
    fit_names = {"seed", "variables", "subsample"}
    pred, seq, trainer, rest = {}, {}, {}, {}
    for key, value in options.items():
        if key in pred_names:
            pred[key] = value
        elif key in seq_names:
            seq[key] = value
        elif key in trainer_names:
            trainer[key] = value
        elif key in fit_names:
            rest[key] = value
        else:
            valid = sorted(pred_names | seq_names | trainer_names | fit_names)
            raise ConfigError(
                f"unknown option {key!r} for ConcurrentSequencer.fit with predictor {kind!r}; "
                f"valid options: {', '.join(valid)}"
            )
    return pred, seq, trainer, rest


class ConcurrentSequencer:
    """Concurrent sequence graphs with learned progress predictors.

    Build one with :meth:`fit` (from demonstrations) or :meth:`load` (from a checkpoint); drive it
    with :meth:`reset` then :meth:`step` once per control tick.
    """

    def __init__(
        self,
        graphs: Mapping[str, SequenceGraph],
        predictor: ProgressPredictor,
        feature_names: Sequence[str],
        config: SequencerConfig | None = None,
        fit_summary: dict[str, Any] | None = None,
        initial_combinations: Sequence[Mapping[str, str]] | None = None,
    ) -> None:
        self.graphs = dict(graphs)
        self.predictor = predictor.eval()
        self.feature_names = list(feature_names)
        self.config = config or SequencerConfig()
        self.fit_summary = fit_summary or {}
        self.initial_combinations = [dict(c) for c in initial_combinations or []]
        """Initial MP per variable of each demonstration (distinct; for ``start_rule=joint``)."""
        if len(self.feature_names) != predictor.n_features:
            raise ConfigError(
                f"{len(self.feature_names)} feature names for a predictor of "
                f"{predictor.n_features} features"
            )
        keys = [(v, mp) for v in sorted(self.graphs) for mp in self.graphs[v].ordered_nodes()]
        extra = predictor.node_keys[len(keys) :]
        if predictor.node_keys[: len(keys)] != keys or extra not in ([], start_keys(self.graphs)):
            raise ConfigError("the predictor's nodes do not match the sequence graphs' nodes")
        self._keys = keys
        self._index = {key: i for i, key in enumerate(keys)}
        self._start_index = {
            (v, mp[len(START_PREFIX) :]): len(keys) + i for i, (v, mp) in enumerate(extra)
        } or self._index
        self._successor_idx = {
            (v, mp): (
                self.graphs[v].successors(mp),
                [self._index[(v, s)] for s in self.graphs[v].successors(mp)],
            )
            for v, mp in keys
        }
        self.active: dict[str, str] = {}
        self.events: list[TransitionEvent] = []
        self.last_tick: TickInfo | None = None
        self._candidates: dict[str, _Candidate | None] = {}
        self._last_t: float | None = None

    # ----------------------------------------------------------------------------- fitting
    @classmethod
    def fit(
        cls,
        demos: Sequence[Demonstration],
        predictor: str = "klr",
        **options: Any,
    ) -> ConcurrentSequencer:
        """Build the sequence graphs and fit every node's progress predictor.

        Args:
            demos: labelled demonstrations sharing feature names and control variables.
            predictor: ``klr`` (paper), ``klr_full``, ``klr_sparse`` or ``mlp``.
            **options: predictor options (e.g. ``gamma``, ``support_scale``, ``min_support``,
                ``l2``, ``feature_scaling``), sequencer options (``threshold``, ``patience``,
                ``min_improvement``), trainer options (``max_epochs``, ``progress_bar``,
                ``logger``, ``log_dir``), ``seed``, ``variables`` (subset to model) and
                ``subsample`` (train on every k-th sample of each activation, its last sample
                always kept; expected progress is computed on the full trajectory first).
        """
        pred_opts, seq_opts, trainer_opts, rest = _split_options(options, predictor)
        seq_config = SequencerConfig(**seq_opts)
        trainer_config = TrainerConfig(**trainer_opts)
        seed = int(rest.get("seed", 0))
        demos = list(demos)
        if not demos:
            raise DataError("ConcurrentSequencer.fit needs at least one demonstration, got none")
        feature_names = list(demos[0].feature_names)
        for m, demo in enumerate(demos):
            if list(demo.feature_names) != feature_names:
                raise DataError(
                    f"{demo.name or f'demonstration {m}'} has features {list(demo.feature_names)}"
                    f" but the first demonstration has {feature_names}; all must match"
                )
        graphs = build_graphs(demos, rest.get("variables"))
        node_keys = [(v, mp) for v in sorted(graphs) for mp in graphs[v].ordered_nodes()]
        if seq_config.start_kernel == "isotropic":
            node_keys += start_keys(graphs)
        model = make_predictor(predictor, node_keys, len(feature_names), **pred_opts)
        all_x = np.concatenate([d.features for d in demos], axis=0)
        model.scaler.fit(all_x, model.config.feature_scaling)
        subsample = int(rest.get("subsample", 1))
        if subsample < 1:
            raise ConfigError(f"subsample must be >= 1, got {subsample}")
        data = node_training_data(graphs, model, subsample)
        summary = fit_predictor(model, data, trainer_config, seed=seed)
        summary["n_demos"] = len(demos)
        combos: list[dict[str, str]] = []
        for demo in demos:
            combo = {v: str(demo.labels[v][0]) for v in sorted(graphs)}
            if combo not in combos:
                combos.append(combo)
        return cls(graphs, model, feature_names, seq_config, summary, combos)

    # ----------------------------------------------------------------------------- inference
    def progress(self, x: np.ndarray | torch.Tensor, heads: int | None = None) -> np.ndarray:
        """φ of every node for features ``x (..., d)``: ``(..., K)`` in :attr:`node_keys` order
        (start heads, if any, after them); ``heads`` keeps only the first ``heads`` columns
        (and skips evaluating the others)."""
        if isinstance(x, torch.Tensor):
            x = x.detach().cpu().numpy()
        xn = np.asarray(x, dtype=np.float64)
        if xn.ndim == 0 or xn.shape[-1] != len(self.feature_names):
            raise DataError(
                f"expected features with {len(self.feature_names)} entries "
                f"({', '.join(self.feature_names[:4])}, ...), got shape {tuple(xn.shape)}"
            )
        if not np.isfinite(xn).all():
            raise DataError("features contain NaN or inf; the sequencer needs finite features")
        with torch.no_grad():
            return self.predictor(torch.from_numpy(np.ascontiguousarray(xn)), heads).numpy()

    @property
    def node_keys(self) -> list[tuple[str, str]]:
        """(variable, MP) of every node, in the order of :meth:`progress`'s first columns
        (start heads, if any, follow them)."""
        return list(self._keys)

    def predict_progress(self, x: np.ndarray) -> dict[str, dict[str, float]]:
        """φ of every node for one feature vector ``x (d,)``: variable -> MP -> φ."""
        state = np.asarray(x, dtype=np.float64).reshape(-1)
        return self._phi_dict(self.progress(state, heads=len(self._keys)))

    def reset(self, t: float, x: np.ndarray) -> dict[str, str]:
        """Start every graph at its initial node of highest entry probability ``1 - φ`` (or the
        demonstrated combination of initial nodes with the highest summed log entry probability
        when ``start_rule="joint"``)."""
        phi = self.progress(np.asarray(x, dtype=np.float64).reshape(-1))
        if self.config.start_rule == "joint" and self.initial_combinations:
            entry = np.clip(1.0 - phi, 1e-12, 1.0)
            scores = [
                sum(np.log(entry[self._start_index[(v, mp)]]) for v, mp in combo.items())
                for combo in self.initial_combinations
            ]
            self.active = dict(self.initial_combinations[int(np.argmax(scores))])
        else:
            self.active = {}
            for v in sorted(self.graphs):
                initial = sorted(self.graphs[v].initial_nodes)
                entry_v = [1.0 - phi[self._start_index[(v, mp)]] for mp in initial]
                self.active[v] = initial[int(np.argmax(entry_v))]
        self.events = []
        self._candidates = {v: None for v in self.graphs}
        self._last_t = float(t)
        self.last_tick = TickInfo(
            float(t), self._phi_dict(phi), {v: {} for v in self.graphs}, dict(self.active)
        )
        return dict(self.active)

    def step(self, t: float, x: np.ndarray) -> dict[str, str]:
        """Advance one tick at time ``t`` [s] with features ``x (d,)``; returns the active MPs."""
        if not self.active:
            raise NotFittedError("call reset(t, x) before step(t, x)")
        t = float(t)
        if self._last_t is not None and t < self._last_t:
            raise DataError(f"time went backwards: step at t={t} after t={self._last_t}")
        self._last_t = t
        state = np.asarray(x, dtype=np.float64).reshape(-1)
        phi = self.progress(state, heads=len(self._keys)).tolist()
        probs: dict[str, dict[str, float]] = {}
        c = self.config
        for v in sorted(self.graphs):
            current = self.active[v]
            names, idx = self._successor_idx[(v, current)]
            if not names:
                probs[v] = {}
                self._candidates[v] = None
                continue
            exit_p = phi[self._index[(v, current)]]
            p = [exit_p * (1.0 - phi[i]) for i in idx]
            probs[v] = dict(zip(names, p, strict=True))
            best = max(range(len(p)), key=p.__getitem__)
            target, p_best = names[best], p[best]
            cand = self._candidates.get(v)
            if p_best <= c.threshold or exit_p <= c.min_exit:
                self._candidates[v] = None
                continue
            if cand is None or cand.target != target:
                cand = _Candidate(target, p_best, t)
            elif p_best > cand.best + c.min_improvement:
                cand.best, cand.since = p_best, t
            self._candidates[v] = cand
            if t - cand.since >= c.patience - 1e-9:
                self.events.append(TransitionEvent(t, v, current, target, p_best, state.copy()))
                self.active[v] = target
                self._candidates[v] = None
        self.last_tick = TickInfo(t, self._phi_dict(phi), probs, dict(self.active))
        return dict(self.active)

    def _phi_dict(self, phi: np.ndarray | list[float]) -> dict[str, dict[str, float]]:
        """Per-node φ ``(K,)`` as variable -> MP -> φ (start heads left out)."""
        out: dict[str, dict[str, float]] = {v: {} for v in sorted(self.graphs)}
        values = phi.tolist() if isinstance(phi, np.ndarray) else phi
        for (v, mp), value in zip(self._keys, values[: len(self._keys)], strict=True):
            out[v][mp] = value
        return out

    def replay(
        self, time: np.ndarray, features: np.ndarray
    ) -> tuple[dict[str, list[str]], list[TransitionEvent]]:
        """Run the sequencer open-loop over a recorded feature stream ``(n,), (n, d)``.

        Returns the MP sequence per variable and the transition events.
        """
        seqs = {v: [mp] for v, mp in self.reset(time[0], features[0]).items()}
        for t, x in zip(time[1:], features[1:], strict=True):
            before = dict(self.active)
            after = self.step(t, x)
            for v, mp in after.items():
                if mp != before[v]:
                    seqs[v].append(mp)
        return seqs, list(self.events)

    # ----------------------------------------------------------------------------- persistence
    def save(self, path: str | Path) -> Path:
        """Write a checkpoint (graphs, predictor weights, configs) atomically to ``path``."""
        payload = {
            "format": CHECKPOINT_FORMAT,
            "version": CHECKPOINT_VERSION,
            "feature_names": self.feature_names,
            "graphs": {v: g.to_dict() for v, g in self.graphs.items()},
            "predictor": {"spec": self.predictor.spec(), "state": self.predictor.state_dict()},
            "sequencer": dataclasses.asdict(self.config),
            "fit_summary": to_builtin(self.fit_summary),
            "initial_combinations": self.initial_combinations,
        }
        path = Path(path)
        with atomic_path(path) as tmp:
            torch.save(payload, tmp)
        return path

    @classmethod
    def load(cls, path: str | Path) -> ConcurrentSequencer:
        """Load a checkpoint written by :meth:`save`."""
        path = Path(path)
        if not path.is_file():
            raise CpmpFileError(
                f"checkpoint {path} does not exist; train one with scripts/train.py"
            )
        try:
            payload = torch.load(path, map_location="cpu", weights_only=True)
        except Exception as err:
            raise CpmpFileError(f"{path} is not a readable cpmp checkpoint: {err}") from err
        if not isinstance(payload, dict) or payload.get("format") != CHECKPOINT_FORMAT:
            raise CpmpFileError(f"{path} is not a cpmp sequencer checkpoint")
        if payload.get("version") != CHECKPOINT_VERSION:
            raise CpmpFileError(
                f"{path} has checkpoint version {payload.get('version')}; this cpmp reads "
                f"version {CHECKPOINT_VERSION}"
            )
        graphs = {v: SequenceGraph.from_dict(g) for v, g in payload["graphs"].items()}
        predictor = predictor_from_spec(payload["predictor"]["spec"])
        predictor.load_state_dict(payload["predictor"]["state"])
        return cls(
            graphs,
            predictor,
            payload["feature_names"],
            SequencerConfig(**payload["sequencer"]),
            payload.get("fit_summary", {}),
            payload.get("initial_combinations", []),
        )

    def with_config(self, **options: Any) -> ConcurrentSequencer:
        """A sequencer sharing graphs and predictor but with other transition-rule options."""
        config = dataclasses.replace(self.config, **options)
        return ConcurrentSequencer(
            self.graphs,
            self.predictor,
            self.feature_names,
            config,
            self.fit_summary,
            self.initial_combinations,
        )

    def describe(self) -> str:
        """All graphs as text."""
        return "\n".join(self.graphs[v].to_text() for v in sorted(self.graphs))

    def check_variable(self, variable: str) -> SequenceGraph:
        if variable not in self.graphs:
            raise UnknownMPError(
                f"unknown control variable {variable!r}; known: {', '.join(sorted(self.graphs))}"
            )
        return self.graphs[variable]


def start_keys(graphs: Mapping[str, SequenceGraph]) -> list[tuple[str, str]]:
    """Keys of the start heads: ``(variable, START_PREFIX + mp)`` per initial node."""
    return [
        (v, START_PREFIX + mp) for v in sorted(graphs) for mp in sorted(graphs[v].initial_nodes)
    ]


def node_training_data(
    graphs: Mapping[str, SequenceGraph], predictor: ProgressPredictor, subsample: int = 1
) -> list[NodeData]:
    """Per-node training samples (scaled features) and expected-progress targets, in the
    predictor's node order; ``subsample`` keeps every k-th sample (and the last) for the loss."""
    out = []
    for v, key_mp in predictor.node_keys:
        mp = key_mp.removeprefix(START_PREFIX)
        acts = graphs[v].activations[mp]
        if not acts:
            raise DataError(f"node {v}/{mp} has no activation data to train on")
        scaled = [predictor.scaler.transform(a.features) for a in acts]
        targets = [expected_progress(f, a.time) for f, a in zip(scaled, acts, strict=True)]
        keep = [_stride(len(f), subsample) for f in scaled]
        x = np.concatenate([f[k] for f, k in zip(scaled, keep, strict=True)])
        y = np.concatenate([y[k] for y, k in zip(targets, keep, strict=True)])
        dt = predictor.dtype_
        out.append(
            NodeData(
                key=(v, key_mp),
                x=torch.as_tensor(x, dtype=dt),
                target=torch.as_tensor(y, dtype=dt),
                activations=scaled,
            )
        )
    return out


def _stride(n: int, k: int) -> np.ndarray:
    """Indices ``0, k, 2k, ...`` of ``n`` samples, always including the last one."""
    idx = np.arange(0, n, k)
    return idx if idx[-1] == n - 1 else np.append(idx, n - 1)
