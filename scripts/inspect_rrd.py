"""Summarise cpmp episode recordings: episode, ticks, duration, transitions, outcome
(``cpmp-inspect-rrd``).

Usage: ``python scripts/inspect_rrd.py FILE.rrd [MORE.rrd ...] [--json]``

With ``--json`` each file is printed as one JSON object per line (``path`` plus the fields of
:class:`cpmp.recordings.RecordingSummary`). Exit status 2 if any file could not be
read (one ``error:`` line per bad file on stderr); the other files are still summarised.
"""

from cpmp.cli.main import inspect_rrd_entry

if __name__ == "__main__":
    inspect_rrd_entry()
