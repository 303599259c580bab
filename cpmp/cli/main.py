"""The command-line entry points: one per job, the Hydra jobs checked before they run.

``cpmp-experiment``, ``cpmp-compare``, ``cpmp-train``, ``cpmp-evaluate``, ``cpmp-collect``,
``cpmp-aggregate``, ``cpmp-progress-field`` (Hydra jobs) and ``cpmp-inspect-rrd``;
``scripts/*.py`` call the same functions. ``cpmp-experiment experiment=compare`` (or any
``experiment`` option with a ``compare`` node) is an alias of ``cpmp-compare``: the command
line dispatches it to the comparison's checks and job.

A Hydra command checks its configuration before it imports anything heavy
(:mod:`cpmp.cli.checks`):

1. **compose** (Hydra and OmegaConf only, :mod:`cpmp.cli.compose`): the command
   line is parsed and the configuration composed as Hydra will compose it (for a multirun:
   every job of the sweep) on the schema of :mod:`cpmp.experiment.config`; an unknown group
   option or key, an override Hydra cannot parse, a value of the wrong type (against the type
   of its default and the schema), an interpolation that does not resolve, a required path
   that is unset or names no file fail here — :func:`check_command`;
2. **the job's own checks** (value ranges, predictor/sequencer/trainer options, the task): the
   composed config is converted into the typed configs of :mod:`cpmp.config`, which validate
   themselves, before any long work, for every job of a sweep before the first one starts;
3. the job runs under ``hydra.main``; a :class:`~cpmp.errors.CpmpError` it raises ends it the
   same way (:func:`run_job`).

A failed check prints one ``error: ...`` line on stderr and exits with status 2. The commands
read their configs from the package ``cpmp._conf`` (:mod:`cpmp.config.paths`): the checkout's
``conf/`` in an editable install, its copy in a wheel; ``--config-dir DIR`` adds a directory of
your own config group options.

The job functions below are the one place where heavy modules (torch, Lightning, MuJoCo,
rerun, matplotlib) are imported: inside the function, after the command line was checked.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

import hydra
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig

from cpmp.cli.checks import CheckedJob, Command, check_command_line, check_jobs
from cpmp.cli.compose import CONF_DIR  # noqa: F401 (re-exported: where the configs are)
from cpmp.cli.import_job import IMPORT_COMMAND
from cpmp.compare.settings import CompareJob
from cpmp.config import TaskConfig
from cpmp.config.paths import CONF_SEARCH_PATH
from cpmp.errors import CpmpError, CpmpFileError
from cpmp.experiment.config import (
    experiment_job,
    job_fit_settings,
    predictor_from_cfg,
    predictor_options,
)

log = logging.getLogger("cpmp")


# ------------------------------------------------------------------------------- the jobs
def _is_compare(cfg: DictConfig) -> bool:
    """Whether a composed config is the comparison's (it has a ``compare`` node)."""
    return cfg.get("compare") is not None


def _experiment_job(cfg: DictConfig, run_dir: Path) -> Path:
    """The main job (:func:`~cpmp.experiment.jobs.run_experiment`), or the comparison's alias."""
    if _is_compare(cfg):
        return _compare_job(cfg, run_dir)
    from cpmp.experiment.jobs import run_experiment  # lazy: torch, MuJoCo after the checks

    return run_experiment(cfg, run_dir)


def _compare_job(cfg: DictConfig, run_dir: Path) -> Path:
    """The comparison (:func:`~cpmp.compare.job.run_compare`); returns ``compare.json``."""
    from cpmp.compare.job import run_compare  # lazy: torch, MuJoCo after the checks

    return run_compare(cfg, run_dir)


def _train_job(cfg: DictConfig, run_dir: Path) -> Path:
    """Train a sequencer from a demonstration file; returns the checkpoint's path."""
    from cpmp.experiment.checkpoint_jobs import train_from_file  # lazy: torch after the checks

    return train_from_file(cfg, run_dir)


def _evaluate_job(cfg: DictConfig, run_dir: Path) -> Path:
    """Evaluate a checkpoint offline; returns the report's path."""
    from cpmp.experiment.checkpoint_jobs import evaluate_checkpoint  # lazy: torch after checks

    return evaluate_checkpoint(cfg, run_dir)


def _aggregate_job(cfg: DictConfig, run_dir: Path) -> Path:
    """One table and plot of a multirun; returns the table's path."""
    from cpmp.analysis.aggregate import aggregate_sweep  # lazy: matplotlib after the checks

    return aggregate_sweep(cfg, run_dir)


