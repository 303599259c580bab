"""cpmp: probabilistic progress prediction and sequencing of concurrent movement primitives."""

from cpmp.errors import (
    CheckpointFormatError,
    ConfigError,
    CpmpError,
    CpmpFileError,
    DataError,
    NotFittedError,
    UnknownMPError,
)

__version__ = "0.1.0"

__all__ = [
    "CheckpointFormatError",
    "ConfigError",
    "CpmpError",
    "CpmpFileError",
    "DataError",
    "NotFittedError",
    "UnknownMPError",
    "__version__",
]
