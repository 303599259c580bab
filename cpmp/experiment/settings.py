"""What a job of the main experiment is, typed.

:class:`ExperimentSettings` is the ``experiment`` group (its ``record`` a :data:`RecordMode`),
:class:`FitSettings` the ``predictor``, ``sequencer`` and ``trainer`` groups, and
:class:`ExperimentJob` all of them with the ``task``. Each validates itself on construction;
:mod:`cpmp.experiment.config` registers them with Hydra and converts a composed ``cfg`` into
them. :class:`ExecutorSettings` is the ``executor`` node: where the jobs of
``experiment.executor=submitit`` or ``dask`` run (:mod:`cpmp.experiment.executors`).
:func:`to_dict` turns a config node into a plain dict.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Literal, TypeAlias, TypeVar, get_args

from omegaconf import DictConfig, OmegaConf

from cpmp.config import BCConfig, FitConfig, GoalNearestConfig, TaskConfig
from cpmp.config.bc import KIND as BC
from cpmp.config.goal_nearest import KIND as GOAL_NEAREST
from cpmp.errors import ConfigError, require
from cpmp.records import JsonValue

RecordMode = Literal["failures", "all", "first", "none"]
"""Which reproduction episodes keep an ``.rrd`` (``experiment.record``): ``failures`` (every
episode that did not complete, plus the first one per training size), ``all``, ``first`` (the
first per training size) or ``none``."""
RECORD_CHOICES: tuple[RecordMode, ...] = get_args(RecordMode)
"""Values of ``experiment.record``."""
ExecutorName = Literal["inline", "local", "submitit", "dask"]
"""What runs the jobs (``experiment.executor``, :mod:`cpmp.experiment.executors`): ``inline``
(this process, one job after the other), ``local`` (spawned worker processes; one worker: this
process), ``submitit`` (submitit jobs: local processes or SLURM jobs, ``executor`` node) or
``dask`` (Dask distributed: an existing cluster at ``executor.address`` or a local one)."""
EXECUTORS: tuple[ExecutorName, ...] = get_args(ExecutorName)
"""Values of ``experiment.executor``."""
CLUSTERS = ("local", "slurm")
"""Values of ``executor.cluster``: where the ``submitit`` executor's jobs run."""
ConfigNode: TypeAlias = "DictConfig | Mapping[str, object] | None"
"""A config group as a job gets it: a composed OmegaConf node, a plain mapping of options, or
``None`` (the group's defaults)."""
_Options = TypeVar("_Options", bound=Mapping[str, object])


def to_dict(cfg: object) -> dict[str, Any]:
    """A plain dict from an OmegaConf node or mapping (``None`` -> ``{}``).

    The option values are not checked here: the typed config that takes them as
    keywords checks them.

    Raises:
        ConfigError: ``cfg`` is neither a mapping nor ``None``.
    """
    if cfg is None:
        return {}
    if isinstance(cfg, DictConfig):
        return OmegaConf.to_container(cfg, resolve=True)  # type: ignore[return-value]
    if isinstance(cfg, Mapping):
        return dict(cfg)
    raise ConfigError(f"expected a mapping of options, got {type(cfg).__name__}")


