"""Composing a cpmp command line's configuration as Hydra will, with Hydra and OmegaConf only.

Used by :mod:`cpmp.cli.checks`: the command line parsed by Hydra's own parser, the job
override lists of a multirun sweep, the composed config with its interpolations resolved, and
every Hydra/OmegaConf error turned into a one-line :class:`~cpmp.errors.ConfigError` /
:class:`~cpmp.errors.CpmpFileError` naming the override (with a "did you mean" for a misspelt
group option or key).
"""

from __future__ import annotations

import argparse
import difflib
import re
from collections.abc import Sequence
from pathlib import Path

from hydra import compose, initialize_config_module
from hydra._internal.core_plugins.basic_sweeper import BasicSweeper
from hydra._internal.utils import get_args_parser
from hydra.core.hydra_config import HydraConfig
from hydra.core.override_parser.overrides_parser import OverridesParser
from hydra.core.override_parser.types import Override
from hydra.errors import HydraException, MissingConfigException
from omegaconf import DictConfig, OmegaConf
from omegaconf.errors import OmegaConfBaseException

from cpmp.compare.settings import register_compare
from cpmp.config.paths import CONF_PACKAGE, conf_dir
from cpmp.config.predictors import REMOVED_OPTIONS
from cpmp.config.sequencer import REMOVED_SEQUENCER_OPTIONS
from cpmp.errors import ConfigError, CpmpError, CpmpFileError
from cpmp.experiment.config import register_configs
from cpmp.records import JsonValue

CONF_DIR = conf_dir()
"""The Hydra config directory: the checkout's ``conf/`` (editable install) or its installed copy
(:mod:`cpmp.config.paths`); Hydra reads it as the package ``cpmp._conf``."""

Composed = dict[tuple[str, ...], DictConfig]
"""The configs composed for one command line (one config name and config directory), by
their overrides: :func:`compose_config` composes each list of overrides once."""


def parse_command_line(argv: Sequence[str]) -> argparse.Namespace:
    """``argv`` parsed by Hydra's own command-line parser.

    Raises:
        ConfigError: a bad flag (argparse would print its usage and exit).
    """

    def error(message: str) -> None:
        raise ConfigError(f"{message} (see --help)")

    parser = get_args_parser()
    parser.error = error  # type: ignore[method-assign]
    return parser.parse_args(list(argv))


def one_line(text: str) -> str:
    """A Hydra/OmegaConf message as one line.

    Search paths, documentation links and OmegaConf's ``full_key``/``object_type`` trailers are
    dropped, option lists joined.
    """
    lines: list[str] = []
    options: list[str] = []
    for raw in str(text).splitlines():
        line = raw.strip()
        if re.match(r"(Config search path|Search path):", line):
            break
        if not line or line.startswith(("See https://", "full_key:", "object_type=")):
            continue
        if raw.startswith("\t"):
            options.append(line)
            continue
        if options:
            lines[-1] += " " + ", ".join(options)
            options = []
        lines.append(line.rstrip("."))
    if options and lines:
        lines[-1] += " " + ", ".join(options)
    return "; ".join(lines)


def parse_overrides(overrides: Sequence[str]) -> list[Override]:
    """``overrides`` parsed by Hydra's override parser (one ``Override`` each).

    Raises:
        ConfigError: an override it cannot parse (the message shows the syntax).
    """
    parser = OverridesParser.create()
    parsed = []
    for line in overrides:
        try:
            parsed.append(parser.parse_override(line))
        except HydraException as err:
            raise ConfigError(
                f"cannot parse the override {line!r}: {one_line(str(err))} (Hydra's override "
                "syntax: key=value, +new_key=value, ~key; quote values with spaces or commas)"
            ) from None
    return parsed


