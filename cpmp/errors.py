"""The one exception family cpmp raises for user errors.

Every error a user can cause (bad file, wrong shape, NaN, unknown MP, bad config) is a
:class:`CpmpError`; the subclasses say which part was wrong. They also derive from the
matching built-in (``ValueError``, ``KeyError``, ``OSError``) so generic handlers keep working.
:func:`require` is the check an optional layer makes before it imports the packages of its
extra (a :class:`MissingExtraError` names the extra to install).
"""

from __future__ import annotations

import importlib.util


class CpmpError(Exception):
    """Base class of every user-facing cpmp error."""


class DataError(CpmpError, ValueError):
    """Demonstration data is malformed: shapes, NaN/inf, time order, missing labels."""


class UnknownMPError(CpmpError, ValueError):
    """A movement primitive or control variable name is not known to the model."""


class ConfigError(CpmpError, ValueError):
    """A configuration value is invalid (unknown option, negative count, bad threshold)."""


class CpmpFileError(CpmpError, OSError):
    """A file is missing, unreadable, or not in the expected cpmp format."""


class CheckpointFormatError(CpmpFileError):
    """A readable checkpoint of another format.

    Attributes:
        found: the file's ``"format"`` entry (``None`` where it has none).
        damaged: the file's content does not match its stored checksum either, so ``found``
            may itself be damaged.
    """

    def __init__(self, message: str, found: object = None, damaged: bool = False) -> None:
        super().__init__(message)
        self.found = found
        self.damaged = damaged


class NotFittedError(CpmpError, RuntimeError):
    """A model was used before it was fitted or loaded."""


class MissingExtraError(CpmpError, ImportError):
    """An optional part of cpmp was used without the extra that installs its dependencies.

    The message names the extra: ``pip install 'cpmp[sim]'``. Raised by :func:`require`
    where an optional layer starts (``cpmp.sim``, ``cpmp.recordings``, ``cpmp.importers``, the
    ``sklearn_klr`` and ``dtw`` predictors, the jobs).

    Attributes:
        name: the missing module (``mujoco``), as :class:`ImportError` has it.
        extra: the extra that installs it (``sim``).
    """

    def __init__(self, message: str, extra: str = "", name: str | None = None) -> None:
        super().__init__(message, name=name)
        self.extra = extra


def require(module: str, extra: str, needed_by: str) -> None:
    """Check that ``module`` can be imported before an optional layer imports it.

    Cheap: a module already imported is looked up, another is only found, not run.

    Args:
        module: the module the layer imports (``mujoco``, ``sklearn``).
        extra: the extra of pyproject.toml that installs it (``sim``, ``baselines``).
        needed_by: what needs it, for the message (``cpmp.sim``).

    Raises:
        MissingExtraError: ``module`` (or a package above it) is not installed.
    """
    try:
        found = importlib.util.find_spec(module) is not None
    except ImportError:  # a parent package is missing
        found = False
    if not found:
        raise MissingExtraError(
            f"{needed_by}: {module} is not installed; install cpmp's [{extra}] extra: "
            f"pip install 'cpmp[{extra}]' (or 'cpmp[all]' for everything)",
            extra=extra,
            name=module,
        )


__all__ = [
    "CheckpointFormatError",
    "ConfigError",
    "CpmpError",
    "CpmpFileError",
    "DataError",
    "MissingExtraError",
    "NotFittedError",
    "UnknownMPError",
]
