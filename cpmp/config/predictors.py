"""The options of every progress predictor (``conf/predictor/``), one dataclass per kind.

The predictors themselves live in :mod:`cpmp.predictors` (``config_class`` names the class
here); the options live apart so that they can be read and checked without importing torch.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

from cpmp.config.validation import OptionValue, finite_number
from cpmp.errors import ConfigError
from cpmp.progress import PATH_NOISE

if TYPE_CHECKING:
    import torch

SCALINGS = ("global", "none", "minmax", "standard")
"""Values of ``feature_scaling`` (see :class:`cpmp.predictors.FeatureScaler`)."""
ACTIVATIONS = ("tanh", "relu", "silu")
"""Values of :attr:`MLPConfig.activation`."""
SKLEARN_SOLVERS = ("newton-cholesky", "lbfgs", "newton-cg")
"""scikit-learn solvers that leave the intercept unpenalised, as ``klr`` does."""


DTYPES = ("auto", "float64", "float32")
"""The predictors' ``dtype`` option values."""
FLOAT32_FROM_SAMPLES = 50_000
"""Training samples from which ``dtype="auto"`` fits in ``float32`` (half the bytes per kernel
block, a faster fit; docs/benchmarks.md measures it); smaller fits keep ``float64``."""


@dataclass
class PredictorConfig:
    """Options shared by every predictor.

    Attributes:
        feature_scaling: ``global`` (default: all features over one common factor, so units
            do not matter), ``none`` (the paper), ``minmax`` or ``standard`` (see
            :class:`~cpmp.predictors.FeatureScaler`); the fitted scaling is stored in the
            checkpoint and applied to every input.
        dtype: ``auto`` (default), ``float64`` or ``float32``: the predictors' floating-point
            type. ``auto`` fits in ``float64`` below :data:`FLOAT32_FROM_SAMPLES` training
            samples and in ``float32`` from there on (:func:`resolved_dtype`; the fit records
            the type it used in the checkpoint); a predictor built outside a fit with
            ``auto`` uses ``float64``.
        path_noise: ``auto`` (default) or ``none`` (the paper): with ``auto`` the L1 path of
            eq. 1, and the support points and feature weights that follow it, are measured
            on each training activation after removing the white noise estimated on it
            (:func:`cpmp.progress.denoise_trajectory`; a trajectory without detected noise is
            used as recorded), and so are the ranges of ``feature_scaling``; in a sequencer's
            fit the ambient features' drift is left out of that path too (held still: no
            progress, weight 0 in a ``path``-weighted kernel;
            :func:`cpmp.sequencer.fit_data.node_training_data`). ``none`` measures them on the
            features as recorded.
    """

    feature_scaling: str = "global"
    dtype: str = "auto"
    path_noise: str = "auto"

    def __post_init__(self) -> None:
        if self.path_noise not in PATH_NOISE:
            raise ConfigError(
                f"path_noise must be one of {', '.join(PATH_NOISE)}, got {self.path_noise!r}"
            )
        if self.feature_scaling not in SCALINGS:
            raise ConfigError(
                f"feature_scaling must be one of {', '.join(SCALINGS)}, "
                f"got {self.feature_scaling!r}"
            )
        if self.dtype not in DTYPES:
            raise ConfigError(f"dtype must be one of {', '.join(DTYPES)}, got {self.dtype!r}")

    def _number(self, name: str) -> float:
        return finite_number(getattr(self, name), f"predictor option {name}")

    def _positive(self, *names: str) -> None:
        for name in names:
            if not self._number(name) > 0:
                raise ConfigError(
                    f"predictor option {name} must be > 0, got {getattr(self, name)!r}"
                )

    def _non_negative(self, *names: str) -> None:
        for name in names:
            if self._number(name) < 0:
                raise ConfigError(
                    f"predictor option {name} must be >= 0, got {getattr(self, name)!r}"
                )

    def _integer(self, *names: str, allow_none: bool = False) -> None:
        """Whole-number options (counts); ``2.0`` is accepted as 2, ``2.5`` is an error."""
        for name in names:
            value = getattr(self, name)
            if value is None and allow_none:
                continue
            number = self._number(name)
            if number != int(number):
                raise ConfigError(f"predictor option {name} must be a whole number, got {value!r}")
            setattr(self, name, int(number))

    @property
    def torch_dtype(self) -> torch.dtype:
        """The torch dtype of :attr:`dtype`."""
        import torch  # lazy: cpmp.config is read before Hydra composition, without torch

        return torch.float32 if self.dtype == "float32" else torch.float64