def _collect_job(cfg: DictConfig, run_dir: Path) -> Path:
    """Record ``n_demos`` scripted demonstrations into ``run_dir / output`` (HDF5)."""
    from cpmp.sim.collect import collect_demonstrations  # lazy: MuJoCo after the checks

    task = TaskConfig.from_dict(cfg.task)
    out = run_dir / str(cfg.output)
    path, _ = collect_demonstrations(task, int(cfg.n_demos), int(cfg.seed), out, bool(cfg.balanced))
    return path


def _progress_field_job(cfg: DictConfig, run_dir: Path) -> Path:
    """The paper's Fig. 3 on synthetic trajectories; returns the PNG path."""
    from cpmp.analysis.progress_field import progress_field_example  # lazy: torch, matplotlib

    kind, options = predictor_options(cfg.predictor)
    result = progress_field_example(
        run_dir,
        n_trajectories=int(cfg.n_trajectories),
        seed=int(cfg.seed),
        predictor=kind,
        predictor_options=options,
    )
    print(f"support points: {result['n_support']}, training MAE: {result['train_mae']:.4f}")
    return Path(result["png"])


# ------------------------------------------------------------------ the jobs' own checks
# Each converts the config into the typed configs the job will build from it, which validate
# themselves (cpmp.experiment.config); only the goal_nearest baseline's options import torch.
def _check_experiment(cfg: DictConfig) -> None:
    """The main job's settings, predictor, sequencer, trainer and task (or the comparison's)."""
    if _is_compare(cfg):
        _check_compare(cfg)
    else:
        experiment_job(cfg)


def _check_compare(cfg: DictConfig) -> None:
    """The comparison's settings, task and ``compare`` node, and the groups its rows share."""
    CompareJob.from_cfg(cfg)
    job_fit_settings(cfg)


def _check_train(cfg: DictConfig) -> None:
    """The predictor, sequencer and trainer groups."""
    job_fit_settings(cfg)


def _check_collect(cfg: DictConfig) -> None:
    """The task."""
    TaskConfig.from_dict(cfg.task)


def _check_progress_field(cfg: DictConfig) -> None:
    """The predictor group."""
    predictor_from_cfg(cfg.predictor)


COMMANDS: dict[str, Command] = {
    command.name: command
    for command in (
        Command(
            "experiment",
            "the main job (collect, train, evaluate, report)",
            _experiment_job,
            _check_experiment,
        ),
        Command(
            "compare",
            "every predictor and baseline on the same demonstrations and boxes",
            _compare_job,
            _check_compare,
        ),
        Command(
            "train",
            "train a sequencer from an HDF5 demonstration file",
            _train_job,
            _check_train,
            required=("data.path",),
            files=("data.path",),
        ),
        Command(
            "evaluate",
            "evaluate a checkpoint offline on a file's test split",
            _evaluate_job,
            required=("checkpoint", "data.path"),
            files=("checkpoint", "data.path"),
        ),
        Command(
            "collect",
            "record scripted demonstrations in the simulator",
            _collect_job,
            _check_collect,
            positive=("n_demos",),
        ),
        Command(
            "aggregate",
            "one table and plot of a multirun of the main job",
            _aggregate_job,
            required=("sweep_dir",),
            dirs=("sweep_dir",),
        ),
        Command(
            "progress_field",
            "the paper's Fig. 3 on synthetic trajectories",
            _progress_field_job,
            _check_progress_field,
            positive=("n_trajectories",),
        ),
        IMPORT_COMMAND,
    )
}
"""Every Hydra command by name: its console script is ``cpmp-<name>`` (``_`` as ``-``), run by
``<name>_main`` below."""


def check_command(name: str, argv: Sequence[str]) -> list[CheckedJob]:
    """Compose and check the configuration of command ``name`` for the command line ``argv``.

    Light imports only (no torch, Lightning or MuJoCo); see
    :func:`~cpmp.cli.checks.check_command_line`.
    """
    return check_command_line(COMMANDS[name], argv)


def _fail(err: CpmpError) -> None:
    """Print ``err`` as one ``error:`` line and exit with status 2."""
    print(f"error: {' '.join(str(err).split())}", file=sys.stderr)
    sys.exit(2)


def run_job(job: Callable[[DictConfig, Path], Path], cfg: DictConfig, run_dir: str | Path) -> Path:
    """Run ``job(cfg, run_dir)``; print its output path last.

    A user error (:class:`CpmpError`) ends the job with one ``error:`` line on stderr and exit
    status 2 instead of a traceback. The error also goes to the job's log file (not a second
    time to the console); a run directory in which the job wrote nothing (Hydra's ``.hydra/``
    and the job's log aside) is removed.
    """
    import torch  # lazy: the jobs' heavy dependency, after the command line was checked

    torch.set_num_threads(max(1, int(cfg.get("threads", 1) or 1)))
    try:
        out = job(cfg, Path(run_dir))
    except CpmpError as err:
        _log_to_files(err)
        _discard_empty_run_dir(Path(run_dir))
        _fail(err)
    print(out)
    return out