def _composition_error(
    err: Exception,
    overrides: Sequence[Override],
    config_name: str,
    config_dir: str | None,
    composed: Composed | None,
) -> ConfigError:
    """A one-line :class:`ConfigError` for a Hydra composition error, naming the override.

    ``composed`` is :func:`compose_config`'s cache, reused to suggest a key.
    """
    text = str(err)
    missing = re.search(r"Could not find '([^']+)/([^']+)'", text)
    if isinstance(err, MissingConfigException) and missing:
        group, option = missing.groups()
        found = re.search(r"Available options in '[^']+':\n((?:\t.*\n?)*)", text)
        choices = found.group(1).split() if found else []
        close = difflib.get_close_matches(option, choices, n=1)
        hint = f" (did you mean {group}={close[0]}?)" if close else ""
        return ConfigError(
            f"{group}={option}: no such option{hint}; choose one of {', '.join(choices)}"
        )
    key = re.match(r"Could not override '([^']+)'", text)
    if key:
        name = key.group(1)
        line = next((o.input_line for o in overrides if o.key_or_group == name), name)
        group, _, leaf = name.partition(".")
        removed = [r[leaf] for r in REMOVED_OPTIONS.values() if leaf in r]
        if group == "predictor" and removed:
            return ConfigError(f"{line}: removed option {name}: {removed[0]}; drop it")
        if group == "sequencer" and leaf in REMOVED_SEQUENCER_OPTIONS:
            why = REMOVED_SEQUENCER_OPTIONS[leaf][1]
            return ConfigError(f"{line}: removed option {name}: {why}; drop it")
        others = [o.input_line for o in overrides if "." not in o.key_or_group]
        close = _close_key(name, config_name, others, config_dir, composed)
        if close is not None:  # a misspelt key: adding it with + would only fail later
            value = line.partition("=")[2]
            return ConfigError(
                f"{line}: the {config_name} config has no key {name!r} (did you mean "
                f"{close!r}?); write {close}={value}"
            )
        return ConfigError(
            f"{line}: the {config_name} config has no key {name!r}; to add a new key write +{line}"
        )
    exists = re.match(r"Could not append to config. An item is already at '([^']+)'", text)
    if exists:
        name = exists.group(1)
        line = next((o.input_line for o in overrides if o.key_or_group == name), name)
        return ConfigError(f"{line}: {name} exists already; set it without the +: {line[1:]}")
    if "Ambiguous value for argument" in text or "requires --multirun" in text:
        line = re.search(r"'([^']+)'", text)
        return ConfigError(
            f"{line.group(1) if line else 'an override'} lists several values: add -m "
            "(--multirun) to run one job per value; for a list write key=[a,b], for a string "
            "with commas quote it: key='a,b'"
        )
    merging = re.match(r"Error merging override (.+)", text)
    if merging and err.__cause__ is not None:
        return ConfigError(f"{merging.group(1)}: {one_line(str(err.__cause__))}")
    if "Cannot find primary config" in text:
        return ConfigError(f"{one_line(text)}; the configs live in {CONF_DIR}")
    if "Primary config module" in text:
        return ConfigError(
            f"cpmp's configs (the package {CONF_PACKAGE}) are not installed: reinstall cpmp "
            "(bash scripts/install.sh, or pip install -e . in a checkout)"
        )
    cause = err.__cause__
    detail = f": {one_line(str(cause))}" if cause is not None and str(cause) else ""
    return ConfigError(f"{one_line(text)}{detail}")


def _close_key(
    key: str,
    config_name: str,
    groups: list[str],
    config_dir: str | None,
    composed: Composed | None = None,
) -> str | None:
    """The existing key a misspelt ``key`` most likely means, from the keys beside it.

    Args:
        key: the dotted key that does not exist.
        config_name: the command's config.
        groups: the overrides of groups and top-level keys (the config is composed with them).
        config_dir: an extra config directory, or ``None``.
        composed: :func:`compose_config`'s cache of the configs composed for the same command
            line (the config composed with ``groups`` is often there already), or ``None``.

    Returns:
        The dotted key (``sequencer.threshold`` for ``sequencer.treshold``), or ``None``.
    """
    parent, _, leaf = key.rpartition(".")
    others = [g for g in groups if g.split("=")[0] != key]
    try:
        cfg = compose_config(config_name, others, config_dir, composed)
    except CpmpError:
        return None
    node = OmegaConf.select(cfg, parent) if parent else cfg
    names = [str(k) for k in node if k != "hydra"] if isinstance(node, DictConfig) else []
    close = difflib.get_close_matches(leaf, names, n=1)
    return ".".join([*filter(None, [parent]), close[0]]) if close else None