def resolved_dtype(dtype: str, n_samples: int) -> str:
    """The floating-point type a fit on ``n_samples`` training samples uses for ``dtype``.

    ``float32`` or ``float64`` as given; ``auto``: ``float32`` from
    :data:`FLOAT32_FROM_SAMPLES` samples on, else ``float64``.
    """
    if dtype != "auto":
        return dtype
    return "float32" if n_samples >= FLOAT32_FROM_SAMPLES else "float64"


CHUNK_SIZE = 2**22
"""Default kernel block size (the bank's ``chunk_size``): kernel entries (samples x supports)
evaluated at a time by the Newton solve, the training loss and the logits of many samples.
4,194,304 float64 entries are 32 MiB; a block and its few temporaries of the same size bound
the fit's kernel memory, whatever the number of samples. A node whose whole kernel fits in one
block is solved exactly as a kernel held whole is (the same numbers, to the bit)."""
SUPPORT_CAP = 512
"""Default ``support_cap``: a node whose fixed rule places more support points than this has
them pooled (:func:`cpmp.predictors.klr.pool_supports`); a node at or below it keeps the
rule's points. The rule places about 2 per unit of path length per activation (4-20 per
activation on the synthetic
worlds), so only fits on tens to hundreds of demonstrations reach it."""
POOL_SIZE = 256
"""Default ``pool_size``: the most supports a pooled node keeps
(:func:`cpmp.predictors.klr.pool_supports`)."""
MERGE_SIMILARITY = 0.999
"""Default ``merge_similarity``: a pooled node stops adding supports once every one of its
rule's points has a chosen support of kernel value at least this (with γ = 4 and unit feature
weights: closer than about 0.016 in scaled features). Higher keeps more supports and predicts
progress better; docs/benchmarks.md measures the trade."""


