"""cpmp: probabilistic progress prediction and sequencing of concurrent movement primitives."""

from cpmp.errors import (
    ConfigError,
    CpmpError,
    CpmpFileError,
    DataError,
    NotFittedError,
    UnknownMPError,
)

__version__ = "0.1.0"

__all__ = [
    "ConfigError",
    "CpmpError",
    "CpmpFileError",
    "DataError",
    "NotFittedError",
    "UnknownMPError",
    "__version__",
]
