"""Running several ``scripts/*.py`` command lines in one fresh interpreter.

A command line of a script costs a Python start and the imports of cpmp, Hydra and torch
(seconds each on a busy machine) before the command does anything; :func:`run_scripts` pays
them once for a batch of command lines, and still runs each one as ``python <script> ...``
does: the file is run as ``__main__`` (:func:`runpy.run_path`) with ``sys.argv`` set, in its
own working directory, its exit status is the one Python gives its ``SystemExit`` (an uncaught
exception prints its traceback and gives 1), and its stdout and stderr are read at file
descriptors 1 and 2, as a parent process reads them.
"""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import pytest

RUNNER = r"""
import json, os, runpy, sys, tempfile, traceback, warnings
from pathlib import Path

spec = json.loads(Path(sys.argv[1]).read_text())
results = []
for run in spec["runs"]:
    os.chdir(run["cwd"])
    sys.argv = [run["script"], *run["argv"]]
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        # catch_warnings resets the warning registries: a warning shows in every run, as in
        # a fresh process
        with warnings.catch_warnings():
            sys.stdout.flush()
            sys.stderr.flush()
            saved = os.dup(1), os.dup(2)
            os.dup2(out.fileno(), 1)
            os.dup2(err.fileno(), 2)
            try:
                runpy.run_path(run["script"], run_name="__main__")
                code = 0
            except SystemExit as done:  # the exit status Python gives SystemExit(code)
                code = 0 if done.code is None else done.code
                if not isinstance(code, int):
                    print(code, file=sys.stderr)
                    code = 1
            except BaseException:
                traceback.print_exc()
                code = 1
            finally:
                sys.stdout.flush()
                sys.stderr.flush()
                os.dup2(saved[0], 1)
                os.dup2(saved[1], 2)
                os.close(saved[0])
                os.close(saved[1])
        out.seek(0)
        err.seek(0)
        results.append(
            {"returncode": code, "stdout": out.read().decode(), "stderr": err.read().decode()}
        )
Path(spec["out"]).write_text(json.dumps(results))
"""
"""The batch runner: reads ``{"runs": [{"script", "argv", "cwd"}], "out"}`` from the JSON file
named by its argument and writes one ``{"returncode", "stdout", "stderr"}`` per run to
``out``."""


@dataclass(frozen=True)
class Ran:
    """What a finished command line left (the fields of :class:`subprocess.CompletedProcess`
    the tests read)."""

    returncode: int
    stdout: str
    stderr: str


def _run_scripts(
    runs: Sequence[tuple[Path, Sequence[str], Path]], workdir: Path, timeout: float = 600
) -> list[Ran]:
    """Run each ``(script, argv, cwd)`` of ``runs`` in turn in one fresh interpreter (see the
    module's docstring); ``workdir`` holds the batch's spec and results."""
    out = workdir / "runs.json"
    spec = {
        "runs": [{"script": str(s), "argv": list(a), "cwd": str(c)} for s, a, c in runs],
        "out": str(out),
    }
    (workdir / "spec.json").write_text(json.dumps(spec))
    proc = subprocess.run(
        [sys.executable, "-c", RUNNER, str(workdir / "spec.json")],
        cwd=workdir,
        capture_output=True,
        text=True,
        timeout=timeout,
    )
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-3000:]
    results = [Ran(**r) for r in json.loads(out.read_text())]
    assert len(results) == len(runs)
    return results


@pytest.fixture(scope="session")
def run_scripts() -> Callable[..., list[Ran]]:
    """``run_scripts(runs, workdir)``: the command lines ``(script, argv, cwd)`` of ``runs``
    run one after another in one fresh interpreter; a :class:`Ran` each."""
    return _run_scripts