@dataclass
class KLRConfig(PredictorConfig):
    """Options of ``klr`` / ``klr_full``.

    The defaults are cpmp's (``predictor=klr`` on the command line, ``"klr"`` in Python); the
    paper's kernel, ``predictor=paper``, sets ``feature_weighting: none``,
    ``feature_scaling: none`` and ``path_noise: none``.

    Attributes:
        gamma: RBF kernel parameter γ in ``exp(-γ ||s - x||²)`` (the paper's "kernel width 4.0").
        support_scale: support points per unit of L1 path length of an activation.
        min_support: minimum support points per activation (the paper uses 3).
        max_support: optional cap per activation (``None``: none).
        max_total_support: hard cap on the support points of all nodes together; a fit that
            would need more stops with a :class:`~cpmp.errors.ConfigError` before allocating
            anything (memory grows with samples x supports).
        l2: weight of the ``½ l2 ||w||²`` penalty added to each node's mean loss.
        bias: learn a per-node intercept (the usual logistic-regression intercept; ``False``
            gives exactly eq. 4, where φ tends to 0.5 far from every support point). On the
            synthetic task the intercept picks the right initial node in 6/6 held-out replays
            against 4/6 without it.
        max_iter: LBFGS iterations per optimiser step (trainer ``solver: lbfgs`` only).
        feature_weighting: ``path`` (default) or ``none`` (isotropic kernel, the paper):
            ``path`` weights, per node, each feature in the kernel by its share of the node's
            L1 path length (eq. 1 splits into one term per feature), so features that drive
            the node's progress count and features that stay constant while it runs (e.g. box
            size, the other arm) count little. Weights are ``max(d * share_j, weight_floor)``.
        weight_floor: smallest feature weight under ``path`` weighting.
        chunk_size: kernel entries (samples x supports) per block of the fit and of the
            logits of many samples (:data:`CHUNK_SIZE`): bounds the fit's kernel memory.
        support_cap: a node whose rule places more support points than this has them pooled
            (``klr`` only; :data:`SUPPORT_CAP`).
        pool_size: the most supports a pooled node keeps (:data:`POOL_SIZE`).
        merge_similarity: a pooled node stops adding supports once every rule point has a
            kept support of at least this kernel value (:data:`MERGE_SIMILARITY`).
    """

    gamma: float = 4.0
    support_scale: float = 2.0
    min_support: int = 3
    max_support: int | None = None
    max_total_support: int = 50_000
    l2: float = 1e-4
    bias: bool = True
    max_iter: int = 500
    feature_weighting: str = "path"
    weight_floor: float = 0.1
    chunk_size: int = CHUNK_SIZE
    support_cap: int = SUPPORT_CAP
    pool_size: int = POOL_SIZE
    merge_similarity: float = MERGE_SIMILARITY

    def __post_init__(self) -> None:
        super().__post_init__()
        self._integer("max_iter", "min_support", "max_total_support")
        self._integer("chunk_size", "support_cap", "pool_size")
        self._positive("chunk_size", "support_cap", "pool_size")
        if not 0.0 < self.merge_similarity < 1.0:
            raise ConfigError(
                "merge_similarity must be in (0, 1) (a kernel value), got "
                f"{self.merge_similarity!r}"
            )
        self._integer("max_support", allow_none=True)
        self._positive("gamma", "max_iter", "min_support", "max_total_support")
        self._non_negative("support_scale", "l2", "weight_floor")
        if self.feature_weighting not in ("none", "path"):
            raise ConfigError(
                f"feature_weighting must be 'none' or 'path', got {self.feature_weighting!r}"
            )
        if self.max_support is not None and self.max_support < self.min_support:
            raise ConfigError(
                f"max_support ({self.max_support}) must be >= min_support ({self.min_support})"
            )


REMOVED_OPTIONS: dict[str, dict[str, str]] = {
    "klr_sparse": {
        **dict.fromkeys(
            (
                "method",
                "candidate_scale",
                "min_candidates",
                "l1",
                "learn_positions",
                "learn_lengthscales",
                "epochs",
                "lr",
                "prune_tol",
                "refit",
            ),
            "klr_sparse's L1-penalised variant (method: l1) was removed; klr_sparse always "
            "follows the sparsity path, which these options do not tune",
        ),
        "start_share": (
            "start_share distilled the sequencer's isotropic start heads, which were removed "
            "with issue #32 (the sequencer option start_kernel); the bank's heads are its "
            "graph nodes, all on the sparsity path"
        ),
    },
}
"""Options a predictor kind no longer has, with why: :func:`predictor_config` names them as
removed rather than unknown."""
FIT_ONLY_REMOVED_OPTIONS: dict[str, frozenset[str]] = {"klr_sparse": frozenset({"start_share"})}
"""Removed options (:data:`REMOVED_OPTIONS`) that acted only while a bank was fitted, on heads
that only a removed sequencer option added: a saved bank holds whatever they did in its
weights, so :func:`saved_predictor_options` drops them from a checkpoint's options, whatever
their value."""