@dataclass
class ExperimentSettings:
    """Sizes of the evaluation (``experiment`` config group).

    The defaults are ``experiment=quick``, a small run (its time: see docs/benchmarks.md).

    Attributes:
        name: label of the settings (``quick``, ``full``, ...).
        seeds: each seed repeats collection, training and reproduction.
        demos_per_strategy: demonstrations collected per strategy (paper: 5, so 15 in all).
        train_per_strategy: of those, used for training (paper: 3, so 9 train / 6 test).
        train_sizes: training-set sizes D to compare (paper: 3, 6, 9), balanced over strategies.
        n_boxes: random boxes reproduced per D and seed (paper: 20).
        box_seed_offset: boxes for reproduction are drawn from ``seed + box_seed_offset``.
        strategy_grid: (widths, depths) cells of the strategy map (Fig. 7).
        record: which reproduction episodes keep an ``.rrd`` (:data:`RecordMode`):
            ``failures`` (every episode that did not complete, plus the first one per training
            size), ``all``, ``first`` or ``none``.
        record_demos: also write the collected demonstrations as ``.rrd``.
        max_time: episode time limit [s] (``None``: the task's ``max_time``).
        feature_noise: std of Gaussian noise added to the training demonstrations' features,
            as a fraction of each feature's range over the training set (0: none); the test
            demonstrations and the closed loop stay noise-free.
        workers: how many jobs (a seed's collection, a training size) run at once: worker
            processes of the ``local`` executor (1: everything in this process) and of the
            ``dask`` one's local cluster, jobs in flight of the ``submitit`` one and on a Dask
            cluster (``None``: min(cores, jobs); on SLURM ``executor.slurm.array_parallelism``;
            on a Dask cluster at ``executor.address``: every job ready to run). The report's
            numbers do not depend on it.
        executor: what runs the jobs (:data:`ExecutorName`): ``local`` (spawned processes),
            ``inline`` (this process), ``submitit`` or ``dask`` (the ``executor`` node says
            where). The report's numbers do not depend on it.
    """

    name: str = "quick"
    seeds: list[int] = field(default_factory=lambda: [0])
    demos_per_strategy: int = 3
    train_per_strategy: int = 2
    train_sizes: list[int] = field(default_factory=lambda: [3, 6])
    n_boxes: int = 6
    box_seed_offset: int = 1000
    strategy_grid: list[int] = field(default_factory=lambda: [8, 6])
    record: RecordMode = "failures"
    record_demos: bool = False
    max_time: float | None = None
    feature_noise: float = 0.0
    workers: int | None = None
    executor: ExecutorName = "local"

    def __post_init__(self) -> None:
        for name in ("demos_per_strategy", "train_per_strategy", "n_boxes", "box_seed_offset"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int):
                raise ConfigError(f"experiment.{name} must be an integer, got {value!r}")
        for name in ("seeds", "train_sizes", "strategy_grid"):
            values = list(getattr(self, name))
            if any(isinstance(v, bool) or not isinstance(v, int) for v in values):
                raise ConfigError(f"experiment.{name} must be integers, got {values}")
            setattr(self, name, values)
        for name in ("seeds", "train_sizes"):
            values = getattr(self, name)
            if len(set(values)) != len(values):
                raise ConfigError(f"experiment.{name} has duplicates: {values}")
        if not self.seeds or any(s < 0 for s in self.seeds):
            raise ConfigError(f"experiment.seeds must be non-negative integers, got {self.seeds}")
        for name in ("demos_per_strategy", "train_per_strategy", "n_boxes"):
            if getattr(self, name) < 1:
                raise ConfigError(f"experiment.{name} must be >= 1, got {getattr(self, name)}")
        if self.train_per_strategy >= self.demos_per_strategy:
            raise ConfigError(
                f"experiment.train_per_strategy ({self.train_per_strategy}) must be smaller than "
                f"demos_per_strategy ({self.demos_per_strategy}) to leave test demos"
            )
        n_train = 3 * self.train_per_strategy
        if not self.train_sizes or any(d < 1 or d > n_train for d in self.train_sizes):
            raise ConfigError(
                f"experiment.train_sizes must lie in 1..{n_train} (3 strategies x "
                f"train_per_strategy), got {self.train_sizes}"
            )
        if len(self.strategy_grid) != 2 or min(self.strategy_grid) < 2:
            raise ConfigError(
                f"experiment.strategy_grid must be [n_widths, n_depths] >= 2, "
                f"got {self.strategy_grid}"
            )
        if self.record not in RECORD_CHOICES:
            raise ConfigError(
                f"experiment.record must be one of {', '.join(RECORD_CHOICES)}, got {self.record!r}"
            )
        noise = self.feature_noise
        if isinstance(noise, bool) or not isinstance(noise, (int, float)) or not noise >= 0:
            raise ConfigError(f"experiment.feature_noise must be a number >= 0, got {noise!r}")
        if not math.isfinite(noise):
            raise ConfigError(f"experiment.feature_noise must be finite, got {noise}")
        if self.max_time is not None and self.max_time <= 0:
            raise ConfigError(f"experiment.max_time must be > 0, got {self.max_time}")
        workers = self.workers
        if workers is not None and (
            isinstance(workers, bool) or not isinstance(workers, int) or workers < 1
        ):
            raise ConfigError(
                f"experiment.workers must be an integer >= 1 or null (auto), got {workers!r}"
            )
        if self.executor not in EXECUTORS:
            raise ConfigError(
                f"experiment.executor must be one of {', '.join(EXECUTORS)}, got {self.executor!r}"
            )

    @classmethod
    def from_cfg(cls, cfg: ConfigNode) -> ExperimentSettings:
        """From the ``experiment`` node (or a mapping); unknown keys raise :class:`ConfigError`."""
        options = to_dict(cfg)
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(options) - known)
        if unknown:
            raise ConfigError(
                f"unknown experiment option(s) {', '.join(unknown)}; "
                f"valid: {', '.join(sorted(known))}"
            )
        return cls(**options)


