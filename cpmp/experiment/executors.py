"""What runs the jobs of the main job and of the comparison: one interface, four backends.

A job is a call of a module-level function on picklable arguments (a seed's collection, a
(seed, D) training size, a comparison's (world, seed, row, D) fit). :class:`JobExecutor`
submits it and returns a future (``done()``, ``result()``); :meth:`JobExecutor.wait_first`
waits for the first of several to finish; :func:`run_queue` keeps ``slots`` jobs in flight,
handing each result to the scheduler, which may then queue more (a seed's training sizes once
its collection is done). The backends (``experiment.executor``, :func:`make_executor`):

- ``inline`` (:class:`InlineExecutor`): each job runs in this process when submitted, one
  after the other (for debugging and tests);
- ``local`` (:class:`LocalExecutor`): a pool of spawned worker processes on this machine, one
  torch thread each, every worker's log records sent to this process prefixed with their job
  (with one worker: in this process, as ``inline``);
- ``submitit`` (:class:`SubmititExecutor`): one ``submitit`` job per job, as a local process
  (``executor.cluster=local``) or a SLURM job (``slurm``), its call, result and log in
  ``executor.folder``;
- ``dask`` (:class:`DaskExecutor`): one task per job on a Dask ``distributed`` cluster, an
  existing one (``executor.address=tcp://host:8786``) or a ``LocalCluster`` of ``workers``
  processes started for the run; one torch thread per job, its log records sent to this
  process prefixed with their job (``distributed`` is imported only by this backend).

Which backend for what (measured by ``scripts/bench_executors.py``; the numbers are in
docs/guide.md, "Running the jobs on a Dask cluster"): ``local`` on one machine, ``dask`` on a
Dask cluster that already runs (its calls and results need no shared folder), ``submitit`` on
SLURM, ``inline`` for jobs shorter than a worker's start.

Every job seeds itself and depends only on its arguments, so the numbers do not depend on the
backend, the worker count or the order in which jobs finish (tested).
"""

from __future__ import annotations

import contextlib
import logging
import logging.handlers
import multiprocessing
import multiprocessing.queues
import os
import re
import sys
import threading
import time
import uuid
from collections.abc import Callable, Hashable, Iterable, Iterator
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, Generic, NamedTuple, NoReturn, Protocol, TypeVar

if TYPE_CHECKING:
    import distributed
    import submitit

from cpmp.errors import ConfigError, CpmpError
from cpmp.experiment.settings import EXECUTORS, ExecutorSettings
from cpmp.records import JsonValue

log = logging.getLogger(__name__)

R = TypeVar("R")
"""A job's result."""
R_co = TypeVar("R_co", covariant=True)
"""A future's result."""
K = TypeVar("K", bound=Hashable)
"""What a scheduler calls its jobs (:class:`Submission`)."""

POLL_S = 0.2
"""How often [s] :class:`SubmititExecutor` looks whether a job finished (a file check; on
SLURM submitit asks ``sacct`` at most once a minute)."""


class JobFuture(Protocol[R_co]):
    """A submitted job: ``concurrent.futures.Future``'s ``done`` and ``result``."""

    def done(self) -> bool:
        """Whether the job finished (with a result or an error)."""
        ...

    def result(self) -> R_co:
        """The job's result, waiting for it; re-raises the job's exception."""
        ...


class JobExecutor:
    """Runs jobs; a context manager that releases what it started on exit.

    Attributes:
        name: the backend (:data:`~cpmp.experiment.settings.EXECUTORS`).
        slots: how many jobs the schedulers keep in flight at once.
    """

    name = ""

    def __init__(self, slots: int = 1) -> None:
        self.slots = max(1, int(slots))

    def submit(self, fn: Callable[..., R], *args: object, label: str = "") -> JobFuture[R]:
        """Run ``fn(*args)`` as a job.

        Args:
            fn: a module-level function (pickled to the workers).
            *args: its picklable arguments.
            label: the job in words (``seed 0 D=3``): the prefix of its log lines.

        Returns:
            The job's future.
        """
        raise NotImplementedError

    def wait_first(self, futures: Iterable[JobFuture[R]]) -> list[JobFuture[R]]:
        """Wait until at least one of ``futures`` is done; return every done one."""
        futures = list(futures)
        while True:
            done = [f for f in futures if f.done()]
            if done or not futures:
                return done
            time.sleep(POLL_S)

    def __enter__(self) -> JobExecutor:
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        trace: TracebackType | None,
    ) -> None:
        self.close()

    def close(self) -> None:
        """Release what entering took (leaving the ``with`` block calls it); nothing here."""


