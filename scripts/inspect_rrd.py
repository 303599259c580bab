"""Summarise cpmp episode recordings: episode, ticks, duration, transitions, outcome.

Usage: ``python scripts/inspect_rrd.py FILE.rrd [MORE.rrd ...] [--json]``

With ``--json`` each file is printed as one JSON object per line (``path`` plus the fields of
:class:`cpmp.experiment.recording.RecordingSummary`). Exit status 2 if any file could not be
read (one ``error:`` line per bad file on stderr); the other files are still summarised.
"""

from __future__ import annotations

import argparse
import json
import sys

from cpmp.errors import CpmpFileError
from cpmp.experiment.recording import format_summary, read_recording


def main(argv: list[str] | None = None) -> int:
    """Run the CLI on ``argv`` (default ``sys.argv[1:]``); returns the exit status."""
    parser = argparse.ArgumentParser(prog="inspect_rrd", description=__doc__.splitlines()[0])
    parser.add_argument("files", nargs="+", metavar="FILE.rrd", help="rerun recordings")
    parser.add_argument("--json", action="store_true", help="one JSON object per file and line")
    args = parser.parse_args(argv)

    status = 0
    for index, path in enumerate(args.files):
        try:
            summary = read_recording(path)
        except CpmpFileError as err:
            print(f"inspect_rrd: error: {err}", file=sys.stderr)
            status = 2
            continue
        if args.json:
            print(json.dumps({"path": path, **summary.to_dict()}))
        else:
            if index:
                print()
            print(f"== {path}")
            print(format_summary(summary))
    return status


if __name__ == "__main__":
    sys.exit(main())
