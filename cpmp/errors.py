"""The one exception family cpmp raises for user errors.

Every error a user can cause (bad file, wrong shape, NaN, unknown MP, bad config) is a
:class:`CpmpError`; the subclasses say which part was wrong. They also derive from the
matching built-in (``ValueError``, ``KeyError``, ``OSError``) so generic handlers keep working.
"""

from __future__ import annotations


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


__all__ = [
    "CheckpointFormatError",
    "ConfigError",
    "CpmpError",
    "CpmpFileError",
    "DataError",
    "NotFittedError",
    "UnknownMPError",
]
