"""Alias of :mod:`cpmp.data.datafile`, kept so that code written against cpmp 0.1 still runs.

New code imports the file functions from :mod:`cpmp.data`
(``from cpmp.data import load_demonstrations, save_demonstrations``).
"""

from cpmp.data.datafile import (
    FORMAT_NAME,
    FORMAT_VERSION,
    list_splits,
    load_demonstrations,
    save_demonstrations,
)

__all__ = [
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "list_splits",
    "load_demonstrations",
    "save_demonstrations",
]