class _Done(Generic[R]):
    """The future of a job that already ran and returned ``value``."""

    def __init__(self, value: R) -> None:
        self._value = value

    def done(self) -> bool:
        return True

    def result(self) -> R:
        return self._value


class _Failed:
    """The future of a job that already ran and raised ``error``."""

    def __init__(self, error: BaseException) -> None:
        self._error = error

    def done(self) -> bool:
        return True

    def result(self) -> NoReturn:
        raise self._error


class InlineExecutor(JobExecutor):
    """Each job runs in this process when it is submitted (one slot, submission order)."""

    name = "inline"

    def __init__(self) -> None:
        super().__init__(1)

    def submit(self, fn: Callable[..., R], *args: object, label: str = "") -> JobFuture[R]:
        """Run ``fn(*args)`` now; its future holds the result or the exception."""
        try:
            return _Done(fn(*args))
        except Exception as err:  # handed back by result(), as a pool's future does
            return _Failed(err)


# --------------------------------------------------------------- local: spawned processes
def default_workers(n_jobs: int) -> int:
    """``min(cores, n_jobs)``: the worker count of ``experiment.workers: null``."""
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        cores = os.cpu_count() or 1
    return max(1, min(cores, n_jobs))


def one_thread() -> None:
    """Worker start-up: one torch thread.

    A second busy thread per process on a machine of few cores slows every process down, and
    one thread everywhere keeps the numbers those of this process.
    """
    import torch  # lazy: the executors are chosen before torch is needed

    torch.set_num_threads(1)


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
def _no_bars() -> Iterator[None]:
    """``TQDM_DISABLE=1`` while jobs start, restored afterwards.

    Jobs show no progress bars (two would overwrite each other; the main process reports their
    progress): tqdm reads ``TQDM_DISABLE`` when imported, and spawned processes, submitit's
    local processes and SLURM jobs inherit the environment they are started with.
    """
    bars = os.environ.get("TQDM_DISABLE")
    os.environ["TQDM_DISABLE"] = "1"
    try:
        yield
    finally:
        if bars is None:
            os.environ.pop("TQDM_DISABLE", None)
        else:
            os.environ["TQDM_DISABLE"] = bars


@contextlib.contextmanager
def spawned_pool(
    workers: int, initializer: Callable[..., None], initargs: tuple
) -> Iterator[ProcessPoolExecutor]:
    """A ``ProcessPoolExecutor`` of ``workers`` spawned processes, shut down on exit.

    Each worker starts with ``initializer(*initargs)`` and without progress bars
    (:func:`_no_bars`).
    """
    with _no_bars():
        context = multiprocessing.get_context("spawn")
        pool = ProcessPoolExecutor(workers, context, initializer=initializer, initargs=initargs)
        try:
            yield pool
        finally:
            pool.shutdown(wait=True, cancel_futures=True)


def _init_worker(queue: multiprocessing.queues.Queue[logging.LogRecord], level: int) -> None:
    """Worker start-up: one torch thread, every log record sent to the main process."""
    one_thread()
    handler = logging.handlers.QueueHandler(queue)
    handler.addFilter(_JobPrefix())
    root = logging.getLogger()
    root.handlers = [handler]
    root.setLevel(level)


def _labelled(label: str, function: Callable[..., R], *args: object) -> R:
    """In a worker: ``function(*args)`` with every log line prefixed with ``label``."""
    global _JOB_LABEL
    _JOB_LABEL = label
    return function(*args)


