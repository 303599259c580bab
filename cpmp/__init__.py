"""cpmp: probabilistic progress prediction and sequencing of concurrent movement primitives.

The package exports the exception family of :mod:`cpmp.errors` (``cpmp.CpmpError``,
``cpmp.DataError``, ...; listed once, in ``cpmp.errors.__all__``) and ``__version__``.
"""

from cpmp import errors as _errors
from cpmp.errors import *  # noqa: F403 (the names of cpmp.errors.__all__)

__version__ = "0.1.0"

__all__ = [*_errors.__all__, "__version__"]
