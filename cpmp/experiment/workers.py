"""The main job's worker processes: a spawned pool running each seed's stages.

Each seed's collection and then each of its training sizes run on the pool, one torch thread
per worker, every worker's log records sent to the main process (prefixed with their job) and
handed to its handlers. :func:`spawned_pool` is the pool itself, shared with the comparison's
scheduler (:mod:`cpmp.compare.runs`).
"""

from __future__ import annotations

import contextlib
import logging
import logging.handlers
import multiprocessing
import os
from collections.abc import Callable, Iterator
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from pathlib import Path
from typing import Any, NamedTuple

import torch

from cpmp.experiment.settings import ExperimentJob


class JobResults(NamedTuple):
    """What the main job's stages gave: each seed's collection and each training size's result."""

    collected: dict[int, Any]
    """What the collection returned, by seed."""
    results: dict[tuple[int, int], Any]
    """What each training size returned, by (seed, D)."""


def default_workers(n_seeds: int) -> int:
    """``min(cores, n_seeds)``: the worker count of ``experiment.workers: null``."""
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        cores = os.cpu_count() or 1
    return max(1, min(cores, n_seeds))


_JOB_LABEL = ""
"""In a worker process: the prefix of its log lines (the job's seed and D)."""


class _JobPrefix(logging.Filter):
    """Prefix every record a worker sends to the main process with its job's label."""

    def filter(self, record: logging.LogRecord) -> bool:
        if _JOB_LABEL:
            record.msg = f"[{_JOB_LABEL}] {record.getMessage()}"
            record.args = None
        return True


class _Dispatch(logging.Handler):
    """Hands a worker's record to the main process's logger of the same name.

    So the record reaches the handlers Hydra configured: console and job log.
    """

    def emit(self, record: logging.LogRecord) -> None:
        logger = logging.getLogger(record.name)
        if logger.isEnabledFor(record.levelno):
            logger.handle(record)


@contextlib.contextmanager
def spawned_pool(
    workers: int, initializer: Callable[..., None] | None = None, initargs: tuple = ()
) -> Iterator[Any]:
    """A ``ProcessPoolExecutor`` of ``workers`` spawned processes, shut down on exit.

    Each worker starts with ``initializer(*initargs)`` (default: one torch thread).

    Workers show no progress bars (two would overwrite each other; the main process reports
    their progress): tqdm reads ``TQDM_DISABLE`` when imported, so it is set while the pool
    starts its workers and restored afterwards.
    """
    bars = os.environ.get("TQDM_DISABLE")
    os.environ["TQDM_DISABLE"] = "1"
    context = multiprocessing.get_context("spawn")
    pool = ProcessPoolExecutor(
        workers, context, initializer=initializer or one_thread, initargs=initargs
    )
    try:
        yield pool
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
        if bars is None:
            os.environ.pop("TQDM_DISABLE", None)
        else:
            os.environ["TQDM_DISABLE"] = bars


def one_thread() -> None:
    """Worker start-up: one torch thread.

    A second busy thread per process on a machine of few cores slows every process down.
    """
    torch.set_num_threads(1)


def _init_worker(queue: Any, level: int) -> None:
    """Worker start-up: one torch thread, every log record sent to the main process."""
    one_thread()
    handler = logging.handlers.QueueHandler(queue)
    handler.addFilter(_JobPrefix())
    root = logging.getLogger()
    root.handlers = [handler]
    root.setLevel(level)


def _labelled(label: str, function: Callable[..., Any], *args: Any) -> Any:
    """In a worker: ``function(*args)`` with every log line prefixed with ``label``."""
    global _JOB_LABEL
    _JOB_LABEL = label
    return function(*args)


def run_parallel(
    job: ExperimentJob,
    run_dir: Path,
    workers: int,
    collect: Callable[[ExperimentJob, Path, int], Any],
    train_size: Callable[[ExperimentJob, Path, Any, int], Any],
) -> JobResults:
    """Every seed's collection, then each of its training sizes, on spawned processes.

    The training sizes of a seed are submitted largest first, as soon as its collection is
    done.

    Args:
        job: the typed job.
        run_dir: the run directory.
        workers: the number of worker processes.
        collect: a seed's collection, ``collect(job, run_dir, seed)``.
        train_size: one training size, ``train_size(job, run_dir, collected, d)``, given
            what ``collect`` returned for its seed. Both are module-level functions (they are
            pickled to the workers).

    Returns:
        The collections by seed and the results by (seed, D).
    """
    settings = job.settings
    queue = multiprocessing.get_context("spawn").Queue()
    listener = logging.handlers.QueueListener(queue, _Dispatch())
    level = logging.getLogger("cpmp").getEffectiveLevel()
    collected: dict[int, Any] = {}
    results: dict[tuple[int, int], Any] = {}
    listener.start()
    try:
        with spawned_pool(workers, _init_worker, (queue, level)) as pool:
            pending: dict[Future, tuple[int, int | None]] = {
                pool.submit(_labelled, f"seed {seed}", collect, job, run_dir, seed): (seed, None)
                for seed in settings.seeds
            }
            while pending:
                done, _ = wait(pending, return_when=FIRST_COMPLETED)
                for future in done:
                    seed, d = pending.pop(future)
                    if d is not None:
                        results[seed, d] = future.result()
                        continue
                    collected[seed] = data = future.result()
                    for size in sorted(settings.train_sizes, reverse=True):
                        label = f"seed {seed} D={size}"
                        args = (label, train_size, job, run_dir, data, size)
                        pending[pool.submit(_labelled, *args)] = (seed, size)
    finally:
        listener.stop()
    return JobResults(collected, results)
