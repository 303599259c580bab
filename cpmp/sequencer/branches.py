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

**The start** is the same choice out of a virtual root node (:class:`StartChoice`, the default
``start_rule="learned"``): every demonstration's first state is one example, labelled with its
combination of initial MPs, and the most probable demonstrated combination starts the episode.
Features that never separate the demonstrated starts (an arm's home jitter, a distractor, a
context quantity that decides something later) weigh about nothing (:func:`separability`), so
only what told the demonstrated starts apart decides.

**Staying** is a choice too. While a cycle repeats, the variable that waits across it (the bowl
held out in ``hold``) sees, between two repetitions, a state much like the one in which it moved
on after the last. Every switch of another variable is a moment the demonstrator decided
something; the states at which a variable kept its MP then and through the next such moment
(its own switch did not come first: it was not waiting for this one) are examples of
:data:`STAY` (:func:`stay_examples`). A fit keeps
them for the nodes where the progress predictor alone would have switched at one of them (a
transition's ``p`` above the threshold), and the choice then has one more class: while
:data:`STAY` is the most probable, no transition of that node fires (a ``hold`` note says so).
What tells staying from going is often two features together (peg's holder goes once the
peg's depth reaches the hole's), so a stay choice also keeps each feature by the separation it
adds, to those that separate better, in telling staying from going (:func:`added_separation`).

:class:`BranchChoices` holds one per such node. A fit stores it in the checkpoint; built from a
coupling alone (:meth:`BranchChoices.learn` without stays), it has the branching nodes only.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from itertools import pairwise
from typing import NamedTuple

import numpy as np

from cpmp.data import Demonstration
from cpmp.records import JsonValue
from cpmp.sequencer.motion import without_ambient
from cpmp.sequencer.switching import Coupling

STAY = "(stay)"
"""The choice of keeping the current MP (the demonstrator stayed in such states)."""
MIN_SPREAD = 0.01
"""The least within-class spread [training ranges] :func:`separability` assumes."""
L2 = 1e-4
"""The L2 penalty on the weights, per example (features in training ranges)."""
_NEWTON_STEPS = 50
SOFT_POWER = 0.5
"""The start and every stay choice weigh features by the square root of their
:func:`separability` (a branch choice among successors by separability itself). The start's
examples are one first state per demonstration, so separability rests on a handful of states,
and the softer weighting keeps every separating feature in play when each separates only some
of the starts (in the simulator box width decides one strategy and depth the other two). A stay
choice's :data:`STAY` examples come from across the whole activation, so every feature the
activation moves spreads widely within that class and separates little on its own: what tells
staying from going is often a combination (at peg's ``hold``, the peg's depth against the
hole's, which alone separates nothing), and a stay choice also keeps each feature by the
separation it adds to those that separate better (:func:`added_separation`, on staying against
going).

Every choice (the start, stay choices, branch choices among successors) leaves out the ambient
features (:attr:`~cpmp.sequencer.switching.Coupling.ambient`, moving alike under every MP and
unbent by its switches: the world's drift, not the task's state;
:func:`~cpmp.sequencer.motion.without_ambient`): its examples come from different
demonstrations and moments, so a drift that differs between them (a light level, a
table-height estimate) separates them by chance."""
MIN_ENTRY = 0.05
"""The least demonstrated entry :func:`entry_scales` divides by (a factor of at most 20)."""


class LinearChoice(NamedTuple):
    """A multinomial logistic regression on separability-weighted features (:func:`learn_choice`).

    Attributes:
        center: ``(d,)`` mean of the examples' weighted, scaled features.
        scale: ``(d,)`` multiplier to weighted training-range units (0 for constant features
            and for features that do not separate the classes).
        weights: ``(K, d)`` per class, on centred weighted features.
        bias: ``(K,)`` per class.
    """

    center: np.ndarray
    scale: np.ndarray
    weights: np.ndarray
    bias: np.ndarray

    def probabilities(self, x: np.ndarray) -> np.ndarray:
        """The probability of each class at features ``x (..., d)``: ``(..., K)``, summing to 1."""
        z = (np.asarray(x, dtype=np.float64) * self.scale - self.center) @ self.weights.T
        z = z + self.bias
        z = z - z.max(axis=-1, keepdims=True)
        e = np.exp(z)
        return e / e.sum(axis=-1, keepdims=True)

    def to_dict(self) -> dict[str, JsonValue]:
        """JSON/checkpoint-friendly form."""
        return {k: np.asarray(v).tolist() for k, v in self._asdict().items()}

    @classmethod
    def from_dict(cls, row: Mapping[str, JsonValue]) -> LinearChoice:
        """Inverse of :meth:`to_dict`."""
        return cls(*(np.asarray(row[k], dtype=np.float64) for k in cls._fields))


def learn_choice(
    states: np.ndarray,
    y: np.ndarray,
    k: int,
    feature_range: np.ndarray,
    power: float = 1.0,
    stay: int | None = None,
) -> LinearChoice:
    """Fit the choice among ``k`` classes from examples ``states (n, d)`` of classes ``y (n,)``.

    Features are put in units of their training range ``feature_range (d,)`` (range 0: left
    out), weighted by how well each separates the classes (:func:`separability`; with
    ``stay``, the index of the :data:`STAY` class, the larger of that and the separation it
    adds to telling staying from going, :func:`added_separation`) to the power ``power``, and
    a multinomial logistic regression (:func:`fit_softmax`) is fitted on them.
    """
    r = np.asarray(feature_range, dtype=np.float64)
    scale = np.divide(1.0, r, out=np.zeros_like(r), where=r > 0)
    z = np.asarray(states, dtype=np.float64) * scale
    weight = separability(z, y, k)
    if stay is not None:
        weight = np.maximum(weight, added_separation(z, (y != stay).astype(int), 2))
    weight = weight**power
    z = z * weight
    center = z.mean(axis=0)
    weights, bias = fit_softmax(z - center, y, k)
    return LinearChoice(center, scale * weight, weights, bias)


@dataclass(frozen=True, eq=False)
class BranchChoice:
    """The learned choice among the successors of one node.

    Attributes:
        variable: the control variable.
        source: the branching MP.
        targets: the demonstrated successors (sorted).
        counts: how many demonstrated switches went to each target.
        model: the fitted choice over :attr:`targets`.
    """

    variable: str
    source: str
    targets: list[str]
    counts: list[int]
    model: LinearChoice

    def probabilities(self, x: np.ndarray) -> np.ndarray:
        """The probability of each target in :attr:`targets` at features ``x (..., d)``.

        Returns:
            ``(..., K)``, summing to 1 over the last axis.
        """
        return self.model.probabilities(x)

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
        examples = ", ".join(f"{s} x{n}" for s, n in zip(self.targets, self.counts, strict=True))
        names = _weighs_most(self.model, feature_names, top)
        return (
            f"  {self.source} -> {' | '.join(self.targets)} chosen from the state "
            f"({examples} demonstrated; weighs most: {names})"
        )


def _weighs_most(model: LinearChoice, feature_names: Sequence[str] | None, top: int) -> str:
    """The ``top`` features whose weights differ most between the classes, comma-separated."""
    spread = np.ptp(model.weights, axis=0)
    order = np.argsort(-spread, kind="stable")[:top]
    names = [
        feature_names[j] if feature_names is not None else f"x[{j}]" for j in order if spread[j] > 0
    ]
    return ", ".join(names) or "-"


@dataclass(frozen=True, eq=False)
class StartChoice:
    """The learned choice among the demonstrated combinations of initial MPs (the start).

    Attributes:
        combinations: each demonstrated combination, variable -> initial MP (sorted).
        counts: how many demonstrations started with each.
        model: the fitted choice over :attr:`combinations` (``None``: one combination only).
    """

    combinations: list[dict[str, str]]
    counts: list[int]
    model: LinearChoice | None

    @classmethod
    def learn(
        cls,
        demos: Sequence[Demonstration],
        variables: Sequence[str],
        feature_range: np.ndarray,
        ambient: np.ndarray | None = None,
    ) -> StartChoice:
        """Learn the start from each demonstration's first state and initial MPs.

        Args:
            demos: the fit's demonstrations (at least one).
            variables: the control variables.
            feature_range: ``(d,)`` each feature's range in the training data.
            ambient: ``(d,)`` bool, features left out (:func:`without_ambient`); ``None``: none.
        """
        keys = [tuple(str(d.labels[v][0]) for v in variables) for d in demos]
        classes = sorted(set(keys))
        counts = [keys.count(c) for c in classes]
        combinations = [dict(zip(variables, c, strict=True)) for c in classes]
        if len(classes) < 2:
            return cls(combinations, counts, None)
        y = np.array([classes.index(c) for c in keys])
        states = np.stack([np.asarray(d.features[0], dtype=np.float64) for d in demos])
        model = learn_choice(
            states, y, len(classes), without_ambient(feature_range, ambient), SOFT_POWER
        )
        return cls(combinations, counts, model)

    def probabilities(self, x: np.ndarray) -> np.ndarray:
        """The probability of each of :attr:`combinations` at the first features ``x (..., d)``."""
        if self.model is None:
            return np.ones((*np.shape(x)[:-1], 1))
        return self.model.probabilities(x)

    def describe(self, feature_names: Sequence[str] | None = None, top: int = 3) -> str:
        """One line: the demonstrated starts and the features that weigh most in the choice."""
        starts = "; ".join(
            f"{', '.join(f'{v}={mp}' for v, mp in sorted(c.items()))} x{n}"
            for c, n in zip(self.combinations, self.counts, strict=True)
        )
        if self.model is None:
            return f"start: {starts} (the one demonstrated start)"
        return f"start chosen from the first state: {starts} (weighs most: " + (
            f"{_weighs_most(self.model, feature_names, top)})"
        )

    def to_dict(self) -> dict[str, JsonValue]:
        """JSON/checkpoint-friendly form."""
        return {
            "combinations": [dict(c) for c in self.combinations],
            "counts": list(self.counts),
            "model": None if self.model is None else self.model.to_dict(),
        }

    @classmethod
    def from_dict(cls, row: Mapping[str, JsonValue]) -> StartChoice:
        """Inverse of :meth:`to_dict`."""
        model = row.get("model")
        return cls(
            [{str(v): str(mp) for v, mp in c.items()} for c in row["combinations"]],
            [int(n) for n in row["counts"]],
            None if model is None else LinearChoice.from_dict(model),
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
    within, between = _scatter(z, y, k)
    ratio = np.sqrt(np.diag(between) / np.diag(within))
    top = float(ratio.max(initial=0.0))
    return ratio / top if top > 0 else np.ones_like(ratio)


def _scatter(z: np.ndarray, y: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """The within- and between-class matrices ``(W, B)``, each ``(d, d)``, of ``z (n, d)``.

    ``B`` is the between-class scatter per degree of freedom, ``W`` the pooled within-class
    covariance with :data:`MIN_SPREAD` squared added to its diagonal. Their diagonals give
    :func:`separability`; the Fisher criterion of a feature set ``S`` is
    ``trace(W[S, S]⁻¹ B[S, S])`` (for one feature, the square of its unnormalised
    separability).
    """
    d = z.shape[1]
    mean = z.mean(axis=0)
    between = np.zeros((d, d))
    within = np.zeros((d, d))
    for i in range(k):
        zi = z[y == i]
        if not len(zi):
            continue
        offset = (zi.mean(axis=0) - mean)[:, None]
        between += len(zi) * offset @ offset.T
        centred = zi - zi.mean(axis=0)
        within += centred.T @ centred
    within = within / max(len(z) - k, 1) + MIN_SPREAD**2 * np.eye(d)
    return within, between / max(k - 1, 1)


def added_separation(z: np.ndarray, y: np.ndarray, k: int) -> np.ndarray:
    """Per feature, the separation it adds to those that separate better (forward selection).

    A feature that separates the classes only together with another (peg's depth against the
    hole's depth: go where they are equal, stay where the peg is short of it) weighs about
    nothing by :func:`separability`. Here the features enter one at a time (forward selection
    by the Fisher criterion ``J`` of a feature set, :func:`_scatter`): first the one that
    separates best alone (weight 1), then each time the one that adds most to ``J`` of those
    in, weighing ``sqrt(ΔJ / J)`` at its entry (at most 1). A partner that completes a
    combination enters early with a large weight; a feature that only repeats what the others
    say, or jitter, enters late with a small one. Features constant over the examples weigh 0.
    The arguments are :func:`separability`'s (features ``z (n, d)`` in training ranges, class
    indices ``y (n,)`` of ``k`` classes), and so is the result: ``(d,)`` weights in ``[0, 1]``.
    """
    d = z.shape[1]
    out = np.zeros(d)
    within, between = _scatter(z, y, k)

    def fisher(s: list[int]) -> float:
        return float(np.trace(np.linalg.solve(within[np.ix_(s, s)], between[np.ix_(s, s)])))

    alone = np.array([fisher([j]) for j in range(d)])
    best = int(np.argmax(alone))
    if alone[best] <= 0:
        return out
    chosen, current = [best], float(alone[best])
    out[best] = 1.0
    rest = [j for j in range(d) if j != best and np.ptp(z[:, j]) > 0]
    while rest:
        gains = [max(fisher([*chosen, j]) - current, 0.0) for j in rest]
        i = int(np.argmax(gains))
        j = rest.pop(i)
        out[j] = min(1.0, float(np.sqrt(gains[i] / current)))
        chosen.append(j)
        current += gains[i]
    return out


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
        start: the learned start (``None``: not learned, e.g. a checkpoint written before it).
        entry_scale: ``(variable, source, target)`` -> the factor on the entry probability
            ``1 - φ_target`` of that switch, for the switches whose demonstrated entries the
            progress predictor does not see as beginnings (a node re-entered in a loop starts
            where its earlier activations ended; see :func:`entry_scales`); 1 for the others.
    """

    choices: dict[tuple[str, str], BranchChoice]
    start: StartChoice | None = None
    entry_scale: dict[tuple[str, str, str], float] = field(default_factory=dict)

    @classmethod
    def learn(
        cls,
        coupling: Coupling,
        feature_range: np.ndarray,
        stays: Mapping[tuple[str, str], Sequence[np.ndarray]] | None = None,
        start: StartChoice | None = None,
        entry_scale: Mapping[tuple[str, str, str], float] | None = None,
    ) -> BranchChoices:
        """One choice per node that branches or whose demonstrator stayed where φ says go.

        Args:
            coupling: the learned coupling, whose switch instances are the examples (and
                whose ambient features every choice leaves out).
            feature_range: ``(d,)`` each feature's range in the training data (features of
                range 0 are left out).
            stays: ``(variable, MP)`` -> states ``(d,)`` at which the demonstrator kept the MP
                although the progress predictor would have switched (:func:`stay_examples`,
                filtered by the fit); those nodes get :data:`STAY` as one more choice.
            start: the learned start (:meth:`StartChoice.learn`), kept as it is.
            entry_scale: the switches' entry factors (:func:`entry_scales`), kept as they are.

        Returns:
            The choices (none for a coupling without switch instances).
        """
        stays = stays or {}
        choices = {}
        ranges = without_ambient(feature_range, coupling.ambient)
        for (v, source), instances in sorted(coupling.instances.items()):
            kept = [np.asarray(x, dtype=np.float64) for x in stays.get((v, source), [])]
            states = [inst.state for inst in instances] + kept
            labels = [inst.target for inst in instances] + [STAY] * len(kept)
            targets = sorted(set(labels))
            if len(targets) < 2:
                continue
            y = np.array([targets.index(t) for t in labels])
            power = SOFT_POWER if kept else 1.0
            stay = targets.index(STAY) if kept else None
            model = learn_choice(np.stack(states), y, len(targets), ranges, power, stay)
            counts = [int(np.sum(y == i)) for i in range(len(targets))]
            choices[(v, source)] = BranchChoice(v, source, targets, counts, model)
        return cls(choices, start, dict(entry_scale or {}))

    def to_dict(self) -> list[dict[str, JsonValue]]:
        """JSON/checkpoint-friendly form."""
        return [
            {
                "variable": c.variable,
                "source": c.source,
                "targets": list(c.targets),
                "counts": list(c.counts),
                **c.model.to_dict(),
            }
            for _, c in sorted(self.choices.items())
        ]

    @classmethod
    def from_dict(
        cls,
        rows: Sequence[Mapping[str, JsonValue]],
        start: Mapping[str, JsonValue] | None = None,
        entry_scale: Sequence[Sequence[str | float]] | None = None,
    ) -> BranchChoices:
        """Inverse of :meth:`to_dict`, :meth:`StartChoice.to_dict` and :meth:`entry_rows`."""
        choices = {}
        for r in rows:
            c = BranchChoice(
                str(r["variable"]),
                str(r["source"]),
                [str(t) for t in r["targets"]],
                [int(n) for n in r["counts"]],
                LinearChoice.from_dict(r),
            )
            choices[(c.variable, c.source)] = c
        scales = {(str(v), str(a), str(b)): float(g) for v, a, b, g in entry_scale or []}
        return cls(choices, None if start is None else StartChoice.from_dict(start), scales)

    def entry_rows(self) -> list[list[str | float]]:
        """:attr:`entry_scale` as ``[variable, source, target, factor]`` rows (sorted)."""
        return [[v, a, b, g] for (v, a, b), g in sorted(self.entry_scale.items())]

    def get(self, variable: str, source: str) -> BranchChoice | None:
        """The choice at ``variable``'s node ``source``, ``None`` if it does not branch."""
        return self.choices.get((variable, source))

    def describe(self, variable: str, feature_names: Sequence[str] | None = None) -> list[str]:
        """One line per branching node of ``variable`` (:meth:`BranchChoice.describe`)."""
        return [
            c.describe(feature_names) for (v, _), c in sorted(self.choices.items()) if v == variable
        ]


def entry_scales(
    exit_phi: Mapping[tuple[str, str, str], np.ndarray],
    entry: Mapping[tuple[str, str, str], np.ndarray],
    threshold: float,
) -> dict[tuple[str, str, str], float]:
    """The entry factors of the switches the progress predictor would not make as demonstrated.

    For each demonstrated switch ``variable: source -> target``, the fitted φ at the states
    where the demonstrator made it gives ``p = φ_source · (1 - φ_target)``. Where the median of
    ``p`` stays at or below ``threshold``, the rule would not make the switch where the
    demonstrator did. When it is the entry ``1 - φ_target`` that is low there (the target is
    re-entered in a loop, starting where its earlier activations ended, so its progress reads
    "done"), the entry is read relative to its demonstrated value: it is multiplied by the
    inverse of its median at the demonstrated switches (the product capped at 1 at run
    time), so that the switch fires as the source ends, as demonstrated.

    Args:
        exit_phi: ``(variable, source, target)`` -> φ of ``source`` at each demonstrated switch.
        entry: the same keys -> ``1 - φ_target`` at the same states.
        threshold: the switching rule's threshold.

    Returns:
        ``(variable, source, target)`` -> factor > 1, only for the switches that need one.
    """
    out = {}
    for key, e in sorted(entry.items()):
        e = np.asarray(e, dtype=np.float64)
        p = np.asarray(exit_phi[key], dtype=np.float64) * e
        level = float(np.median(e))
        if float(np.median(p)) <= threshold and level < threshold:
            out[key] = 1.0 / max(level, MIN_ENTRY)
    return out


def stay_examples(
    demos: Sequence[Demonstration], variables: Sequence[str]
) -> dict[tuple[str, str], list[np.ndarray]]:
    """The states at which each variable kept its MP while another variable switched.

    Another variable's switch is a moment the demonstrator decided something. A variable that
    kept its MP then and also through the next such moment chose to stay — between two
    repetitions of a cycle, the waiting variable does so; at peg's half-inserted deep hole, the
    holder keeps holding while the inserter releases and pushes. A variable whose own switch
    comes before the next moment was waiting for this one (it switched in response to it):
    that moment is no stay, nor is one at which it switched too. How far the variable is
    through its MP does not matter: a node whose last part is short in the features (the
    holder's ``hold`` while the peg is pushed home) is still staying there.

    Args:
        demos: the fit's demonstrations.
        variables: the control variables.

    Returns:
        ``(variable, MP)`` -> the features ``(d,)`` at each such moment (the first sample after
        the other variable's switch).
    """
    out: dict[tuple[str, str], list[np.ndarray]] = {}
    for demo in demos:
        labels = {v: np.asarray(demo.labels[v]) for v in variables}
        changed = {v: np.flatnonzero(lab[1:] != lab[:-1]) + 1 for v, lab in labels.items()}
        for v in variables:
            others = np.unique(
                np.concatenate([changed[u] for u in variables if u != v] + [np.zeros(0, int)])
            )
            own = changed[v]
            # the last moment has no next one to stay through
            for i, following in pairwise(others):
                later = own[own >= i]
                if len(later) and later[0] == i:
                    continue  # it switched at this moment too
                if not len(later) or later[0] >= following:
                    out.setdefault((v, str(labels[v][i])), []).append(demo.features[i].copy())
    return out


__all__ = [
    "L2",
    "STAY",
    "BranchChoice",
    "BranchChoices",
    "LinearChoice",
    "StartChoice",
    "added_separation",
    "entry_scales",
    "fit_softmax",
    "learn_choice",
    "stay_examples",
]