def compose_config(
    config_name: str,
    overrides: Sequence[str],
    config_dir: str | None,
    composed: Composed | None = None,
) -> DictConfig:
    """The composed config (with its ``hydra`` node) of ``conf/<config_name>.yaml``.

    Args:
        config_name: the command's config.
        overrides: the command line's overrides.
        config_dir: an extra config directory, or ``None``.
        composed: the configs composed already with this ``config_name`` and ``config_dir``
            (by their overrides), or ``None``: a config found there is returned as it is
            (treat it as read-only), a newly composed one is added. Pass one per command line
            (a config's ``hydra`` node holds the working directory and the time).

    Raises:
        ConfigError: anything Hydra cannot compose.
        CpmpFileError: ``config_dir`` is not a directory.
    """
    key = tuple(overrides)
    if composed is not None and key in composed:
        return composed[key]
    # the schemas of conf/ are stored on import; again only if Hydra's ConfigStore was cleared
    register_configs(missing_only=True)
    register_compare(missing_only=True)
    overrides = list(overrides)
    if config_dir is not None:
        overrides = _with_search_path(overrides, config_dir)
    parsed = parse_overrides(overrides)
    try:
        with initialize_config_module(config_module=CONF_PACKAGE, version_base="1.3"):
            cfg = compose(config_name, overrides=overrides, return_hydra_config=True)
    except (HydraException, OmegaConfBaseException, ValueError) as err:
        raise _composition_error(err, parsed, config_name, config_dir, composed) from None
    if composed is not None:
        composed[key] = cfg
    return cfg


def _with_search_path(overrides: list[str], config_dir: str) -> list[str]:
    """``overrides`` with ``--config-dir`` added to ``hydra.searchpath`` (as Hydra adds it)."""
    path = Path(config_dir).absolute()
    if not path.is_dir():
        raise CpmpFileError(f"--config-dir {config_dir}: no such directory")
    rest, searchpath = [], []
    for override, line in zip(parse_overrides(overrides), overrides, strict=True):
        if override.get_key_element() == "hydra.searchpath":
            searchpath = [str(v) for v in override.value()]
        else:
            rest.append(line)
    entries = ",".join(f"'{p}'" for p in [*searchpath, f"file://{path}"])
    return [*rest, f"hydra.searchpath=[{entries}]"]


def resolved_job(cfg: DictConfig) -> dict[str, JsonValue]:
    """The job's part of ``cfg`` (without ``hydra``) with every interpolation resolved.

    Raises:
        ConfigError: an interpolation that does not resolve.
    """
    hydra_config = HydraConfig.instance()  # for ${hydra:...}; restored after
    previous = hydra_config.cfg
    hydra_config.set_config(cfg)
    job = OmegaConf.masked_copy(cfg, [k for k in cfg if k != "hydra"])
    try:
        return OmegaConf.to_container(job, resolve=True)  # type: ignore[return-value]
    except OmegaConfBaseException as err:
        key = getattr(err, "full_key", None)
        raise ConfigError(f"{key or 'config'}: {one_line(str(err))}") from None
    finally:
        hydra_config.cfg = previous


def sweep_jobs(parsed: list[Override]) -> list[list[str]]:
    """The job override lists of a multirun (Hydra's basic sweeper: every combination).

    Raises:
        ConfigError: a sweep of Hydra's own settings, or a sweep Hydra cannot split.
    """
    hydra_lines, task = [], []
    for o in parsed:
        if o.is_hydra_override():
            if o.is_sweep_override():
                raise ConfigError(f"{o.input_line}: Hydra's own settings cannot be swept")
            hydra_lines.append(o.input_line)
        else:
            task.append(o)
    try:
        (batch,) = BasicSweeper.split_arguments(task, max_batch_size=None)
    except HydraException as err:
        raise ConfigError(one_line(str(err))) from None
    return [[*hydra_lines, *job] for job in batch]
