"""Progress predictors: ``torch.nn.Module`` banks mapping features ``(..., d)`` to ``(..., K)``.

Use :func:`make_predictor` to build one by name (``klr``, ``klr_full``, ``klr_sparse``, ``mlp``,
and the baselines ``sklearn_klr``, ``regression_clip``, ``time_phase``, ``dtw``) and
:func:`predictor_from_spec` to rebuild a saved one.
"""

from __future__ import annotations

from collections.abc import Mapping

from cpmp.config.predictors import predictor_config, saved_predictor_options
from cpmp.config.validation import OptionValue
from cpmp.errors import ConfigError
from cpmp.predictors.base import (
    FeatureScaler,
    NodeData,
    NodeKey,
    PredictorConfig,
    ProgressPredictor,
    soft_bce,
)
from cpmp.predictors.baselines import (
    RegressionClipConfig,
    RegressionClipPredictor,
    SklearnKLRConfig,
    SklearnKLRPredictor,
    TimePhaseConfig,
    TimePhasePredictor,
)
from cpmp.predictors.dtw import DTWConfig, DTWPredictor
from cpmp.predictors.klr import (
    FullKLRPredictor,
    KLRConfig,
    KLRPredictor,
    SparseKLRConfig,
    SparseKLRPredictor,
)
from cpmp.predictors.mlp import MLPConfig, MLPPredictor
from cpmp.records import JsonValue

PREDICTORS: dict[str, type[ProgressPredictor]] = {
    cls.kind: cls
    for cls in (
        KLRPredictor,
        FullKLRPredictor,
        SparseKLRPredictor,
        MLPPredictor,
        SklearnKLRPredictor,
        RegressionClipPredictor,
        TimePhasePredictor,
        DTWPredictor,
    )
}


def _predictor_class(kind: str) -> type[ProgressPredictor]:
    if kind not in PREDICTORS:
        raise ConfigError(f"unknown predictor {kind!r}; choose one of {', '.join(PREDICTORS)}")
    return PREDICTORS[kind]


def make_predictor(
    kind: str, node_keys: list[NodeKey], n_features: int, **options: OptionValue
) -> ProgressPredictor:
    """An untrained predictor bank of type ``kind`` for ``node_keys``."""
    return _predictor_class(kind)(node_keys, n_features, predictor_config(kind, **options))


def predictor_from_spec(spec: Mapping[str, JsonValue]) -> ProgressPredictor:
    """Rebuild a predictor (untrained weights, right shapes) from :meth:`ProgressPredictor.spec`.

    An option removed since that acted only in the fit (``klr_sparse``'s ``start_share``:
    :data:`~cpmp.config.predictors.FIT_ONLY_REMOVED_OPTIONS`) is dropped; any other removed
    option is a :class:`~cpmp.errors.ConfigError` naming it as removed.
    """
    kind = spec["kind"]
    config = predictor_config(kind, **saved_predictor_options(kind, spec["config"]))
    node_keys = [tuple(k) for k in spec["node_keys"]]
    return _predictor_class(kind)(node_keys, int(spec["n_features"]), config, **spec["shapes"])


__all__ = [
    "PREDICTORS",
    "DTWConfig",
    "DTWPredictor",
    "FeatureScaler",
    "FullKLRPredictor",
    "KLRConfig",
    "KLRPredictor",
    "MLPConfig",
    "MLPPredictor",
    "NodeData",
    "NodeKey",
    "PredictorConfig",
    "ProgressPredictor",
    "RegressionClipConfig",
    "RegressionClipPredictor",
    "SklearnKLRConfig",
    "SklearnKLRPredictor",
    "SparseKLRConfig",
    "SparseKLRPredictor",
    "TimePhaseConfig",
    "TimePhasePredictor",
    "make_predictor",
    "predictor_from_spec",
    "soft_bce",
]
