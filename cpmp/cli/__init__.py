"""The command line: every ``cpmp-*`` command and ``scripts/*.py`` wrapper starts here.

``compose`` composes a job's Hydra config from ``conf/`` and the overrides, ``checks`` checks a
command line before anything heavy is imported (a bad option is one ``error:`` line and exit
status 2), ``main`` runs the job of each command.
"""

from cpmp.errors import require as _require

_require("hydra", "jobs", "the cpmp-* commands")