class LocalExecutor(JobExecutor):
    """A pool of ``workers`` spawned processes on this machine (the ``local`` backend).

    One torch thread per worker; the workers' log records reach this process's handlers,
    prefixed with their job's label.
    """

    name = "local"

    def __init__(self, workers: int) -> None:
        super().__init__(workers)
        self._stack = contextlib.ExitStack()
        self._pool: ProcessPoolExecutor | None = None

    def __enter__(self) -> LocalExecutor:
        queue = multiprocessing.get_context("spawn").Queue()
        listener = logging.handlers.QueueListener(queue, _Dispatch())
        level = logging.getLogger("cpmp").getEffectiveLevel()
        listener.start()
        self._stack.callback(listener.stop)
        try:
            self._pool = self._stack.enter_context(
                spawned_pool(self.slots, _init_worker, (queue, level))
            )
        except BaseException:
            self._stack.close()
            raise
        return self

    def close(self) -> None:
        """Stop the pool and the log listener."""
        self._pool = None
        self._stack.close()

    def submit(self, fn: Callable[..., R], *args: object, label: str = "") -> JobFuture[R]:
        """Queue ``fn(*args)`` on the pool, its log lines prefixed with ``label``."""
        if self._pool is None:
            raise RuntimeError("submit a job inside `with LocalExecutor(...):`")
        return self._pool.submit(_labelled, label, fn, *args)

    def wait_first(self, futures: Iterable[JobFuture[R]]) -> list[JobFuture[R]]:
        """``concurrent.futures.wait`` for the first of the pool's futures."""
        futures = list(futures)
        if not futures:
            return []
        done, _ = wait(futures, return_when=FIRST_COMPLETED)  # type: ignore[arg-type]
        return [f for f in futures if f in done]


# ----------------------------------------------------------------- submitit: local or SLURM
class _Raised(NamedTuple):
    """A :class:`~cpmp.errors.CpmpError` a submitit job raised, re-raised by its future."""

    error: CpmpError


def _submitit_call(label: str, level: int, fn: Callable[..., R], *args: object) -> R | _Raised:
    """In a submitit job: one torch thread, log lines prefixed with ``label``, ``fn(*args)``.

    The log lines go to the job's standard error (``<folder>/<job id>_0_log.err``).
    """
    one_thread()
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(
        logging.Formatter(f"[%(asctime)s][%(name)s][%(levelname)s] [{label}] %(message)s")
    )
    root = logging.getLogger()
    root.handlers = [handler]
    root.setLevel(level)
    try:
        return fn(*args)
    except CpmpError as err:  # a user error keeps its type (submitit would wrap it)
        return _Raised(err)


class _SubmititFuture(Generic[R_co]):
    """A submitit job's future: its ``result()`` re-raises a user error with its own type."""

    def __init__(self, job: submitit.Job[R_co | _Raised], label: str) -> None:
        self.job = job
        self.label = label

    def done(self) -> bool:
        return bool(self.job.done())

    def result(self) -> R_co:
        value = self.job.result()
        if isinstance(value, _Raised):
            raise value.error
        return value


def _job_name(label: str) -> str:
    """A SLURM job name for ``label``: ``cpmp_seed_0_D=3``."""
    return "cpmp_" + re.sub(r"[^\w=.-]+", "_", label).strip("_") if label else "cpmp"


def submitit_parameters(settings: ExecutorSettings) -> dict[str, JsonValue]:
    """``submitit.AutoExecutor.update_parameters``'s arguments for the ``executor`` node.

    ``time`` and ``cpus_per_task`` are submitit's generic ``timeout_min`` and
    ``cpus_per_task`` (they apply to ``cluster=local`` too); the others are ``slurm_*``.
    """
    slurm = settings.slurm
    out: dict[str, JsonValue] = {
        "timeout_min": slurm.time,
        "cpus_per_task": slurm.cpus_per_task,
        "slurm_array_parallelism": slurm.array_parallelism,
    }
    if slurm.partition:
        out["slurm_partition"] = slurm.partition
    if slurm.mem:
        out["slurm_mem"] = slurm.mem
    out.update({f"slurm_{key}": value for key, value in slurm.extra.items()})
    return out


