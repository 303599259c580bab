"""``cpmp-import``: robot recordings in, one cpmp demonstration file out (a Hydra job).

Recordings: ROS 2 bags, LeRobot datasets, MimicGen-style HDF5; config ``conf/import.yaml``.

The command is checked and run like the other Hydra commands (:mod:`cpmp.cli.main`): the config
is composed with light imports, ``mapping`` and ``input`` must be set, the mapping file must exist
and parse (:func:`cpmp.importers.load_mapping`), the split must be valid; a failed check prints
one ``error:`` line and exits with status 2. The job then calls
:func:`cpmp.importers.import_recordings`, prints :func:`cpmp.importers.summary_text` (also
written to ``summary.txt`` in the run directory) and prints the written file's path last. A
failed import leaves no output file.

``on_error=skip`` (or ``on_error: skip`` in the mapping; ``on_error=raise`` on the command
line overrides a mapping's ``skip``) imports the good demonstrations and reports every skipped
one with its reason in the summary and in ``<output>.skipped.json``; when it skipped any, the
command exits with status :data:`SKIPPED_STATUS` (3) after printing the path, so scripts notice.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from omegaconf import DictConfig

from cpmp.cli.checks import Command
from cpmp.errors import ConfigError, CpmpFileError
from cpmp.io import atomic_write_text

if TYPE_CHECKING:
    from cpmp.importers import SplitSpec

# cpmp.importers (rosbags, LeRobot and HDF5 readers) is imported by the functions that use it:
# every other command's process imports this module (cpmp.cli.main lists the command)

NAME = "import"
"""The config (``conf/import.yaml``) and job name (runs go to ``logs/import/<timestamp>/``)."""

SKIPPED_STATUS = 3
"""The exit status of an import that wrote its file but skipped demonstrations
(``on_error=skip``); 0: everything imported, 2: an error and no file."""


def _inputs(cfg: DictConfig) -> list[str]:
    """``input`` as a list of paths (one path, or a list of bags)."""
    value = cfg.get("input")
    if isinstance(value, str):
        return [value]
    if isinstance(value, Sequence):
        return [str(v) for v in value]
    raise ConfigError(f"input={value!r}: give a path (or a list of bag paths)")


def split_from_cfg(cfg: DictConfig) -> SplitSpec:
    """The job's ``test_fraction``, ``seed`` and ``test`` as a :class:`SplitSpec`."""
    from cpmp.importers import SplitSpec  # lazy: see the imports above

    test = cfg.get("test") or ()
    return SplitSpec(
        test_fraction=cfg.get("test_fraction", 0.0),
        seed=cfg.get("seed", 0),
        test=tuple(str(name) for name in test),
    )


def on_error_from_cfg(cfg: DictConfig) -> str | None:
    """The job's ``on_error`` (``raise`` or ``skip``), or ``None`` for the mapping's.

    Raises:
        ConfigError: another value.
    """
    from cpmp.importers import ON_ERROR  # lazy: see the imports above

    value = cfg.get("on_error")
    if value is not None and value not in ON_ERROR:
        raise ConfigError(
            f"on_error={value!r}: give on_error=raise (a bad demonstration refuses the import) "
            "or on_error=skip (import the others and report it)"
        )
    return value


def check_import(cfg: DictConfig) -> None:
    """The mapping parses, every input exists, ``on_error`` and the split are valid.

    Raises:
        ConfigError: an invalid mapping, ``on_error`` or split.
        CpmpFileError: the mapping file or an input is missing.
    """
    from cpmp.importers import load_mapping  # lazy: see the imports above

    load_mapping(str(cfg.mapping))
    on_error_from_cfg(cfg)
    for path in _inputs(cfg):
        if not Path(path).exists():
            raise CpmpFileError(
                f"input={path}: no such file or directory (relative to {Path.cwd()})"
            )
    split_from_cfg(cfg)


def import_job(cfg: DictConfig, run_dir: Path) -> Path:
    """Import ``cfg.input`` with ``cfg.mapping`` into ``run_dir / cfg.output``.

    Returns:
        The written demonstration file.

    Raises:
        SystemExit: status :data:`SKIPPED_STATUS` when demonstrations were skipped, after the
            summary and the file's path (printed last, as the command does) were printed.
    """
    from cpmp.importers import import_recordings, summary_text  # lazy: see the imports above

    output = Path(str(cfg.output))
    output = output if output.is_absolute() else run_dir / output
    result = import_recordings(
        str(cfg.mapping),
        _inputs(cfg),
        output,
        split_from_cfg(cfg),
        on_error=on_error_from_cfg(cfg),
    )
    text = summary_text(result)
    atomic_write_text(run_dir / "summary.txt", text + "\n")
    print(text)
    if result.skipped:
        print(output, flush=True)
        sys.exit(SKIPPED_STATUS)
    return output


IMPORT_COMMAND = Command(
    NAME,
    "import robot recordings (ROS 2 bags, LeRobot datasets, MimicGen HDF5) as demonstrations",
    import_job,
    check_import,
    required=("mapping", "input"),
    files=("mapping",),
)
"""The ``cpmp-import`` command, listed in :data:`cpmp.cli.main.COMMANDS` with the others."""


__all__ = [
    "IMPORT_COMMAND",
    "SKIPPED_STATUS",
    "check_import",
    "import_job",
    "on_error_from_cfg",
    "split_from_cfg",
]
