"""Progress predictors: ``torch.nn.Module`` banks mapping features ``(..., d)`` to ``(..., K)``.

Use :func:`make_predictor` to build one by name (``klr``, ``klr_full``, ``klr_sparse``, ``mlp``,
and the baselines ``sklearn_klr``, ``regression_clip``, ``time_phase``, ``dtw``) and
:func:`predictor_from_spec` to rebuild a saved one.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from cpmp.errors import ConfigError
from cpmp.predictors.base import (
    START_PREFIX,
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


def predictor_options(kind: str) -> list[str]:
    """The option names accepted by predictor ``kind``."""
    return [f.name for f in dataclasses.fields(_predictor_class(kind).config_class)]


def _predictor_class(kind: str) -> type[ProgressPredictor]:
    if kind not in PREDICTORS:
        raise ConfigError(f"unknown predictor {kind!r}; choose one of {', '.join(PREDICTORS)}")
    return PREDICTORS[kind]


def make_config(kind: str, **options: Any) -> PredictorConfig:
    """Validated config of predictor ``kind``; unknown options raise :class:`ConfigError`."""
    cls = _predictor_class(kind)
    valid = predictor_options(kind)
    unknown = sorted(set(options) - set(valid))
    if unknown:
        raise ConfigError(
            f"unknown option(s) {', '.join(unknown)} for predictor {kind!r}; "
            f"valid options: {', '.join(valid)}"
        )
    try:
        return cls.config_class(**options)
    except TypeError as err:
        raise ConfigError(f"bad options for predictor {kind!r}: {err}") from err


def make_predictor(
    kind: str, node_keys: list[NodeKey], n_features: int, **options: Any
) -> ProgressPredictor:
    """An untrained predictor bank of type ``kind`` for ``node_keys``."""
    return _predictor_class(kind)(node_keys, n_features, make_config(kind, **options))


def predictor_from_spec(spec: dict[str, Any]) -> ProgressPredictor:
    """Rebuild a predictor (untrained weights, right shapes) from :meth:`ProgressPredictor.spec`."""
    kind = spec["kind"]
    config = make_config(kind, **spec["config"])
    node_keys = [tuple(k) for k in spec["node_keys"]]
    return _predictor_class(kind)(node_keys, int(spec["n_features"]), config, **spec["shapes"])


__all__ = [
    "PREDICTORS",
    "START_PREFIX",
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
    "make_config",
    "make_predictor",
    "predictor_from_spec",
    "predictor_options",
    "soft_bce",
]