class SubmititExecutor(JobExecutor):
    """One submitit job per job: a local process or a SLURM job (the ``submitit`` backend).

    Each job's call, result and log are in ``settings.folder``; a job runs one torch thread
    and writes its log lines, prefixed with its label, to its ``<job id>_0_log.err``. Jobs
    still running when the executor exits with an error are cancelled.
    """

    name = "submitit"

    def __init__(self, settings: ExecutorSettings, slots: int) -> None:
        super().__init__(slots)
        settings.check(self.name)
        import submitit  # lazy: only this backend needs it

        self.folder = Path(str(settings.folder))
        self.cluster = settings.cluster
        self._executor = submitit.AutoExecutor(folder=self.folder, cluster=settings.cluster)
        try:
            self._executor.update_parameters(**submitit_parameters(settings))
        except NameError as err:  # submitit's unknown parameter
            raise ConfigError(f"executor.slurm: {err}") from None
        self._futures: list[_SubmititFuture[object]] = []

    def submit(self, fn: Callable[..., R], *args: object, label: str = "") -> JobFuture[R]:
        """Submit ``fn(*args)`` as a submitit job named after ``label``."""
        level = logging.getLogger("cpmp").getEffectiveLevel()
        self._executor.update_parameters(name=_job_name(label))
        with _no_bars():
            job = self._executor.submit(_submitit_call, label, level, fn, *args)
        log.info(
            "%s: submitit job %s (%s), log %s", label, job.job_id, self.cluster, job.paths.stderr
        )
        future: _SubmititFuture[R] = _SubmititFuture(job, label)
        self._futures.append(future)
        return future

    def close(self) -> None:
        """Cancel the jobs that have not finished."""
        for future in self._futures:
            if not future.done():
                future.job.cancel(check=False)
        self._futures.clear()


# --------------------------------------------------------------- dask: a distributed cluster
class _ForwardRecords(logging.Handler):
    """In a Dask task: send the records of this task's thread to the client, labelled.

    Each record, its message prefixed with ``[label]``, becomes an event of ``topic`` on the
    scheduler, which the client that submitted the task handles (:class:`DaskExecutor`).
    """

    def __init__(self, worker: distributed.Worker, topic: str, label: str) -> None:
        super().__init__()
        self.worker = worker
        self.topic = topic
        self.label = label
        self.thread = threading.get_ident()

    def emit(self, record: logging.LogRecord) -> None:
        if record.thread != self.thread:  # another task's (a worker of several threads)
            return
        try:
            message = record.getMessage()
            attributes = dict(record.__dict__)
            attributes["msg"] = f"[{self.label}] {message}" if self.label else message
            attributes["args"] = None
            if record.exc_info:
                attributes["exc_text"] = logging.Formatter().formatException(record.exc_info)
            attributes["exc_info"] = None
            attributes.pop("message", None)
            self.worker.log_event(self.topic, attributes)
        except Exception:
            self.handleError(record)


def _dask_call(topic: str, label: str, level: int, fn: Callable[..., R], *args: object) -> R:
    """In a Dask task: one torch thread, no progress bars, log records to the client.

    The records of ``cpmp`` (at ``level``) and the warnings of every other logger go to the
    client as events of ``topic`` while ``fn(*args)`` runs.
    """
    from distributed import get_worker  # lazy: the worker has it

    one_thread()
    os.environ["TQDM_DISABLE"] = "1"  # read when tqdm is first imported in this worker
    handler = _ForwardRecords(get_worker(), topic, label)
    root, ours = logging.getLogger(), logging.getLogger("cpmp")
    before = ours.level
    ours.setLevel(level)
    root.addHandler(handler)
    try:
        return fn(*args)
    finally:
        root.removeHandler(handler)
        ours.setLevel(before)


def _dispatch_event(event: tuple[float, dict[str, object]]) -> None:
    """The client's side of :class:`_ForwardRecords`: a record to this process's logger."""
    _, attributes = event
    _DISPATCH.emit(logging.makeLogRecord(attributes))


