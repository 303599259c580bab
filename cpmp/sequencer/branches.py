"""Which way a branching node goes, learned from the states where the demonstrator left it.

A node with two or more demonstrated successors is a choice — at a cycle's exit, "again" or
"move on" (``pour -> scoop`` while soup remains, ``pour -> rest`` once the bowl is full). The
transition probabilities ``p_s = φ_current · (1 - φ_s)`` cannot make it when the successors'
entries look alike (both start where the cycle ends) and what decides it is a quantity that
does not move while either successor runs, which cpmp's path-weighted progress de-weights.

:class:`BranchChoice` learns the choice from the labels alone: every demonstrated switch out of
the node (:attr:`cpmp.sequencer.switching.Coupling.instances`: the features at the switch and
where it went) is one example, and a multinomial logistic regression with an L2 penalty on the
features in units of their training range says which successor the demonstrator took in states
like the current one. The transition rule then lets only the most probable successor (among
those demonstrated in the current context) fire; the others are not candidates at that tick.
Nodes with one successor, or whose demonstrations always went the same way, have no choice and
nothing changes for them.

**Staying** is a choice too. While a cycle repeats, the variable that waits across it (the bowl
held out in ``hold``) sees, between two repetitions, a state much like the one in which it moved
on after the last. Every switch of another variable is a moment the demonstrator decided
something; the states at which a variable kept its MP then, while clearly inside it (its label
below ``1 - progress_margin``), are examples of :data:`STAY` (:func:`stay_examples`). A fit keeps
them for the nodes where the progress predictor alone would have switched at one of them (a
transition's ``p`` above the threshold), and the choice then has one more class: while
:data:`STAY` is the most probable, no transition of that node fires (a ``hold`` note says so).

:class:`BranchChoices` holds one per such node. A fit stores it in the checkpoint; built from a
coupling alone (:meth:`BranchChoices.learn` without stays), it has the branching nodes only.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from cpmp.data import Demonstration
from cpmp.sequencer.switching import Coupling

STAY = "(stay)"
"""The choice of keeping the current MP (the demonstrator stayed in such states)."""
MIN_SPREAD = 0.01
"""The least within-class spread [training ranges] :func:`separability` assumes."""
L2 = 1e-4
"""The L2 penalty on the weights, per example (features in training ranges)."""
_NEWTON_STEPS = 50


@dataclass(frozen=True, eq=False)
class BranchChoice:
    """The learned choice among the successors of one node.

    Attributes:
        variable: the control variable.
        source: the branching MP.
        targets: the demonstrated successors (sorted).
        counts: how many demonstrated switches went to each target.
        center: ``(d,)`` mean of the examples' scaled features.
        scale: ``(d,)`` multiplier to training-range units (0 for constant features).
        weights: ``(K, d)`` per target, on centred scaled features.
        bias: ``(K,)`` per target.
    """

    variable: str
    source: str
    targets: list[str]
    counts: list[int]
    center: np.ndarray
    scale: np.ndarray
    weights: np.ndarray
    bias: np.ndarray

    def probabilities(self, x: np.ndarray) -> np.ndarray:
        """The probability of each target in :attr:`targets` at features ``x (..., d)``.

        Returns:
            ``(..., K)``, summing to 1 over the last axis.
        """
        z = (np.asarray(x, dtype=np.float64) * self.scale - self.center) @ self.weights.T
        z = z + self.bias
        z = z - z.max(axis=-1, keepdims=True)
        e = np.exp(z)
        return e / e.sum(axis=-1, keepdims=True)

    def choose(self, x: np.ndarray, among: Sequence[str]) -> str | None:
        """The most probable of ``among`` and :data:`STAY` (if learned) at ``x (d,)``.

        Returns:
            A target, :data:`STAY`, or ``None`` if none of ``among`` is known.
        """
        known = [s for s in among if s in self.targets]
        if known and STAY in self.targets:
            known.append(STAY)
        if not known:
            return None
        prob = self.probabilities(x)
        return max(known, key=lambda s: (prob[self.targets.index(s)], s))

    def describe(self, feature_names: Sequence[str] | None = None, top: int = 3) -> str:
        """One line: the examples per target and the features that weigh most in the choice."""
        spread = np.ptp(self.weights, axis=0)
        order = np.argsort(-spread, kind="stable")[:top]
        names = [
            feature_names[j] if feature_names is not None else f"x[{j}]"
            for j in order
            if spread[j] > 0
        ]
        examples = ", ".join(f"{s} x{n}" for s, n in zip(self.targets, self.counts, strict=True))
        return (
            f"  {self.source} -> {' | '.join(self.targets)} chosen from the state "
            f"({examples} demonstrated; weighs most: {', '.join(names) or '-'})"
        )


def separability(z: np.ndarray, y: np.ndarray, k: int) -> np.ndarray:
    """Per feature, how well it separates the classes: ``sqrt`` of its ANOVA F ratio, at most 1.

    The between-class spread of each feature over its pooled within-class spread (a floor of
    :data:`MIN_SPREAD` training ranges), normalised so that the best feature weighs 1. A feature
    whose values do not differ between the classes (position jitter among a handful of
    examples) weighs about nothing, so it cannot decide the choice.

    Args:
        z: ``(n, d)`` features in training ranges.
        y: ``(n,)`` class indices.
        k: the number of classes.

    Returns:
        ``(d,)`` weights in ``[0, 1]``.
    """
    mean = z.mean(axis=0)
    between = np.zeros(z.shape[1])
    within = np.zeros(z.shape[1])
    for i in range(k):
        zi = z[y == i]
        between += len(zi) * (zi.mean(axis=0) - mean) ** 2
        within += ((zi - zi.mean(axis=0)) ** 2).sum(axis=0)
    within = within / max(len(z) - k, 1) + MIN_SPREAD**2
    ratio = np.sqrt(between / max(k - 1, 1) / within)
    top = float(ratio.max(initial=0.0))
    return ratio / top if top > 0 else np.ones_like(ratio)


def fit_softmax(z: np.ndarray, y: np.ndarray, k: int, l2: float = L2) -> tuple[np.ndarray, ...]:
    """L2-penalised multinomial logistic regression by Newton's method.

    Args:
        z: ``(n, d)`` inputs.
        y: ``(n,)`` class indices in ``[0, k)``.
        k: the number of classes.
        l2: the penalty ``l2 * n / 2 * |W|^2`` (and a thousandth of it on the bias, which
            keeps the Hessian positive definite).

    Returns:
        ``(weights (k, d), bias (k,))``.
    """
    n, d = z.shape
    a = np.concatenate([z, np.ones((n, 1))], axis=1)
    theta = np.zeros((k, d + 1))
    penalty = np.full(d + 1, l2 * n)
    penalty[-1] *= 1e-3
    onehot = np.eye(k)[y]
    for _ in range(_NEWTON_STEPS):
        logits = a @ theta.T
        logits -= logits.max(axis=1, keepdims=True)
        p = np.exp(logits)
        p /= p.sum(axis=1, keepdims=True)
        grad = ((p - onehot).T @ a) + penalty * theta
        hess = np.zeros((k, d + 1, k, d + 1))
        for i in range(k):
            for j in range(k):
                w = p[:, i] * ((i == j) - p[:, j])
                hess[i, :, j, :] = (a * w[:, None]).T @ a
            hess[i, :, i, :] += np.diag(penalty)
        step = np.linalg.solve(hess.reshape(k * (d + 1), -1), grad.reshape(-1))
        theta -= step.reshape(k, d + 1)
        if float(np.abs(step).max()) < 1e-10:
            break
    return theta[:, :d], theta[:, d]


@dataclass(frozen=True)
class BranchChoices:
    """The learned choice of every branching node (see module doc).

    Attributes:
        choices: ``(variable, source)`` -> its :class:`BranchChoice`.
    """

    choices: dict[tuple[str, str], BranchChoice]

    @classmethod
    def learn(
        cls,
        coupling: Coupling,
        feature_range: np.ndarray,
        stays: Mapping[tuple[str, str], Sequence[np.ndarray]] | None = None,
    ) -> BranchChoices:
        """One choice per node that branches or whose demonstrator stayed where φ says go.

        Args:
            coupling: the learned coupling, whose switch instances are the examples.
            feature_range: ``(d,)`` each feature's range in the training data (features of
                range 0 are left out).
            stays: ``(variable, MP)`` -> states ``(d,)`` at which the demonstrator kept the MP
                although the progress predictor would have switched (:func:`stay_examples`,
                filtered by the fit); those nodes get :data:`STAY` as one more choice.

        Returns:
            The choices (none for a coupling without switch instances).
        """
        r = np.asarray(feature_range, dtype=np.float64)
        scale = np.divide(1.0, r, out=np.zeros_like(r), where=r > 0)
        stays = stays or {}
        choices = {}
        for (v, source), instances in sorted(coupling.instances.items()):
            kept = [np.asarray(x, dtype=np.float64) for x in stays.get((v, source), [])]
            states = [inst.state for inst in instances] + kept
            labels = [inst.target for inst in instances] + [STAY] * len(kept)
            targets = sorted(set(labels))
            if len(targets) < 2:
                continue
            y = np.array([targets.index(t) for t in labels])
            z = np.stack(states) * scale
            weight = separability(z, y, len(targets))
            z = z * weight
            center = z.mean(axis=0)
            weights, bias = fit_softmax(z - center, y, len(targets))
            counts = [int(np.sum(y == i)) for i in range(len(targets))]
            choices[(v, source)] = BranchChoice(
                v, source, targets, counts, center, scale * weight, weights, bias
            )
        return cls(choices)

    def to_dict(self) -> list[dict[str, Any]]:
        """JSON/checkpoint-friendly form."""
        return [
            {
                "variable": c.variable,
                "source": c.source,
                "targets": list(c.targets),
                "counts": list(c.counts),
                "center": c.center.tolist(),
                "scale": c.scale.tolist(),
                "weights": c.weights.tolist(),
                "bias": c.bias.tolist(),
            }
            for _, c in sorted(self.choices.items())
        ]

    @classmethod
    def from_dict(cls, rows: Sequence[Mapping[str, Any]]) -> BranchChoices:
        """Inverse of :meth:`to_dict`."""
        choices = {}
        for r in rows:
            c = BranchChoice(
                str(r["variable"]),
                str(r["source"]),
                [str(t) for t in r["targets"]],
                [int(n) for n in r["counts"]],
                np.asarray(r["center"], dtype=np.float64),
                np.asarray(r["scale"], dtype=np.float64),
                np.asarray(r["weights"], dtype=np.float64),
                np.asarray(r["bias"], dtype=np.float64),
            )
            choices[(c.variable, c.source)] = c
        return cls(choices)

    def get(self, variable: str, source: str) -> BranchChoice | None:
        """The choice at ``variable``'s node ``source``, ``None`` if it does not branch."""
        return self.choices.get((variable, source))

    def describe(self, variable: str, feature_names: Sequence[str] | None = None) -> list[str]:
        """One line per branching node of ``variable`` (:meth:`BranchChoice.describe`)."""
        return [
            c.describe(feature_names) for (v, _), c in sorted(self.choices.items()) if v == variable
        ]


