"""The ``dask`` executor of :mod:`cpmp.experiment.executors`: the jobs of the other backends
with the same results on a Dask ``LocalCluster`` of two worker processes (one torch thread
each, their log lines labelled in this process), a job's user error re-raised with its type,
the cluster closed on exit, and a bad ``executor`` node or scheduler refused with a message
saying what to set."""

from __future__ import annotations

import logging
import os
import sys
import time
from typing import Any

import pytest
from test_executors import (  # its jobs travel by value (it registers itself with cloudpickle)
    compose_cfg,
    job_identity,
    job_user_error,
    squares_with_followers,
)

from cpmp.errors import ConfigError, DataError, MissingExtraError
from cpmp.experiment.config import experiment_job
from cpmp.experiment.executors import (
    DaskExecutor,
    InlineExecutor,
    Submission,
    job_slots,
    make_executor,
    run_queue,
)
from cpmp.experiment.settings import ExecutorSettings

distributed = pytest.importorskip("distributed")


def torch_threads(x: int) -> tuple[int, int]:
    """A job's result: ``x`` and the torch threads of the process that ran it."""
    import torch

    return x, torch.get_num_threads()


@pytest.fixture(scope="module")
def dask_executor() -> Any:
    """One entered ``dask`` executor: its own ``LocalCluster`` of two processes (shared by the
    tests of this module: a cluster and its workers' imports take seconds)."""
    executor = DaskExecutor(ExecutorSettings(), 2)
    with executor:
        yield executor


class Reentrant:
    """``executor`` whose ``with`` leaves it open (the fixture closes it)."""

    def __init__(self, executor: DaskExecutor) -> None:
        self.executor = executor

    def __getattr__(self, name: str) -> Any:
        return getattr(self.executor, name)

    def __enter__(self) -> DaskExecutor:
        return self.executor

    def __exit__(self, *exc: object) -> None:
        return None


def test_dask_runs_the_jobs_of_inline_with_the_same_results(dask_executor, caplog):
    """The jobs (two, each queueing a follower) give inline's results, in other processes,
    one torch thread each; their log lines reach this process labelled with their job."""
    with caplog.at_level(logging.INFO, logger="cpmp"):
        results, pids = squares_with_followers(Reentrant(dask_executor))
        deadline = time.monotonic() + 5  # the records travel beside the results
        want_line = "[after 2] job 20 ran"
        while want_line not in caplog.messages and time.monotonic() < deadline:
            time.sleep(0.05)
    inline, _ = squares_with_followers(InlineExecutor())
    assert results == inline == {1: 1, 2: 4, ("after", 1): 100, ("after", 2): 400}
    assert os.getpid() not in pids
    assert want_line in caplog.messages and "[x=1] job 1 ran" in caplog.messages
    futures = [dask_executor.submit(torch_threads, x, label=f"t{x}") for x in (1, 2)]
    assert [f.result() for f in futures] == [(1, 1), (2, 1)]


def test_a_jobs_user_error_reaches_the_caller_with_its_type(dask_executor):
    with pytest.raises(DataError, match="job 7: no demonstrations"):
        run_queue(
            dask_executor,
            iter([Submission(7, job_user_error, (7,), "x=7"), None]).__next__,
            lambda key, result: None,
        )
    assert dask_executor.submit(job_identity, 3, label="after the error").result()[0] == 9


def test_a_cluster_at_an_address_runs_the_jobs_and_stays_up(dask_executor, caplog):
    """An executor of ``executor.address`` (here the fixture's running cluster) runs the jobs,
    its log lines labelled, and leaves the cluster running when it closes."""
    address = dask_executor.cluster.scheduler_address
    executor = make_executor("dask", ExecutorSettings(address=address), 2)
    with caplog.at_level(logging.INFO, logger="cpmp"):
        results, _ = squares_with_followers(executor)
        deadline = time.monotonic() + 5
        while "[after 1] job 10 ran" not in caplog.messages and time.monotonic() < deadline:
            time.sleep(0.05)
    assert results == {1: 1, 2: 4, ("after", 1): 100, ("after", 2): 400}
    assert "[after 1] job 10 ran" in caplog.messages
    assert executor.cluster is None and executor.client is None
    assert dask_executor.submit(job_identity, 4, label="still up").result()[0] == 16


def test_the_executor_closes_the_cluster_it_started():
    """On exit the client and the cluster are closed, and the scheduler's log level (quiet
    while the cluster ran in this process) is back."""
    executor = make_executor("dask", ExecutorSettings(), 1)
    assert isinstance(executor, DaskExecutor)
    level = logging.getLogger("distributed").level
    with executor:
        cluster, client = executor.cluster, executor.client
        assert cluster is not None and client is not None
        assert len(cluster.workers) == 1
    assert executor.cluster is None and executor.client is None
    assert client.status == "closed"
    assert cluster.status.name == "closed"
    assert logging.getLogger("distributed").level == level


def test_slots_on_a_dask_cluster():
    """A local cluster has one worker per core at most; a cluster at an address takes every
    job ready (its scheduler queues them)."""
    remote = ExecutorSettings(address="tcp://10.0.0.5:8786")
    assert job_slots("dask", remote, None, 40) == 40
    assert job_slots("dask", remote, None, 40, auto=3) == 3
    assert job_slots("dask", remote, 5, 40) == 5
    assert job_slots("dask", ExecutorSettings(), None, 40) <= (os.cpu_count() or 1)


# ------------------------------------------------------------------------------- errors
@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"adress": "tcp://h:1"}, r"unknown option\(s\) executor\.adress; valid: .*address"),
        ({"connect_timeout": 0}, r"executor\.connect_timeout must be an integer >= 1"),
        ({"address": ""}, r"executor\.address must be a Dask scheduler address"),
    ],
)
def test_a_bad_dask_option_is_refused(options, message):
    with pytest.raises(ConfigError, match=message):
        ExecutorSettings.from_cfg(options)


@pytest.mark.parametrize(
    ("address", "why"),
    [("http://host:8786", "unknown address scheme 'http'"), ("host", "missing port number")],
)
def test_a_bad_address_is_refused_before_the_job(address, why):
    cfg = compose_cfg("experiment", ["experiment.executor=dask", f"executor.address={address}"])
    with pytest.raises(ConfigError, match=rf"is not a Dask scheduler address \({why}.*tcp://"):
        experiment_job(cfg)


def test_no_scheduler_at_the_address_says_what_to_do():
    settings = ExecutorSettings(address="tcp://127.0.0.1:9", connect_timeout=1)
    executor = DaskExecutor(settings, 2)
    with pytest.raises(ConfigError, match=r"no Dask scheduler answered at .*127\.0\.0\.1:9"):
        executor.__enter__()
    assert executor.client is None


def test_without_distributed_the_error_names_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)
    with pytest.raises(MissingExtraError, match=r"pip install 'cpmp\[jobs\]'") as caught:
        make_executor("dask", ExecutorSettings(), 2)
    assert caught.value.extra == "jobs"
