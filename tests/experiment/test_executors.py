"""The executors of :mod:`cpmp.experiment.executors`: one interface, three backends (this
process, a spawned pool, submitit's local processes) giving the same results; the comparison
run on each gives the same numbers; a bad ``experiment.executor`` or ``executor`` node fails
with a message saying what to set."""

from __future__ import annotations

import json
import logging
import os
import sys
from pathlib import Path
from typing import Any

import cloudpickle
import pytest

from cpmp.errors import ConfigError, DataError
from cpmp.experiment.executors import (
    InlineExecutor,
    LocalExecutor,
    Submission,
    SubmititExecutor,
    job_slots,
    make_executor,
    run_queue,
    submitit_parameters,
)
from cpmp.experiment.settings import EXECUTORS, ExecutorSettings, ExperimentSettings

ROOT = Path(__file__).resolve().parents[2]
CONF = ROOT / "conf"
# The jobs below are this test module's, which a submitit process cannot import by name (the
# package's job functions it can): they travel by value.
cloudpickle.register_pickle_by_value(sys.modules[__name__])
# The ``local`` backend's spawned workers import this module by name to find its jobs: only
# light modules are imported at its top (no torch, no Hydra), the heavier ones in the tests
# that use them, so that such a worker starts in a third of the CPU time (measured on 2 cores:
# 2.5 s instead of 7.5 s).


def compose_cfg(config_name: str, overrides: list[str]) -> Any:
    from hydra import compose, initialize_config_dir

    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        return compose(config_name, overrides=overrides)


# ------------------------------------------------------------ jobs (module level: pickled)
def job_identity(x: int) -> tuple[int, int]:
    """A job's result that says which process ran it."""
    logging.getLogger("cpmp.test_executors").info("job %d ran", x)
    return x * x, os.getpid()


def job_user_error(x: int) -> None:
    """A job raising a user error."""
    raise DataError(f"job {x}: no demonstrations")


def executors(tmp_path: Path) -> dict[str, Any]:
    """One executor per backend, two jobs at once where they can."""
    folder = ExecutorSettings(folder=str(tmp_path / "submitit"))
    return {
        "inline": InlineExecutor(),
        "local": LocalExecutor(2),
        "submitit": SubmititExecutor(folder, 2),
    }


def squares_with_followers(executor: Any) -> tuple[dict[Any, int], set[int]]:
    """Two jobs; each finished one queues a follower (as a collection its training sizes)."""
    queue = [Submission(x, job_identity, (x,), f"x={x}") for x in (1, 2)]
    results: dict[Any, int] = {}
    pids: set[int] = set()

    def finished(key: Any, result: tuple[int, int]) -> None:
        results[key], pid = result
        pids.add(pid)
        if isinstance(key, int):
            queue.append(Submission(("after", key), job_identity, (10 * key,), f"after {key}"))

    with executor:
        run_queue(executor, lambda: queue.pop(0) if queue else None, finished)
    return results, pids


@pytest.mark.slow
def test_every_backend_runs_the_same_jobs_where_it_says(tmp_path, caplog):
    """Each backend gives every job's result; ``inline`` runs them in this process, ``local``
    and ``submitit`` in other processes; ``local`` forwards the workers' log lines with the
    job's label, ``submitit`` writes them, labelled, into its folder."""
    want = {1: 1, 2: 4, ("after", 1): 100, ("after", 2): 400}
    for name, executor in executors(tmp_path).items():
        with caplog.at_level(logging.INFO, logger="cpmp"):
            results, pids = squares_with_followers(executor)
        assert results == want, name
        assert (pids == {os.getpid()}) == (name == "inline"), name
        messages = [r.getMessage() for r in caplog.records]
        if name == "local":
            assert "[after 2] job 20 ran" in messages
        caplog.clear()
    logs = "".join(p.read_text() for p in (tmp_path / "submitit").glob("*_log.err"))
    assert "[after 2] job 20 ran" in logs and "[x=1] job 1 ran" in logs


@pytest.mark.parametrize("name", ["inline", "local", "submitit"])
def test_a_jobs_user_error_reaches_the_caller_with_its_type(tmp_path, name):
    executor = executors(tmp_path)[name]
    with executor, pytest.raises(DataError, match="job 7: no demonstrations"):
        run_queue(
            executor,
            iter([Submission(7, job_user_error, (7,), "x=7"), None]).__next__,
            lambda key, result: None,
        )


def test_slots_and_the_local_pool_of_one_worker(tmp_path):
    """``experiment.workers`` is the jobs at once of every backend (``inline``: 1; never more
    than the jobs); its default on SLURM is the array parallelism; ``local`` with one worker
    runs in this process."""
    slurm = ExecutorSettings(folder=str(tmp_path), cluster="slurm")
    assert job_slots("inline", slurm, 4, 10) == 1
    assert job_slots("local", slurm, 4, 3) == 3
    assert job_slots("submitit", slurm, None, 1000) == slurm.slurm.array_parallelism
    assert job_slots("submitit", slurm, 5, 1000) == 5
    assert job_slots("local", slurm, None, 6, auto=1) == 1  # the main job: one per seed at most
    assert job_slots("submitit", ExecutorSettings(), None, 6, auto=1) == 1
    assert isinstance(make_executor("local", slurm, 1), InlineExecutor)
    assert isinstance(make_executor("local", slurm, 2), LocalExecutor)