def stay_examples(
    demos: Sequence[Demonstration],
    variables: Sequence[str],
    progress: Sequence[Mapping[str, np.ndarray]],
    margin: float,
) -> dict[tuple[str, str], list[np.ndarray]]:
    """The states at which each variable kept its MP while another variable switched.

    Another variable's switch is a moment the demonstrator decided something; a variable that
    kept its MP then, while less than ``1 - margin`` through it (its eq. 1 label), chose to
    stay — between two repetitions of a cycle, the waiting variable does so.

    Args:
        demos: the fit's demonstrations.
        variables: the control variables.
        progress: per demonstration, per variable, the fit's progress labels ``(n,)``.
        margin: a variable at least ``1 - margin`` through its MP is near its own switch, not
            staying.

    Returns:
        ``(variable, MP)`` -> the features ``(d,)`` at each such moment (the first sample after
        the other variable's switch).
    """
    out: dict[tuple[str, str], list[np.ndarray]] = {}
    for demo, done in zip(demos, progress, strict=True):
        labels = {v: np.asarray(demo.labels[v]) for v in variables}
        moments = sorted(
            {int(i) for v in variables for i in np.flatnonzero(labels[v][1:] != labels[v][:-1]) + 1}
        )
        for i in moments:
            for v in variables:
                lab = labels[v]
                if lab[i - 1] == lab[i] and float(done[v][i]) < 1.0 - margin:
                    out.setdefault((v, str(lab[i])), []).append(demo.features[i].copy())
    return out


__all__ = ["L2", "STAY", "BranchChoice", "BranchChoices", "fit_softmax", "stay_examples"]
