"""Where cpmp's Hydra configs are: the package ``cpmp._conf``, for every caller.

The repository's top-level ``conf/`` is installed as the package ``cpmp._conf`` (setup.py maps
it). A wheel carries a copy; an editable install (``pip install -e .``) maps the package onto
the checkout's ``conf/`` itself, so edits there take effect without reinstalling. Hydra reads
it through its ``pkg://`` search path (:data:`CONF_SEARCH_PATH`), the rest of cpmp through
:func:`conf_dir`.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

from cpmp.errors import CpmpFileError

CONF_PACKAGE = "cpmp._conf"
"""The package that holds ``conf/``'s YAML files (``experiment.yaml``, ``predictor/``, ...)."""

CONF_SEARCH_PATH = f"pkg://{CONF_PACKAGE}"
"""Hydra's name of :data:`CONF_PACKAGE` (``hydra.main(config_path=...)``)."""


def conf_dir() -> Path:
    """The folder of the configs: ``conf/`` of the checkout, or the installed copy.

    Raises:
        CpmpFileError: cpmp is imported without being installed (its configs are not a
            package), or installed zipped.
    """
    try:
        root = resources.files(CONF_PACKAGE)
    except ModuleNotFoundError:
        raise CpmpFileError(
            f"cpmp's configs (the package {CONF_PACKAGE}) are not installed: install cpmp "
            "(bash scripts/install.sh, or pip install -e . in a checkout)"
        ) from None
    if not isinstance(root, Path):
        raise CpmpFileError(f"cpmp's configs {root} are not a folder: install cpmp unzipped")
    return root