def _log_to_files(err: CpmpError) -> None:
    """Write ``err`` to the log files only (the console gets the one ``error:`` line)."""
    record = log.makeRecord(
        log.name, logging.ERROR, __file__, 0, "%s: %s", (type(err).__name__, err), None
    )
    for handler in logging.getLogger().handlers + log.handlers:
        if isinstance(handler, logging.FileHandler):
            handler.handle(record)


def _discard_empty_run_dir(run_dir: Path) -> None:
    """Remove ``run_dir`` if a failed job wrote nothing into it.

    Only what Hydra writes before the job (``.hydra/`` with its config files, and the job's
    ``<job name>.log``) is removed, and the directory itself only once empty: another file
    keeps all of it. The working directory is never removed.

    Args:
        run_dir: the job's output directory.
    """
    if not run_dir.is_dir() or run_dir.resolve() == Path.cwd().resolve():
        return
    hydra_dir = run_dir / ".hydra"
    logs = {f"{HydraConfig.get().job.name}.log"} if HydraConfig.initialized() else set()
    ours = {".hydra", *logs}
    if any(p.name not in ours for p in run_dir.iterdir()):
        return
    if hydra_dir.is_dir() and any(
        p.name not in ("config.yaml", "hydra.yaml", "overrides.yaml") or not p.is_file()
        for p in hydra_dir.iterdir()
    ):
        return
    for name in logs:
        (run_dir / name).unlink(missing_ok=True)
    if hydra_dir.is_dir():
        for p in hydra_dir.iterdir():
            p.unlink()
        hydra_dir.rmdir()
    run_dir.rmdir()


class _Task:
    """Hydra's task function of a command (picklable, for the joblib and SLURM launchers).

    Hydra names the job, and so the run directory ``logs/<job>/...``, after the task function's
    module: the instance carries the command's name there.
    """

    def __init__(self, name: str) -> None:
        self.name = name
        self.__module__ = name

    def __call__(self, cfg: DictConfig) -> Path:
        """Run the command's job on ``cfg`` in Hydra's output directory."""
        return run_job(COMMANDS[self.name].job, cfg, HydraConfig.get().runtime.output_dir)


def run_command(name: str) -> None:
    """Run Hydra command ``name`` on ``sys.argv``: check, then run the job(s) under Hydra.

    Exits with status 2 and one ``error:`` line on a bad configuration.
    """
    try:
        jobs = check_command(name, sys.argv[1:])
        check_jobs(COMMANDS[name], jobs)
    except CpmpError as err:
        _fail(err)
    hydra.main(version_base="1.3", config_path=CONF_SEARCH_PATH, config_name=name)(_Task(name))()


def _entry_point(name: str) -> Callable[[], None]:
    """The console-script function of Hydra command ``name``: :func:`run_command` ``(name)``."""

    def main() -> None:
        run_command(name)

    main.__name__ = main.__qualname__ = f"{name}_main"
    main.__doc__ = f"``cpmp-{name.replace('_', '-')}``: {COMMANDS[name].summary}."
    return main


experiment_main = _entry_point("experiment")
compare_main = _entry_point("compare")
train_main = _entry_point("train")
evaluate_main = _entry_point("evaluate")
collect_main = _entry_point("collect")
aggregate_main = _entry_point("aggregate")
progress_field_main = _entry_point("progress_field")
import_main = _entry_point("import")


def inspect_rrd_main(argv: Sequence[str] | None = None) -> int:
    """``cpmp-inspect-rrd FILE.rrd [...] [--json]``: summarise episode recordings.

    Each summary has the episode, ticks, duration, transitions, notes and outcome.

    Returns:
        The exit status: 2 if any file could not be read (one ``error:`` line per bad file on
        stderr; the other files are still summarised), else 0.
    """
    from cpmp.recordings import format_summary, read_recording  # lazy: rerun, for this command

    parser = argparse.ArgumentParser(
        prog="inspect_rrd",
        description="Summarise cpmp episode recordings: episode, ticks, duration, "
        "transitions, outcome.",
    )
    parser.add_argument("files", nargs="+", metavar="FILE.rrd", help="rerun recordings")
    parser.add_argument("--json", action="store_true", help="one JSON object per file and line")
    args = parser.parse_args(None if argv is None else list(argv))

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


def inspect_rrd_entry() -> None:
    """Console-script wrapper of :func:`inspect_rrd_main` (exits with its status)."""
    sys.exit(inspect_rrd_main())