@dataclass
class SparseKLRConfig(KLRConfig):
    """Options of ``klr_sparse`` (on top of :class:`KLRConfig`, whose defaults it shares).

    ``klr_sparse`` starts from cpmp's default model (``klr``) and learns which of the fixed
    rule's support points of the graph nodes to keep. It follows a *sparsity path*: greedy
    forward selection over all graph nodes (:mod:`cpmp.predictors.selection`), recorded at
    support totals that are fractions (*levels*) of the graph nodes' fixed-rule count, once per
    kernel width in ``gamma_scales``. By default the path runs to ``level`` 1/4 and keeps that
    point; with ``level: null`` the level and width of least held-out progress MAE are kept
    (then the loss, then fewer supports, break ties). The validation data are the fit's
    (held-out demonstrations: the main job's test split, ``trainer.val_fraction``, or
    ``validation=`` of :meth:`~cpmp.sequencer.ConcurrentSequencer.fit`); without any,
    ``holdout_fraction`` of each node's activations (seeded by the fit's seed) is held out to
    choose, and the chosen level and width are then selected again on every activation. The
    kept supports are then *refined* (inducing points, :mod:`cpmp.predictors.inducing`):
    positions, one kernel factor per node and feature that may widen the kernel but never
    narrow it, weights and bias optimised together by LBFGS on the training loss, each
    support anchored to its path point; the convex solver then solves the weights on every
    sample.
    Why each piece is there, measured: docs/benchmarks.md and docs/history.md.

    The fit summary reports the path: ``sparsity_path`` (one record per width and level:
    ``level``, ``gamma_scale``, ``n_support``, ``train_loss``, ``val_loss``, ``val_mae``,
    ``chosen``), ``sparsity_level``, ``sparsity_gamma_scale``, ``sparsity_validation``
    (``validation``, ``held-out activations`` or ``none``), ``n_support_rule`` (the graph
    nodes' fixed-rule count) and ``refine`` (the loss before and after, the evaluations
    spent).

    Attributes:
        level: the share of the fixed rule's support count to keep, in (0, 1] (default
            0.25): the graph nodes then have ``floor(level * n_support_rule)`` supports (at
            least one per node); the width is still chosen on the validation data, and the
            path up to that level is reported with its held-out scores. ``None``: keep the
            level of least held-out MAE among ``path_levels`` (on a few demonstrations that
            MAE is measured on a handful of held-out activations, and the lower levels it
            picked completed no more episodes than the top one: docs/benchmarks.md).
        path_levels: the levels at which the path is recorded and scored, each in (0, 1]
            (default 1/16, 1/8, 3/16, 1/4).
        gamma_scales: kernel widths tried along the path, as factors of ``gamma`` (> 0; 1: the
            default kernel; 0.25: twice as wide); each is a path of its own. Default: (1,),
            the default kernel only (a wider kernel's smoother φ can stay below the switching
            threshold).
        holdout_fraction: without validation data, the share of each node's activations (of
            nodes with at least two) held out to choose the level and width, in (0, 1)
            (default 0.25).
        refine_iter: LBFGS iterations of the refinement at most (default 60; 0: keep the fixed
            rule's positions and the default kernel, the path's model as it is).
        refine_samples: training samples per node, at most, on which the refinement's loss is
            computed (every k-th; default 128; the weights are then re-solved on every sample).
        refine_anchor: weight ``λ`` of ``λ Σ ||u - u₀||²`` in the refinement's loss (``u``: the
            positions in kernel widths), which pulls each moved support back to its point on
            the demonstrated path, where the closed loop needs φ high at the activations' ends;
            default 0.01; 0: free; a large value: kept in place.
        l2: as in :class:`KLRConfig`, and the same default.
    """

    level: float | None = 0.25
    path_levels: tuple[float, ...] = (0.0625, 0.125, 0.1875, 0.25)
    gamma_scales: tuple[float, ...] = (1.0,)
    holdout_fraction: float = 0.25
    refine_iter: int = 60
    refine_samples: int = 128
    refine_anchor: float = 0.01

    def __post_init__(self) -> None:
        super().__post_init__()
        self._integer("refine_iter", "refine_samples")
        self._positive("refine_samples")
        self._non_negative("refine_iter", "refine_anchor")
        if self.level is not None:
            self.level = self._share("level", self.level)
        self.path_levels = self._shares("path_levels")
        self.gamma_scales = self._shares("gamma_scales", upper=None)
        fraction = self._number("holdout_fraction")
        if not 0.0 < fraction < 1.0:
            raise ConfigError(
                f"predictor option holdout_fraction must be in (0, 1), got {fraction!r}"
            )

    def _share(self, name: str, value: object, upper: float | None = 1.0) -> float:
        """One level or factor: a finite number in (0, ``upper``]."""
        number = finite_number(value, f"predictor option {name}")
        if not number > 0 or (upper is not None and number > upper):
            bound = "in (0, 1]" if upper is not None else "> 0"
            raise ConfigError(f"predictor option {name} must be {bound}, got {value!r}")
        return float(number)

    def _shares(self, name: str, upper: float | None = 1.0) -> tuple[float, ...]:
        """A non-empty list of levels or factors, each as :meth:`_share` checks."""
        values = getattr(self, name)
        if isinstance(values, (str, bytes)) or not hasattr(values, "__iter__"):
            raise ConfigError(f"predictor option {name} must be a list of numbers, got {values!r}")
        out = tuple(self._share(name, v, upper) for v in values)
        if not out:
            raise ConfigError(f"predictor option {name} must list at least one number")
        return out