def test_the_executor_node_becomes_submitits_parameters():
    from cpmp.compare.settings import CompareJob

    cfg = compose_cfg(
        "compare",
        [
            "experiment.executor=submitit",
            "executor.folder=/shared/jobs",
            "executor.cluster=slurm",
            "executor.slurm.partition=cpu",
            "executor.slurm.time=30",
            "executor.slurm.mem=8G",
            "executor.slurm.array_parallelism=64",
            "+executor.slurm.extra.account=lab",
        ],
    )
    job = CompareJob.from_cfg(cfg)
    assert job.settings.executor == "submitit"
    assert submitit_parameters(job.executor) == {
        "timeout_min": 30,
        "cpus_per_task": 1,
        "slurm_array_parallelism": 64,
        "slurm_partition": "cpu",
        "slurm_mem": "8G",
        "slurm_account": "lab",
    }


# ------------------------------------------------------------------------------- errors
def test_an_unknown_executor_names_the_valid_ones(tmp_path):
    from cpmp.cli.checks import check_jobs
    from cpmp.cli.main import COMMANDS, check_command

    valid = ", ".join(EXECUTORS)
    with pytest.raises(ConfigError, match=rf"experiment\.executor must be one of {valid}"):
        ExperimentSettings.from_cfg({"executor": "ray"})
    with pytest.raises(ConfigError, match=rf"experiment\.executor must be one of {valid}"):
        make_executor("spark", ExecutorSettings(), 2)
    jobs = check_command("experiment", ["experiment=tiny", "experiment.executor=ray"])
    with pytest.raises(ConfigError, match=rf"one of {valid}, got 'ray'"):
        check_jobs(COMMANDS["experiment"], jobs)


@pytest.mark.parametrize("command", ["experiment", "compare"])
def test_submitit_without_a_folder_says_to_set_it(command):
    from cpmp.cli.checks import check_jobs
    from cpmp.cli.main import COMMANDS, check_command

    jobs = check_command(command, ["experiment.executor=submitit"])
    with pytest.raises(ConfigError, match=r"needs executor\.folder"):
        check_jobs(COMMANDS[command], jobs)
    with pytest.raises(ConfigError, match=r"needs executor\.folder"):
        SubmititExecutor(ExecutorSettings(), 2)


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        (["executor.cluster=pbs"], r"executor\.cluster must be one of local, slurm"),
        (["+executor.slurm.extra.acount=lab"], r"unknown executor\.slurm\.extra .*acount"),
        (["executor.slurm.time=0"], r"executor\.slurm\.time must be an integer >= 1"),
    ],
)
def test_a_bad_executor_node_is_refused_before_the_job(tmp_path, overrides, message):
    from cpmp.experiment.config import experiment_job

    folder = f"executor.folder={tmp_path}"
    cfg = compose_cfg("experiment", ["experiment.executor=submitit", folder, *overrides])
    with pytest.raises(ConfigError, match=message):
        experiment_job(cfg)


# -------------------------------------------------------- the same numbers on each backend
def compare_numbers(run_dir: Path) -> list[dict[str, Any]]:
    """Every row of ``compare.json`` without the fields a wall time enters."""
    rows = json.loads((run_dir / "compare.json").read_text())["rows"]
    timed = ("fit_s", "tick_ms")
    out = []
    for row in rows:
        row = {k: v for k, v in row.items() if k not in timed}
        row["per_seed"] = {k: v for k, v in row["per_seed"].items() if k not in timed}
        out.append(row)
    return out


@pytest.mark.slow
def test_the_comparison_gives_the_same_numbers_on_every_executor(tmp_path):
    """The two-point world of ``experiment=compare_tiny`` (2 seeds, the paper's kernel at
    D = 4: 2 jobs) on ``inline``, ``local`` (two processes), ``submitit`` (``cluster=local``,
    two at once) and ``dask`` (a local cluster of two processes): every number of
    ``compare.json`` but the wall times is the same, and ``timings.json`` names the executor
    that ran it."""
    from cpmp.compare.job import run_compare

    base = [
        "experiment=compare_tiny",
        "~compare.worlds.sim",
        "compare.worlds.two_point.train_sizes=[4]",
        "compare.predictors=[paper]",
        "compare.sweep.support_scale=[]",
        "compare.baselines=[]",
    ]
    runs = {
        "inline": ["experiment.executor=inline"],
        "local": ["experiment.executor=local", "experiment.workers=2"],
        "submitit": [
            "experiment.executor=submitit",
            "experiment.workers=2",
            f"executor.folder={tmp_path / 'submitit'}",
        ],
        "dask": ["experiment.executor=dask", "experiment.workers=2"],
    }
    numbers = {}
    for name, overrides in runs.items():
        run_compare(compose_cfg("compare", [*base, *overrides]), tmp_path / name)
        numbers[name] = compare_numbers(tmp_path / name)
        timings = json.loads((tmp_path / name / "timings.json").read_text())
        assert timings["executor"] == name and len(timings["jobs"]) == 2
    (row,) = numbers["inline"]
    assert row["errors"] == [] and row["world"] == "two_point" and row["seeds"] == [0, 1]
    assert len(row["per_seed"]["mae"]) == 2
    assert numbers["local"] == numbers["inline"]
    assert numbers["submitit"] == numbers["inline"]
    assert numbers["dask"] == numbers["inline"]
    assert len(list((tmp_path / "submitit").glob("*_result.pkl"))) == 2
