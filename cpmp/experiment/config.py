"""Turning Hydra/OmegaConf configs into validated cpmp objects (fail fast, before long work)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from cpmp.errors import ConfigError
from cpmp.predictors import PREDICTORS, make_config


def to_dict(cfg: Any) -> dict[str, Any]:
    """A plain dict from an OmegaConf node or mapping (``None`` -> ``{}``)."""
    if cfg is None:
        return {}
    try:
        from omegaconf import DictConfig, OmegaConf

        if isinstance(cfg, DictConfig):
            return OmegaConf.to_container(cfg, resolve=True)  # type: ignore[return-value]
    except ImportError:  # pragma: no cover - omegaconf comes with hydra-core
        pass
    if isinstance(cfg, Mapping):
        return dict(cfg)
    raise ConfigError(f"expected a mapping of options, got {type(cfg).__name__}")


def predictor_options(cfg: Any) -> tuple[str, dict[str, Any]]:
    """``(kind, options)`` from a ``predictor`` config group entry; validated now."""
    options = to_dict(cfg)
    kind = options.pop("kind", None)
    if kind not in PREDICTORS:
        raise ConfigError(
            f"predictor.kind must be one of {', '.join(PREDICTORS)}, got {kind!r} "
            f"(choose with predictor=<name>)"
        )
    if "hidden" in options and options["hidden"] is not None:
        options["hidden"] = tuple(options["hidden"])
    make_config(kind, **options)
    return kind, options