_DISPATCH = _Dispatch()
"""The handler of :func:`_dispatch_event`."""


class DaskExecutor(JobExecutor):
    """One Dask task per job on a ``distributed`` cluster (the ``dask`` backend).

    ``settings.address`` names the scheduler of a running cluster (``tcp://host:8786``; its
    workers must import cpmp and the same packages); ``None`` starts a ``LocalCluster`` of
    ``slots`` worker processes, one thread each, closed on exit. A job runs one torch thread;
    its log records reach this process's handlers prefixed with its label; its exception is
    re-raised with its type by its future's ``result()``. On exit the client closes: jobs not
    started are dropped (a job already running on a shared cluster finishes its call).
    """

    name = "dask"

    def __init__(self, settings: ExecutorSettings, slots: int) -> None:
        super().__init__(slots)
        settings.check(self.name)
        self.address = settings.address
        self.connect_timeout = settings.connect_timeout
        self.topic = f"cpmp-log-{uuid.uuid4().hex}"
        self.cluster: distributed.LocalCluster | None = None
        self.client: distributed.Client | None = None
        self._quiet: int | None = None

    def __enter__(self) -> DaskExecutor:
        from distributed import Client, LocalCluster  # lazy: only this backend needs it

        try:
            with _no_bars():
                if self.address is None:
                    # its scheduler runs in this process: its INFO lines are not the job's
                    scheduler_log = logging.getLogger("distributed")
                    self._quiet = scheduler_log.level
                    scheduler_log.setLevel(max(logging.WARNING, self._quiet))
                    self.cluster = LocalCluster(
                        n_workers=self.slots,
                        threads_per_worker=1,
                        processes=True,
                        dashboard_address=None,  # no dashboard; its health page: any port
                        scheduler_kwargs={"dashboard_address": ":0"},
                    )
                    self.client = Client(self.cluster)
                else:
                    self.client = self._connect(Client)
            self.client.subscribe_topic(self.topic, _dispatch_event)
        except BaseException:
            self.close()
            raise
        log.info("dask: %d jobs at once on %s", self.slots, self.client.scheduler.address)
        return self

    def _connect(self, client: type[distributed.Client]) -> distributed.Client:
        """A client of the scheduler at ``self.address``.

        Raises:
            ConfigError: no scheduler answered within ``connect_timeout`` seconds.
        """
        try:
            return client(self.address, timeout=self.connect_timeout)
        except (OSError, TimeoutError) as err:
            raise ConfigError(
                f"no Dask scheduler answered at executor.address={self.address} within "
                f"{self.connect_timeout} s ({type(err).__name__}: {err}): start one there "
                "(`dask scheduler`, then `dask worker <address>` on each machine), fix the "
                "address, raise executor.connect_timeout, or set executor.address=null for a "
                "local Dask cluster"
            ) from None

    def close(self) -> None:
        """Close the client and the local cluster (if this executor started one)."""
        client, cluster = self.client, self.cluster
        self.client = self.cluster = None
        try:
            if client is not None:
                with contextlib.suppress(Exception):
                    client.unsubscribe_topic(self.topic)
                client.close()
            if cluster is not None:
                cluster.close()
        finally:
            if self._quiet is not None:
                logging.getLogger("distributed").setLevel(self._quiet)
                self._quiet = None

    def submit(self, fn: Callable[..., R], *args: object, label: str = "") -> JobFuture[R]:
        """Submit ``fn(*args)`` as a Dask task (its key named after ``label``)."""
        if self.client is None:
            raise RuntimeError("submit a job inside `with DaskExecutor(...):`")
        level = logging.getLogger("cpmp").getEffectiveLevel()
        key = f"{_job_name(label)}-{uuid.uuid4().hex}"
        return self.client.submit(_dask_call, self.topic, label, level, fn, *args, key=key)

    def wait_first(self, futures: Iterable[JobFuture[R]]) -> list[JobFuture[R]]:
        """``distributed.wait`` for the first of the futures."""
        from distributed import wait as dask_wait

        futures = list(futures)
        if not futures:
            return []
        done, _ = dask_wait(futures, return_when="FIRST_COMPLETED")
        return [f for f in futures if f in done]