@dataclass
class SklearnKLRConfig(KLRConfig):
    """Options of ``sklearn_klr``, on top of those of :class:`KLRConfig`.

    ``gamma``, the support rule, ``l2``, ``bias`` and feature weighting mean the same as there.

    ``l2`` becomes scikit-learn's ``C = 1 / (n · l2)`` for a node of ``n`` samples (``C = inf``,
    no penalty, for ``l2 = 0``): scikit-learn minimises ``C Σ_i s_i ℓ_i + ½ ||w||²``, which for
    the two weighted copies is ``1 / l2`` times ``klr``'s ``mean BCE + ½ l2 ||w||²``.

    Attributes:
        sklearn_solver: ``newton-cholesky`` (default), ``lbfgs`` or ``newton-cg`` (each leaves
            the intercept unpenalised).
        sklearn_tol: scikit-learn's stopping tolerance.
        sklearn_max_iter: scikit-learn's iteration cap per node.
    """

    sklearn_solver: str = "newton-cholesky"
    sklearn_tol: float = 1e-10
    sklearn_max_iter: int = 200

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.sklearn_solver not in SKLEARN_SOLVERS:
            raise ConfigError(
                f"sklearn_solver must be one of {', '.join(SKLEARN_SOLVERS)}, "
                f"got {self.sklearn_solver!r}"
            )
        self._integer("sklearn_max_iter")
        self._positive("sklearn_tol", "sklearn_max_iter")


@dataclass
class RegressionClipConfig(KLRConfig):
    """Options of ``regression_clip``: those of :class:`KLRConfig`, ``l2`` the ridge penalty.

    Each node minimises ``½ mean (K w + b − φ)² + ½ l2 ||w||²`` (the intercept ``b``
    unpenalised).
    """


@dataclass
class TimePhaseConfig(KLRConfig):
    """Options of ``time_phase``: exactly those of :class:`KLRConfig`.

    Only the labels differ (normalised elapsed time).
    """


@dataclass
class MLPConfig(PredictorConfig):
    """Options of ``mlp``.

    Attributes:
        hidden: hidden layer widths.
        activation: ``tanh``, ``relu`` or ``silu``.
        epochs: full-batch Adam steps at most (the budget); the trainer's early stopping
            usually ends the fit sooner, once the training loss stops improving.
        lr: Adam learning rate.
        weight_decay: L2 penalty on all weights, added to each node's mean loss.
    """

    hidden: tuple[int, ...] = (32, 32)
    activation: str = "tanh"
    epochs: int = 600
    lr: float = 0.03
    weight_decay: float = 1e-4

    def __post_init__(self) -> None:
        super().__post_init__()
        self.hidden = tuple(int(h) for h in self.hidden)
        if not self.hidden or any(h < 1 for h in self.hidden):
            raise ConfigError(f"hidden must list positive layer widths, got {self.hidden}")
        if self.activation not in ACTIVATIONS:
            raise ConfigError(
                f"activation must be one of {sorted(ACTIVATIONS)}, got {self.activation!r}"
            )
        self._integer("epochs")
        self._positive("epochs", "lr")
        self._non_negative("weight_decay")


