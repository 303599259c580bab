"""The options of every progress predictor (``conf/predictor/``), one dataclass per kind.

The predictors themselves live in :mod:`cpmp.predictors` (``config_class`` names the class
here); the options live apart so that they can be read and checked without importing torch.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from cpmp.config.validation import finite_number
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


@dataclass
class PredictorConfig:
    """Options shared by every predictor.

    Attributes:
        feature_scaling: ``global`` (default: all features over one common factor, so units
            do not matter), ``none`` (the paper), ``minmax`` or ``standard`` (see
            :class:`~cpmp.predictors.FeatureScaler`); the fitted scaling is stored in the
            checkpoint and applied to every input.
        dtype: ``float64`` or ``float32``.
        path_noise: ``auto`` (default) or ``none`` (the paper): with ``auto`` the L1 path of
            eq. 1, and the support points and feature weights that follow it, are measured
            on each training activation after removing the white noise estimated on it
            (:func:`cpmp.progress.denoise_trajectory`; a trajectory without detected noise is
            used as recorded), and so are the ranges of ``feature_scaling``; ``none``
            measures them on the features as recorded.
    """

    feature_scaling: str = "global"
    dtype: str = "float64"
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
        if self.dtype not in ("float32", "float64"):
            raise ConfigError(f"dtype must be 'float32' or 'float64', got {self.dtype!r}")

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

        return torch.float64 if self.dtype == "float64" else torch.float32


@dataclass
class KLRConfig(PredictorConfig):
    """Options of ``klr`` / ``klr_full``.

    The defaults are cpmp's (``predictor=klr_path``); the paper's ``predictor=klr`` sets
    ``feature_weighting: none`` and ``feature_scaling: none``.

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

    def __post_init__(self) -> None:
        super().__post_init__()
        self._integer("max_iter", "min_support", "max_total_support")
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


@dataclass
class SparseKLRConfig(KLRConfig):
    """Options of ``klr_sparse`` (on top of :class:`KLRConfig`).

    Attributes:
        candidate_scale: candidates per unit path length (generous; pruned after training).
        min_candidates: minimum candidates per activation.
        l1: weight of the sparsity penalty ``l1 * mean|w|`` per node.
        learn_positions: also move the support points.
        learn_lengthscales: learn one length-scale per node and feature (ARD).
        epochs: Adam steps (full batch) at most (the budget); the trainer's early stopping
            usually ends the sparsity phase sooner, once the training loss stops improving.
        lr: Adam learning rate.
        prune_tol: prune supports with ``|w| < prune_tol * max|w|`` of their node.
        refit: re-fit the surviving weights to convergence (the trainer's convex solver,
            Newton by default) after pruning.
    """

    candidate_scale: float = 8.0
    min_candidates: int = 8
    l1: float = 1e-2
    learn_positions: bool = False
    learn_lengthscales: bool = False
    epochs: int = 400
    lr: float = 0.1
    prune_tol: float = 0.02
    refit: bool = True

    def __post_init__(self) -> None:
        super().__post_init__()
        self._integer("min_candidates", "epochs")
        self._positive("candidate_scale", "min_candidates", "epochs", "lr")
        self._non_negative("l1", "prune_tol")


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


def predictor_config(kind: str, **options: Any) -> PredictorConfig:
    """Validated options of predictor ``kind``; unknown options raise :class:`ConfigError`."""
    cls = predictor_config_class(kind)
    valid = predictor_option_names(kind)
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