def make_executor(name: str, settings: ExecutorSettings, workers: int) -> JobExecutor:
    """The backend ``name`` (``experiment.executor``) with ``workers`` jobs at once.

    ``local`` with one worker runs in this process (``inline``).

    Args:
        name: ``inline``, ``local``, ``submitit`` or ``dask``.
        settings: the ``executor`` node (``submitit`` and ``dask`` only).
        workers: jobs in flight at once (worker processes of ``local`` and of ``dask``'s local
            cluster).

    Raises:
        ConfigError: an unknown name (naming the valid ones); ``submitit`` without a folder;
            ``dask`` with a bad address.
        MissingExtraError: ``submitit`` or ``dask`` without its package (the ``jobs`` extra).
    """
    if name not in EXECUTORS:
        raise ConfigError(
            f"experiment.executor must be one of {', '.join(EXECUTORS)}, got {name!r}"
        )
    if name == "submitit":
        return SubmititExecutor(settings, workers)
    if name == "dask":
        return DaskExecutor(settings, workers)
    if name == "local" and workers > 1:
        return LocalExecutor(workers)
    return InlineExecutor()


def job_slots(
    name: str,
    settings: ExecutorSettings,
    workers: int | None,
    n_jobs: int,
    auto: int | None = None,
) -> int:
    """How many of ``n_jobs`` jobs run at once: ``experiment.workers`` or its default.

    Args:
        name: the executor (``experiment.executor``).
        settings: the ``executor`` node.
        workers: ``experiment.workers`` (``None``: the default).
        n_jobs: how many jobs there are (the most that can run at once).
        auto: the default's cap besides the cores (the main job: its seeds; ``None``:
            ``n_jobs``).

    Returns:
        1 for ``inline``; else ``workers``, by default :func:`default_workers` (one per core,
        at most ``auto``), on SLURM ``executor.slurm.array_parallelism``, on a Dask cluster at
        ``executor.address`` ``auto`` (every job ready: its scheduler queues them); at most
        ``n_jobs``.
    """
    if name == "inline":
        return 1
    if workers is None:
        on_slurm = name == "submitit" and settings.cluster == "slurm"
        on_dask_cluster = name == "dask" and settings.address is not None
        cap = n_jobs if auto is None else auto
        if on_slurm:
            workers = settings.slurm.array_parallelism
        else:
            workers = cap if on_dask_cluster else default_workers(cap)
    return max(1, min(workers, n_jobs))


@dataclass(frozen=True)
class Submission(Generic[K, R]):
    """A job for :func:`run_queue`: its key, function, arguments and label."""

    key: K
    """What the scheduler calls it (handed back with its result)."""
    fn: Callable[..., R]
    """A module-level function."""
    args: tuple[object, ...]
    """Its picklable arguments."""
    label: str
    """The job in words (its log lines' prefix)."""


def run_queue(
    executor: JobExecutor,
    next_job: Callable[[], Submission[K, R] | None],
    finished: Callable[[K, R], None],
) -> None:
    """Keep ``executor.slots`` jobs in flight until ``next_job`` has none left.

    Args:
        executor: an entered executor.
        next_job: the next job to submit, or ``None`` for none now (it may have more after
            a result came back).
        finished: ``finished(key, result)`` of every job, as it finishes (the jobs finished
            at the same time in submission order); it may make ``next_job`` give more.

    Raises:
        Exception: the first job error, as the job raised it.
    """
    pending: dict[JobFuture[R], tuple[int, K]] = {}
    submitted = 0
    while True:
        while len(pending) < executor.slots and (job := next_job()) is not None:
            future = executor.submit(job.fn, *job.args, label=job.label)
            pending[future] = (submitted, job.key)
            submitted += 1
        if not pending:
            return
        for future in sorted(executor.wait_first(pending), key=lambda f: pending[f][0]):
            _, key = pending.pop(future)
            finished(key, future.result())