@dataclass
class DTWConfig(PredictorConfig):
    """Options of ``dtw`` (distances in the scaled features of ``feature_scaling``).

    Attributes:
        window: ticks of recent features aligned at each tick (50: 0.5 s at 100 Hz).
        stride: ticks between two window points, and between two kept samples of each training
            activation (so both are sampled alike); the window holds ``ceil(window / stride)``
            points.
        max_reference: samples kept per training activation at most (after the stride, longer
            activations are thinned evenly); bounds the cost of a tick.
    """

    window: int = 50
    stride: int = 10
    max_reference: int = 30

    def __post_init__(self) -> None:
        super().__post_init__()
        self._integer("window", "stride", "max_reference")
        self._positive("window", "stride")
        if self.max_reference < 2:
            raise ConfigError(
                f"predictor option max_reference must be >= 2, got {self.max_reference!r}"
            )


PREDICTOR_CONFIGS: dict[str, type[PredictorConfig]] = {
    "klr": KLRConfig,
    "klr_full": KLRConfig,
    "klr_sparse": SparseKLRConfig,
    "mlp": MLPConfig,
    "sklearn_klr": SklearnKLRConfig,
    "regression_clip": RegressionClipConfig,
    "time_phase": TimePhaseConfig,
    "dtw": DTWConfig,
}
"""The options class of every predictor kind (each predictor's ``config_class``; tested)."""


def predictor_config_class(kind: str) -> type[PredictorConfig]:
    """The options class of predictor ``kind``; an unknown kind is a :class:`ConfigError`."""
    if kind not in PREDICTOR_CONFIGS:
        raise ConfigError(
            f"unknown predictor {kind!r}; choose one of {', '.join(PREDICTOR_CONFIGS)}"
        )
    return PREDICTOR_CONFIGS[kind]


def predictor_option_names(kind: str) -> list[str]:
    """The option names accepted by predictor ``kind``."""
    return [f.name for f in dataclasses.fields(predictor_config_class(kind))]


def saved_predictor_options(
    kind: str, options: Mapping[str, OptionValue]
) -> dict[str, OptionValue]:
    """A saved bank's options without those removed since that acted only in its fit.

    Args:
        kind: the predictor kind.
        options: the options of a checkpoint's predictor (its ``spec``'s ``config``).

    Returns:
        ``options`` without :data:`FIT_ONLY_REMOVED_OPTIONS` (every other removed option is
        still refused by :func:`predictor_config`).
    """
    inert = FIT_ONLY_REMOVED_OPTIONS.get(kind, frozenset())
    return {k: v for k, v in options.items() if k not in inert}


def predictor_config(kind: str, **options: OptionValue) -> PredictorConfig:
    """Validated options of predictor ``kind``.

    Raises:
        ConfigError: an unknown option, or one the kind no longer has
            (:data:`REMOVED_OPTIONS`, named as removed), or a bad value.
    """
    cls = predictor_config_class(kind)
    valid = predictor_option_names(kind)
    removed = REMOVED_OPTIONS.get(kind, {})
    gone = sorted(set(options) & set(removed))
    if gone:
        reasons = "; ".join(dict.fromkeys(removed[name] for name in gone))
        raise ConfigError(
            f"removed option(s) {', '.join(gone)} for predictor {kind!r}: {reasons}; drop "
            f"them (valid options: {', '.join(valid)})"
        )
    unknown = sorted(set(options) - set(valid))
    if unknown:
        raise ConfigError(
            f"unknown option(s) {', '.join(unknown)} for predictor {kind!r}; "
            f"valid options: {', '.join(valid)}"
        )
    try:
        return cls(**options)
    except TypeError as err:
        raise ConfigError(f"bad options for predictor {kind!r}: {err}") from err
