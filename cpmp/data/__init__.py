"""Demonstrations: the labelled record, its HDF5 file format and feature augmentation.

A :class:`Demonstration` holds one demonstration's sample times ``(n,)`` [s], features
``(n, d)`` and, per control variable, the MP active at each sample; it validates itself on
construction. :func:`save_demonstrations` / :func:`load_demonstrations` read and write the
HDF5 layout of ``docs/data_format.md`` (atomically, with train/test masks);
:func:`add_feature_noise` perturbs features for robustness studies.
"""

from cpmp.data.augment import add_feature_noise, feature_ranges, noisy_features
from cpmp.data.datafile import (
    FORMAT_NAME,
    FORMAT_VERSION,
    list_splits,
    load_demonstrations,
    save_demonstrations,
)
from cpmp.data.demonstration import (
    Activation,
    Demonstration,
    DemonstrationLog,
    mp_catalogue,
    mp_sequences,
)

__all__ = [
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "Activation",
    "Demonstration",
    "DemonstrationLog",
    "add_feature_noise",
    "feature_ranges",
    "list_splits",
    "load_demonstrations",
    "mp_catalogue",
    "mp_sequences",
    "noisy_features",
    "save_demonstrations",
]
