"""What a fit learns from and what it checks afterwards.

Per-node training data, the non-finite and degenerate-node checks, label-glitch and label-typo
warnings.

:func:`cpmp.sequencer.fit.fit_parts` builds one :class:`~cpmp.predictors.NodeData` per node
(its scaled samples and progress targets, eq. 1) with :func:`node_training_data`, fits them
with :func:`cpmp.predictors.training.fit_predictor`, then reports what it found with
:func:`glitch_warnings` and :func:`fit_warnings`; :func:`initial_combinations` are the
demonstrated starts of ``start_rule="joint"``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import torch

from cpmp.data import Demonstration
from cpmp.errors import DataError
from cpmp.graph import SequenceGraph
from cpmp.predictors import NodeData, ProgressPredictor
from cpmp.progress import expected_progress, path_length, path_trajectory, progress_labels


def initial_combinations(
    demos: Sequence[Demonstration], variables: Sequence[str]
) -> list[dict[str, str]]:
    """The distinct initial MP per variable of the demonstrations, in order of first appearance.

    What ``start_rule="joint"`` chooses among.

    Args:
        demos: the demonstrations.
        variables: the control variables.

    Returns:
        One variable -> MP mapping per distinct start.
    """
    combos: list[dict[str, str]] = []
    for demo in demos:
        combo = {v: str(demo.labels[v][0]) for v in variables}
        if combo not in combos:
            combos.append(combo)
    return combos


def node_training_data(
    graphs: Mapping[str, SequenceGraph],
    predictor: ProgressPredictor,
    subsample: int = 1,
    ambient: np.ndarray | None = None,
) -> list[NodeData]:
    """Per-node training samples (scaled features) and progress targets, in the predictor's order.

    The targets are eq. 1, or normalised time for a predictor with ``labels = "time"``;
    ``subsample`` keeps every k-th sample (and the last) for the loss. Each activation is
    scaled, measured (:func:`cpmp.progress.path_trajectory`: denoised for ``path_denoised``
    labels) and labelled.

    With ``path_denoised`` labels (cpmp's eq. 1: the task's motion) the ``ambient (d,)``
    features (:func:`cpmp.sequencer.motion.ambient_features`) are held at each activation's
    first value along its path: their drift is no progress, so it adds nothing to the labels,
    the support points' spacing or the path weights, and the nodes mark them
    :attr:`~cpmp.predictors.NodeData.ignored` (a path-weighted kernel weighs them 0). Other
    labels (the paper's, time) keep every feature.
    """
    denoised = predictor.labels == "path_denoised"  # then eq. 1 ("path") along denoised paths
    noise, kind = ("auto", "path") if denoised else ("none", predictor.labels)
    ignored = None
    if denoised and ambient is not None and np.any(ambient):
        ignored = np.asarray(ambient, dtype=bool)
    out = []
    for v, mp in predictor.node_keys:
        acts = graphs[v].activations[mp]
        if not acts:
            raise DataError(f"node {v}/{mp} has no activation data to train on")
        scaled = [predictor.scaler.transform(a.features) for a in acts]
        paths = [_held(path_trajectory(f, noise), ignored) for f in scaled]
        targets = [progress_labels(p, a.time, kind) for p, a in zip(paths, acts, strict=True)]
        keep = [_stride(len(f), subsample) for f in scaled]
        x = np.concatenate([f[k] for f, k in zip(scaled, keep, strict=True)])
        y = np.concatenate([y[k] for y, k in zip(targets, keep, strict=True)])
        dt = predictor.dtype_
        out.append(
            NodeData(
                key=(v, mp),
                x=torch.as_tensor(x, dtype=dt),
                target=torch.as_tensor(y, dtype=dt),
                activations=scaled,
                paths=paths,
                labels=targets,
                ignored=ignored,
            )
        )
    return out


def _held(path: np.ndarray, ignored: np.ndarray | None) -> np.ndarray:
    """``path (n, d)`` with the ``ignored`` features held at their first value."""
    if ignored is None:
        return path
    out = path.copy()
    out[:, ignored] = path[:1, ignored]
    return out


def node_validation_data(
    graphs: Mapping[str, SequenceGraph],
    predictor: ProgressPredictor,
    demos: Sequence[Demonstration],
) -> list[NodeData]:
    """Per-node held-out samples (scaled features) and eq. 1 labels, in the predictor's order.

    Every activation in ``demos`` of an MP the ``graphs`` have is scaled with the
    predictor's scaler and labelled by eq. 1 on its own (:func:`cpmp.progress.
    expected_progress` of the scaled features: the offline evaluation's label, whatever
    labels the bank trains on). Activations of unknown MPs or variables are left out, so a
    node may get no rows.

    Args:
        graphs: the fit's sequence graphs.
        predictor: the bank (its scaler fitted).
        demos: the validation demonstrations.

    Returns:
        One :class:`~cpmp.predictors.NodeData` per node (``x (P, d)``, ``target (P,)``).
    """
    samples: dict[tuple[str, str], tuple[list[np.ndarray], list[np.ndarray]]] = {}
    for demo in demos:
        scaled = predictor.scaler.transform(demo.features)
        for v in sorted(graphs):
            if v not in demo.variables:
                continue
            for seg in demo.segments(v):
                if seg.mp not in graphs[v].nodes:
                    continue
                x, y = samples.setdefault((v, seg.mp), ([], []))
                x.append(scaled[seg.start : seg.stop])
                y.append(expected_progress(x[-1], seg.time))
    out = []
    dt, d = predictor.dtype_, predictor.n_features
    for v, mp in predictor.node_keys:
        x, y = samples.get((v, mp), ([], []))
        out.append(
            NodeData(
                key=(v, mp),
                x=torch.as_tensor(np.concatenate(x) if x else np.zeros((0, d)), dtype=dt),
                target=torch.as_tensor(np.concatenate(y) if y else np.zeros(0), dtype=dt),
            )
        )
    return out


def demo_progress(
    graphs: Mapping[str, SequenceGraph], data: Sequence[NodeData], n_samples: Sequence[int]
) -> list[dict[str, np.ndarray]]:
    """The fit's progress labels laid out along the demonstrations the ``graphs`` were built from.

    Every activation is labelled as its node trained on it: what
    :meth:`cpmp.sequencer.switching.Coupling.learn` measures the demonstrated switches with, so
    that it need not label them again.

    Args:
        graphs: the fit's sequence graphs.
        data: the fit's per-node training data (:func:`node_training_data`).
        n_samples: each demonstration's number of samples.

    Returns:
        Per demonstration, per variable, the labels ``(n,)``.
    """
    out = [{v: np.zeros(n) for v in graphs} for n in n_samples]
    for node in data:
        v, mp = node.key
        for a, labels in zip(graphs[v].activations[mp], node.labels, strict=True):
            out[a.demo][v][a.start : a.stop] = labels
    return out


def nonfinite_parameters(module: torch.nn.Module) -> list[str]:
    """Names of the floating-point parameters and buffers of ``module`` holding NaN or inf."""
    return [
        name
        for name, value in module.state_dict().items()
        if value.is_floating_point() and not torch.isfinite(value).all()
    ]


DEGENERATE_PATH = 1e-9
"""Total L1 path length (scaled features) below which a node's activations count as still."""
UNSEPARATED_MAE = 0.2
"""Mean absolute progress error on a node's own training data above which it is reported."""


GLITCH_SAMPLES = 2
"""Activations of at most this many samples between two other MPs are reported as likely
label glitches."""


TYPO_EDITS = 2
"""A node with one activation whose name is at most this many edits (and at most a third of the
longer name) from another MP of its variable is reported as a likely label typo."""


def edit_distance(a: str, b: str) -> int:
    """The optimal-string-alignment distance between two strings.

    Insertions, deletions, substitutions and swaps of two neighbouring letters count one edit
    each (``clsoe`` -> ``close`` is 1).

    Args:
        a: one string.
        b: the other.

    Returns:
        The number of edits.
    """
    rows = [list(range(len(b) + 1))]
    for i, ca in enumerate(a, 1):
        row = [i] + [0] * len(b)
        for j, cb in enumerate(b, 1):
            row[j] = min(rows[-1][j] + 1, row[j - 1] + 1, rows[-1][j - 1] + (ca != cb))
            if i > 1 and j > 1 and ca == b[j - 2] and a[i - 2] == cb:
                row[j] = min(row[j], rows[-2][j - 2] + 1)
        rows.append(row)
    return rows[-1][-1]


def typo_warnings(graphs: Mapping[str, SequenceGraph], demos: Sequence[Demonstration]) -> list[str]:
    """One message per node that looks like a mistyped name of another MP of its variable.

    A node with a single activation whose name is within :data:`TYPO_EDITS` edits of another
    node's (``clsoe`` beside ``close``): a typo in one demonstration's labels makes a node with
    one activation and new edges, which the sequencer then tries to reach.

    Args:
        graphs: the fitted graphs (their activations index ``demos``).
        demos: the training demonstrations.

    Returns:
        The messages, naming both MPs and the demonstration of the single activation.
    """
    out = []
    for v in sorted(graphs):
        acts = graphs[v].activations
        for mp in sorted(acts):
            if len(acts[mp]) != 1:
                continue
            near = [
                other
                for other in sorted(acts)
                if other != mp
                and len(acts[other]) > 1
                and edit_distance(mp, other) <= min(TYPO_EDITS, max(len(mp), len(other)) // 3)
            ]
            if near:
                a = acts[mp][0]
                name = demos[a.demo].name or f"demonstration {a.demo}"
                out.append(
                    f"node {v}/{mp}: its one activation (in {name}, from sample {a.start}) is "
                    f"named like {v}/{near[0]} ({len(acts[near[0]])} activations); if it is a "
                    f"typo, relabel it {near[0]!r}, or the sequencer learns an MP of one example"
                )
    return out


def glitch_warnings(
    graphs: Mapping[str, SequenceGraph], demos: Sequence[Demonstration]
) -> list[str]:
    """One message per node with a very short activation or a name that looks mistyped.

    An activation of at most :data:`GLITCH_SAMPLES` samples between two other MPs (A...A, B,
    C...C): such a node can hardly ever be entered in closed loop, and the sequencer would
    wait there. A likely typo in an MP's name: :func:`typo_warnings`.

    Args:
        graphs: the fitted graphs (their activations index ``demos``).
        demos: the training demonstrations.

    Returns:
        The messages, short activations first.
    """
    out = []
    for v in sorted(graphs):
        for mp, acts in sorted(graphs[v].activations.items()):
            short = [
                a
                for a in acts
                if a.stop - a.start <= GLITCH_SAMPLES
                and a.start > 0
                and a.stop < demos[a.demo].n_samples
            ]
            if short:
                a = short[0]
                name = demos[a.demo].name or f"demonstration {a.demo}"
                out.append(
                    f"node {v}/{mp}: its activation in {name} lasts {a.stop - a.start} "
                    f"sample(s) (from sample {a.start}); if that is a label glitch, relabel it, "
                    "or the sequencer may wait in this MP"
                )
    return out + typo_warnings(graphs, demos)


def fit_warnings(predictor: ProgressPredictor, data: Sequence[NodeData]) -> list[str]:
    """Degenerate nodes, one message each.

    Activations without feature change (their progress falls back to normalised time, which
    the features cannot show) and nodes whose fitted φ misses their own targets by more than
    :data:`UNSEPARATED_MAE` on average.
    """
    out = []
    with torch.no_grad():
        for i, node in enumerate(data):
            v, mp = node.key
            name = f"node {v}/{mp}"
            length = sum(path_length(a) for a in node.activations)
            if length < DEGENERATE_PATH:
                out.append(
                    f"{name}: the features do not change during its activations, so its "
                    "progress cannot be predicted from them; add a feature that moves while "
                    "this MP runs"
                )
                continue
            logit = predictor.node_logits(node.x, i)
            mae = float((torch.sigmoid(logit) - node.target).abs().mean())
            if mae > UNSEPARATED_MAE:
                out.append(
                    f"{name}: the predictor cannot fit its progress (training MAE {mae:.2f}); "
                    "its activations may look alike at start and end in these features"
                )
    return out


def _stride(n: int, k: int) -> np.ndarray:
    """Indices ``0, k, 2k, ...`` of ``n`` samples, always including the last one."""
    idx = np.arange(0, n, k)
    return idx if idx[-1] == n - 1 else np.append(idx, n - 1)
