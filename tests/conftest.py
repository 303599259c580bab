"""Shared fixtures: small synthetic demonstrations, a fitted sequencer, a demonstration file with
splits, and running the ``scripts/`` entry points (to the end, or in the background next to an
in-process run)."""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Callable, Iterator
from contextlib import AbstractContextManager, contextmanager
from dataclasses import dataclass
from pathlib import Path

import pytest
import torch

from cpmp.data import save_demonstrations
from cpmp.sequencer import ConcurrentSequencer
from cpmp.worlds.two_point import make_demonstrations

ROOT = Path(__file__).resolve().parents[1]
STDERR_TAIL = 3000
"""Characters of a failed script's stderr shown in the assertion message (its traceback)."""

# One thread: on 2 cores, torch's default thread pool fights with other processes and makes
# the small fits of the tests many times slower.
torch.set_num_threads(1)


@pytest.fixture(scope="session")
def train_demos():
    """Six synthetic two-variable demonstrations, three per strategy."""
    return make_demonstrations(6, seed=0)


@pytest.fixture(scope="session")
def test_demos():
    """Held-out synthetic demonstrations from another seed."""
    return make_demonstrations(6, seed=1)


@pytest.fixture(scope="session")
def fit_on_train(train_demos):
    """``fit_on_train(predictor, **options)``: a :class:`~cpmp.sequencer.ConcurrentSequencer`
    fitted on :func:`train_demos` with seed 0 and no logger (``options``: the predictor's and
    the sequencer's, as ``ConcurrentSequencer.fit`` takes them)."""

    def fit(predictor: str = "klr", **options):
        return ConcurrentSequencer.fit(train_demos, predictor, seed=0, logger=None, **options)

    return fit


@pytest.fixture(scope="session")
def fitted_klr(fit_on_train):
    """The default ``klr`` sequencer fitted on :func:`train_demos`."""
    return fit_on_train("klr")


def _script_argv(script: str, args: tuple[str, ...]) -> list[str]:
    return [sys.executable, f"scripts/{script}", *args]


@pytest.fixture(scope="session")
def run_script() -> Callable[..., subprocess.CompletedProcess]:
    """``run_script(script, *args, timeout=120)``: run ``scripts/<script>`` with ``args`` from
    the repository root to its end; returns the finished process (stdout, stderr as text,
    the exit status unchecked)."""

    def run(script: str, *args: str, timeout: float = 120) -> subprocess.CompletedProcess:
        return subprocess.run(
            _script_argv(script, args),
            cwd=ROOT,
            capture_output=True,
            text=True,
            timeout=timeout,
        )

    return run


@dataclass
class BackgroundScript:
    """Where a script started by :func:`script_in_background` writes.

    stdout: its standard output, complete once the ``with`` block has ended.
    stderr: its standard error.
    """

    stdout: Path
    stderr: Path


@pytest.fixture(scope="session")
def script_in_background() -> Callable[..., AbstractContextManager[BackgroundScript]]:
    """``with script_in_background(logs, script, *args, timeout=600) as run:`` starts
    ``scripts/<script>`` with ``args`` from the repository root, its output in
    ``logs/stdout.txt`` and ``logs/stderr.txt``, while the block runs; on leaving the block
    it waits for the script (at most ``timeout`` seconds) and asserts that it succeeded,
    showing the end of its stderr otherwise."""

    @contextmanager
    def start(
        logs: Path, script: str, *args: str, timeout: float = 600
    ) -> Iterator[BackgroundScript]:
        run = BackgroundScript(logs / "stdout.txt", logs / "stderr.txt")
        with open(run.stdout, "w") as out, open(run.stderr, "w") as err:
            proc = subprocess.Popen(
                _script_argv(script, args), cwd=ROOT, stdout=out, stderr=err, text=True
            )
            try:
                yield run
            finally:
                proc.wait(timeout=timeout)
        assert proc.returncode == 0, run.stderr.read_text()[-STDERR_TAIL:]

    return start


@pytest.fixture(scope="module")
def demo_file(tmp_path_factory) -> Path:
    """Six synthetic demonstrations (alternating strategies) in one file with splits:
    demo_0..3 are ``train``, demo_4..5 ``test``."""
    demos = make_demonstrations(6, seed=0)
    path = tmp_path_factory.mktemp("data") / "demos.h5"
    names = [d.name for d in demos]
    save_demonstrations(path, demos, splits={"train": names[:4], "test": names[4:]})
    return path