@dataclass
class SlurmSettings:
    """The ``executor.slurm`` node: the SLURM job of each cpmp job (``executor.cluster=slurm``).

    Attributes:
        partition: the partition (``None``: the cluster's default).
        time: each job's time limit [min] (also the limit of a ``cluster=local`` job).
        cpus_per_task: CPUs per job (each job runs one torch thread).
        mem: memory per job, as SLURM writes it (``8G``; ``None``: the cluster's default).
        array_parallelism: the most jobs queued or running at once (the default of
            ``experiment.workers`` on SLURM).
        extra: further ``sbatch`` parameters of submitit's SLURM executor, without their
            ``slurm_`` prefix (``account``, ``qos``, ``constraint``, ``gpus_per_node``,
            ``additional_parameters``, ...).
    """

    partition: str | None = None
    time: int = 60
    cpus_per_task: int = 1
    mem: str | None = None
    array_parallelism: int = 32
    extra: dict[str, Any] = field(default_factory=dict)  # OmegaConf's schema: Any, not a union


@dataclass
class ExecutorSettings:
    """The ``executor`` node: where the ``submitit`` and ``dask`` executors run the jobs.

    Attributes:
        folder: submitit's folder: each job's pickled call, result and logs
            (``<job id>_0_log.out`` / ``.err``); on SLURM a folder every node can read.
            Required by ``experiment.executor=submitit``.
        cluster: ``local`` (local processes) or ``slurm`` (SLURM jobs), see :data:`CLUSTERS`.
        slurm: the SLURM parameters of each job (time and cpus_per_task also on ``local``).
        address: ``experiment.executor=dask``: the scheduler of a running Dask cluster
            (``tcp://host:8786``; its workers must import cpmp); ``None``: a Dask cluster of
            ``experiment.workers`` local processes, one thread each, started for the job.
        connect_timeout: ``experiment.executor=dask``: how long [s] to try to reach
            ``address`` before giving up.
    """

    folder: str | None = None
    cluster: str = "local"
    slurm: SlurmSettings = field(default_factory=SlurmSettings)
    address: str | None = None
    connect_timeout: int = 30

    def __post_init__(self) -> None:
        if self.cluster not in CLUSTERS:
            raise ConfigError(
                f"executor.cluster must be one of {', '.join(CLUSTERS)}, got {self.cluster!r}"
            )
        slurm = self.slurm
        for name in ("time", "cpus_per_task", "array_parallelism"):
            value = getattr(slurm, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ConfigError(f"executor.slurm.{name} must be an integer >= 1, got {value!r}")
        timeout = self.connect_timeout
        if isinstance(timeout, bool) or not isinstance(timeout, int) or timeout < 1:
            raise ConfigError(f"executor.connect_timeout must be an integer >= 1, got {timeout!r}")
        if self.address is not None and (not isinstance(self.address, str) or not self.address):
            raise ConfigError(
                "executor.address must be a Dask scheduler address such as tcp://host:8786, "
                f"or null for a local Dask cluster; got {self.address!r}"
            )

    @classmethod
    def from_cfg(cls, cfg: ConfigNode) -> ExecutorSettings:
        """From the ``executor`` node (or a mapping; ``None``: the defaults), keys checked.

        Raises:
            ConfigError: an unknown key or a bad value, naming it.
        """
        options = _known(cls, to_dict(cfg), "executor.")
        slurm = _known(SlurmSettings, to_dict(options.pop("slurm", None)), "executor.slurm.")
        slurm["extra"] = to_dict(slurm.get("extra"))
        return cls(**options, slurm=SlurmSettings(**slurm))

    def check(self, executor: str) -> None:
        """What ``experiment.executor=executor`` needs of this node.

        The ``submitit`` executor needs a folder and takes only the ``extra`` SLURM parameters
        submitit knows (imports submitit); the ``dask`` executor needs the ``distributed``
        package and an ``executor.address`` it can parse (``None`` or ``scheme://host:port``).

        Raises:
            ConfigError: no ``executor.folder``, an unknown ``executor.slurm.extra`` key, or a
                bad ``executor.address``.
            MissingExtraError: ``dask`` without ``distributed`` (the ``jobs`` extra).
        """
        if executor == "dask":
            self._check_dask()
        if executor != "submitit":
            return
        if not self.folder:
            raise ConfigError(
                "experiment.executor=submitit needs executor.folder: where submitit keeps each "
                "job's call, result and logs (on SLURM a folder every node can read), e.g. "
                "executor.folder=/shared/cpmp_jobs"
            )
        from submitit import SlurmExecutor  # lazy: only the submitit executor needs it

        valid = SlurmExecutor._valid_parameters()
        unknown = sorted(set(self.slurm.extra) - valid)
        if unknown:
            raise ConfigError(
                f"unknown executor.slurm.extra parameter(s) {', '.join(unknown)}; "
                f"valid: {', '.join(sorted(valid))}"
            )

    def _check_dask(self) -> None:
        """What ``experiment.executor=dask`` needs: ``distributed``, a parseable address."""
        require("distributed", "jobs", "experiment.executor=dask")
        if self.address is None:
            return
        from distributed.comm import get_address_host_port  # lazy: only dask needs it

        try:
            get_address_host_port(self.address)
        except ValueError as err:
            raise ConfigError(
                f"executor.address={self.address!r} is not a Dask scheduler address ({err}): "
                "write scheme://host:port, e.g. executor.address=tcp://10.0.0.5:8786 (what "
                "`dask scheduler` prints), or executor.address=null for a local Dask cluster"
            ) from None


def _known(cls: type, options: _Options, path: str) -> _Options:
    """``options`` of the dataclass ``cls`` at ``path``, unknown keys refused.

    Raises:
        ConfigError: a key ``cls`` does not have, naming the valid ones.
    """
    known = [f.name for f in dataclasses.fields(cls)]
    unknown = sorted(set(options) - set(known))
    if unknown:
        raise ConfigError(
            f"unknown option(s) {', '.join(path + k for k in unknown)}; "
            f"valid: {', '.join(path + k for k in known)}"
        )
    return options


@dataclass(frozen=True)
class FitSettings:
    """The typed ``predictor``, ``sequencer``, ``trainer`` and ``logger`` groups of a job.

    Attributes:
        fit: the learned sequencer's :class:`~cpmp.config.FitConfig` (seed 0; the jobs set
            the seed and the trainer's ``log_dir`` per fit).
        goal_nearest: the options of the ``goal_nearest`` baseline when the ``sequencer``
            group selects it (``kind: goal_nearest``; the predictor and trainer are then not
            used), else ``None``.
        logger: the ``logger`` group: a Lightning logger's ``_target_`` and arguments, built
            per fit by :func:`cpmp.experiment.fitting.make_logger`; ``None``: no logging.
        bc: the options of the ``bc`` (behaviour-cloning) baseline when the ``sequencer``
            group selects it (``kind: bc``; the predictor and trainer are then not used),
            else ``None``.
    """

    fit: FitConfig
    goal_nearest: GoalNearestConfig | None = None
    logger: dict[str, JsonValue] | None = None
    bc: BCConfig | None = None

    @property
    def baseline(self) -> str | None:
        """The baseline the ``sequencer`` group selects (``goal_nearest``, ``bc``).

        ``None`` for the learned sequencer.
        """
        if self.goal_nearest is not None:
            return GOAL_NEAREST
        return BC if self.bc is not None else None

    def baseline_options(self) -> dict[str, JsonValue]:
        """The selected baseline's options with its ``kind`` (empty for the learned one)."""
        options = self.goal_nearest if self.goal_nearest is not None else self.bc
        if options is None:
            return {}
        return {"kind": self.baseline, **dataclasses.asdict(options)}

    @property
    def predictor(self) -> str:
        """The predictor kind."""
        return self.fit.predictor


@dataclass(frozen=True)
class ExperimentJob:
    """The main job's config, typed: what ``run_experiment`` and its workers take.

    Attributes:
        settings: the ``experiment`` group.
        task: the ``task`` group.
        fit: the ``predictor``, ``sequencer`` and ``trainer`` groups.
        executor: the ``executor`` node (used by ``experiment.executor=submitit`` and ``dask``).
    """

    settings: ExperimentSettings
    task: TaskConfig
    fit: FitSettings
    executor: ExecutorSettings = field(default_factory=ExecutorSettings)
