"""Checking a cpmp command line before anything heavy is imported (used by :mod:`cpmp.cli.main`).

:func:`check_command_line` parses the command line with Hydra's own parser and composes the
configuration as Hydra will (for a multirun: every job of the sweep) with Hydra, OmegaConf and
the schema of :mod:`cpmp.experiment.config` only (:mod:`~cpmp.cli.compose`); an
unknown group option or key, an override Hydra cannot parse, a value of the wrong type (against
the type of its default and the schema), an interpolation that does not resolve, a required
path that is unset or names no file become one-line :class:`~cpmp.errors.ConfigError` /
:class:`~cpmp.errors.CpmpFileError` messages naming the override. :func:`check_jobs` then runs
the command's own value checks (the typed configs) on every job, before the first starts.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from hydra.core.override_parser.types import Override
from omegaconf import DictConfig, ListConfig, OmegaConf
from omegaconf.errors import OmegaConfBaseException

from cpmp.cli.compose import (
    CONF_DIR,
    Composed,
    compose_config,
    one_line,
    parse_command_line,
    parse_overrides,
    resolved_job,
    sweep_jobs,
)
from cpmp.errors import ConfigError, CpmpError, CpmpFileError
from cpmp.records import JsonValue


@dataclass(frozen=True)
class Command:
    """A Hydra command: its config, its job and the checks that run before it.

    The config is ``conf/<name>.yaml``; ``name`` is also the job's name, so runs go to
    ``logs/<name>/<timestamp>/``.

    Attributes:
        name: config and job name.
        summary: what the command does, in a few words (the docstring of its entry point).
        job: ``job(cfg, run_dir) -> output path``; imports its heavy parts itself.
        check: the job's own value checks ``check(cfg)`` (may import torch), or ``None``.
        required: keys that must be set (a path each).
        files: keys naming a file that must exist (when set).
        dirs: keys naming a directory that must exist (when set).
        positive: keys holding a count that must be >= 1.
    """

    name: str
    summary: str
    job: Callable[[DictConfig, Path], Path]
    check: Callable[[DictConfig], None] | None = None
    required: tuple[str, ...] = ()
    files: tuple[str, ...] = ()
    dirs: tuple[str, ...] = ()
    positive: tuple[str, ...] = ()


# ------------------------------------------------------------------------ checking values
_KINDS = ((bool, "a boolean"), (int, "an integer"), (float, "a number"), (str, "a string"))
_ACCEPTS = {
    "a boolean": {"a boolean"},
    "an integer": {"an integer"},
    "a number": {"an integer", "a number"},
    "a string": {"a string"},
    "a list": {"a list"},
    "a mapping": {"a mapping"},
}


def _kind(value: object) -> str | None:
    """The kind of a config value (``None`` for null).

    A YAML default written as an integer is an integer option, one written with a decimal
    point a number.
    """
    if value is None:
        return None
    if isinstance(value, (list, tuple, ListConfig)):
        return "a list"
    if isinstance(value, (dict, DictConfig)):
        return "a mapping"
    return next((name for types, name in _KINDS if isinstance(value, types)), None)


def _check_type(key: str, value: object, default: JsonValue) -> None:
    """``value`` (set on the command line) must be of the kind of ``default``.

    An integer where the default is an integer, a number where it is a float, and so on; null
    is always accepted (the job's own checks say whether null is allowed).

    Raises:
        ConfigError: ``value`` (or an element of it) is of another kind.
    """
    want, got = _kind(default), _kind(value)
    if want is None or got is None:
        return
    if got not in _ACCEPTS[want]:
        raise ConfigError(f"{key}={value!r}: expected {want} (the default is {default!r})")
    if want == "a list" and len(default):
        kinds = {_kind(v) for v in default}
        if len(kinds) == 1 and None not in kinds:
            (element,) = kinds
            for v in value:
                if v is not None and _kind(v) not in _ACCEPTS[element]:
                    raise ConfigError(
                        f"{key}: element {v!r} should be {element} (the default is "
                        f"{list(default)!r})"
                    )


def _select(cfg: dict[str, JsonValue], key: str) -> tuple[bool, JsonValue]:
    """``(found, value)`` of the dotted ``key`` in ``cfg``."""
    node: JsonValue = cfg
    for part in key.split("."):
        if not isinstance(node, dict) or part not in node:
            return False, None
        node = node[part]
    return True, node


def _check_types(base: dict[str, JsonValue], parsed: list[Override]) -> None:
    """The overridden values, as written on the command line, against the kinds of the defaults.

    ``base`` is the config composed with the same group options and no value override,
    ``parsed`` the value overrides; an interpolation is checked once resolved, by the schema.
    """
    for override in parsed:
        if override.is_delete() or override.is_hydra_override():
            continue
        value = override.value()
        if isinstance(value, str) and "${" in value:
            continue
        key = override.get_key_element().lstrip("+")
        in_base, default = _select(base, key)
        if in_base:
            _check_type(key, value, default)


def _check_values(command: Command, job: dict[str, JsonValue]) -> None:
    """The seed and counts of the composed job, then the command's required paths.

    Raises:
        ConfigError: a bad seed or count, an unset required path.
        CpmpFileError: a file or directory that does not exist.
    """
    if "seed" in job:
        seed = job["seed"]
        if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            raise ConfigError(f"seed={seed!r}: the seed must be a non-negative integer")
    for key in command.positive:
        value = _select(job, key)[1]
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise ConfigError(f"{key}={value!r}: must be an integer >= 1")
    for key in command.required:
        if _select(job, key)[1] in (None, ""):
            raise ConfigError(f"{key} is required: add {key}=<path> to the command line")
    for key in command.files:
        value = _select(job, key)[1]
        if value not in (None, "") and not Path(str(value)).is_file():
            raise CpmpFileError(f"{key}={value}: no such file (relative to {Path.cwd()})")
    for key in command.dirs:
        value = _select(job, key)[1]
        if value not in (None, "") and not Path(str(value)).is_dir():
            raise CpmpFileError(f"{key}={value}: no such directory (relative to {Path.cwd()})")


# --------------------------------------------------------------------------- the checks
@dataclass
class CheckedJob:
    """One job of a command line, composed and checked.

    Attributes:
        overrides: the job's overrides (a multirun's jobs each get one value of each sweep).
        cfg: the composed config, without its ``hydra`` node (as the job gets it).
    """

    overrides: list[str]
    cfg: DictConfig


def check_command_line(command: Command, argv: Sequence[str]) -> list[CheckedJob]:
    """Compose and check the configuration of ``command`` for the command line ``argv``.

    ``argv`` is without the program name. Only light imports (Hydra, OmegaConf; never torch,
    Lightning or MuJoCo). Returns one :class:`CheckedJob` per job (several for a multirun
    sweep); none for ``--help``, ``--cfg``, ``--info`` and the like, which run no job (the
    configuration of ``--cfg`` and ``--info`` is composed, not checked further).

    Raises:
        ConfigError: unknown group option or key, unparsable override, a value of the wrong
            type, an interpolation that does not resolve, an unset required path.
        CpmpFileError: a path that names no file or directory.
    """
    args = parse_command_line(argv)
    if args.help or args.hydra_help or args.shell_completion or args.experimental_rerun:
        return []
    inspection = args.cfg is not None or args.info is not None
    if args.config_path is not None:
        raise ConfigError(
            f"--config-path is not supported: cpmp's configs are in {CONF_DIR}; add a "
            "directory of your own config options with --config-dir DIR"
        )
    config_name = args.config_name or command.name
    overrides = list(args.overrides)
    parsed = parse_overrides(overrides)
    multirun = args.multirun or any(
        o.get_key_element() == "hydra.mode" and str(o.value()) == "MULTIRUN" for o in parsed
    )
    jobs = sweep_jobs(parsed) if multirun else [overrides]
    checked: list[CheckedJob] = []
    composed: Composed = {}  # each list of overrides is composed once
    bases: dict[tuple[str, ...], dict[str, JsonValue]] = {}
    for job_overrides in jobs:
        try:
            if inspection:
                compose_config(config_name, job_overrides, args.config_dir, composed)
                continue
            job_parsed = parse_overrides(job_overrides)
            group_names = _group_names(config_name, args.config_dir, composed)
            groups = tuple(
                line
                for line, o in zip(job_overrides, job_parsed, strict=True)
                if o.key_or_group in group_names or o.is_hydra_override()
            )
            if groups not in bases:
                bases[groups] = resolved_job(
                    compose_config(config_name, list(groups), args.config_dir, composed)
                )
            _check_types(bases[groups], [o for o in job_parsed if o.input_line not in groups])
            cfg = compose_config(config_name, job_overrides, args.config_dir, composed)
            same = tuple(job_overrides) == groups  # no value override: the base is the job
            _check_values(command, bases[groups] if same else resolved_job(cfg))
        except CpmpError as err:
            raise _in_job(err, job_overrides, len(jobs)) from None
        checked.append(
            CheckedJob(job_overrides, OmegaConf.masked_copy(cfg, [k for k in cfg if k != "hydra"]))
        )
    return checked


_GROUP_NAMES: dict[str, frozenset[str]] = {}
"""The config groups of each of cpmp's own configs (no ``--config-dir``) by config name,
found once per process (the defaults list of ``conf/<name>.yaml`` does not change)."""


def _group_names(config_name: str, config_dir: str | None, composed: Composed) -> frozenset[str]:
    """The config groups of ``config_name`` (its ``hydra.runtime.choices`` with no override).

    Args:
        config_name: the command's config.
        config_dir: an extra config directory, or ``None``.
        composed: the command line's configs (:func:`~cpmp.cli.compose.compose_config`).

    Returns:
        The group names, such as ``predictor`` and ``hydra/launcher``.
    """
    if config_dir is None and config_name in _GROUP_NAMES:
        return _GROUP_NAMES[config_name]
    default = compose_config(config_name, [], config_dir, composed)
    names = frozenset(default.hydra.runtime.choices)
    if config_dir is None:
        _GROUP_NAMES[config_name] = names
    return names


def _in_job(err: CpmpError, overrides: list[str], n_jobs: int) -> CpmpError:
    """``err`` with the job named when a sweep has several."""
    if n_jobs == 1:
        return err
    return type(err)(f"{err} (in the sweep's job {' '.join(overrides)})")


def check_jobs(command: Command, jobs: Sequence[CheckedJob]) -> None:
    """Run ``command``'s own value checks on every job.

    A check may import torch (MuJoCo for the task).

    Raises:
        CpmpError: the job's error, naming the override it is about and the job of a sweep.
    """
    check = command.check
    if check is None:
        return
    for job in jobs:
        error: CpmpError
        try:
            check(job.cfg)
        except OmegaConfBaseException as err:  # a section removed with ~group
            error = ConfigError(
                f"{getattr(err, 'full_key', None) or 'config'}: {one_line(str(err))}"
            )
        except CpmpError as err:
            error = _with_override(err, job.overrides)
        else:
            continue
        raise _in_job(error, job.overrides, len(jobs)) from None


def _with_override(err: CpmpError, overrides: Sequence[str]) -> CpmpError:
    """``err`` prefixed with the one override whose key it names by its last part only.

    For example ``task.max_time=-1: max_time must be ...``.
    """
    text = str(err)
    named = []
    for line in overrides:
        key = line.split("=", 1)[0].lstrip("+~")
        leaf = key.rpartition(".")[2]
        if key not in text and re.search(rf"\b{re.escape(leaf)}\b", text):
            named.append(line)
    return type(err)(f"{named[0]}: {text}") if len(named) == 1 else err
