"""The sizes of ``scripts/bench.py`` (:class:`BenchSettings`) and its sections (:data:`SECTIONS`).

They are checked on construction; nothing here runs a measurement.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from cpmp.errors import ConfigError

SECTIONS = ("fit", "sequencer", "realtime", "stages", "scaling", "gradient")
"""The benchmark's sections, in the order they run."""


@dataclass
class BenchSettings:
    """Sizes of :func:`~cpmp.benchmarks.suite.run_bench`.

    The defaults are the issue's; :meth:`quick` is small.

    Attributes:
        sections: which of :data:`SECTIONS` to run.
        seed: seed of the demonstrations, boxes and fits.
        fit_demos: simulated training demonstrations of the ``fit`` and ``sequencer``
            sections, drawn as seed ``seed`` of the main job draws them (9: the full
            experiment's D = 9).
        repeats: timed repetitions of each fit (the report gives min and median).
        batch: episodes run together (sequencer and real-time sections).
        ticks: control ticks per episode of the ``sequencer`` section.
        max_time: episode time limit [s] of the ``realtime`` section (``None``: the task's).
        experiment: ``experiment=`` config of the ``stages`` section.
        experiment_overrides: further Hydra overrides of that run (``experiment.workers=2``).
        scaling_demos: demonstration counts of the ``scaling`` section.
        scaling_features: feature counts of the ``scaling`` section (>= 6, the relay task's).
        scaling_ticks: ticks per episode when timing the sequencer in ``scaling``.
        gradient_demos: synthetic demonstrations of the ``gradient`` section.
        gradient_predictors: the Adam-trained predictors timed there.
        gradient_epochs: cap on their epochs (``None``: each predictor's default).
        lbfgs: also time the LBFGS solver (``trainer.solver=lbfgs``) in ``fit``.
        threads: torch (and BLAS) threads.
    """

    sections: list[str] = field(default_factory=lambda: list(SECTIONS))
    seed: int = 0
    fit_demos: int = 9
    repeats: int = 3
    batch: int = 20
    ticks: int = 300
    max_time: float | None = None
    experiment: str = "quick"
    experiment_overrides: list[str] = field(default_factory=list)
    scaling_demos: list[int] = field(default_factory=lambda: [3, 6, 12, 25, 50])
    scaling_features: list[int] = field(default_factory=lambda: [24, 64, 128, 256])
    scaling_ticks: int = 100
    gradient_demos: int = 6
    gradient_predictors: list[str] = field(default_factory=lambda: ["mlp"])
    gradient_epochs: int | None = None
    lbfgs: bool = False
    threads: int = 1

    def __post_init__(self) -> None:
        unknown = [s for s in self.sections if s not in SECTIONS]
        if unknown or not self.sections:
            raise ConfigError(
                f"unknown or no bench sections {unknown or self.sections}; choose from "
                f"{', '.join(SECTIONS)}"
            )
        for name in ("fit_demos", "repeats", "batch", "ticks", "scaling_ticks", "threads"):
            check_count(name, getattr(self, name))
        check_count("gradient_demos", self.gradient_demos)
        if self.gradient_epochs is not None:
            check_count("gradient_epochs", self.gradient_epochs)
        if self.seed < 0:
            raise ConfigError(f"seed must be >= 0, got {self.seed}")
        if self.max_time is not None and not self.max_time > 0:
            raise ConfigError(f"max_time must be > 0 seconds, got {self.max_time}")
        for name in ("scaling_demos", "scaling_features"):
            values = getattr(self, name)
            if not values:
                raise ConfigError(f"{name} needs at least one value")
            for value in values:
                check_count(name, value)
        from cpmp.worlds.relay.world import FEATURE_NAMES  # lazy: torch; the CLI parses first

        if min(self.scaling_features) < len(FEATURE_NAMES):
            raise ConfigError(
                f"scaling_features must be >= {len(FEATURE_NAMES)} (the relay task's features), "
                f"got {self.scaling_features}"
            )

    @classmethod
    def quick(cls, **overrides: object) -> BenchSettings:
        """Small sizes: 3 demonstrations, 4 episodes, ``experiment=tiny``.

        The run time is in docs/benchmarks.md.

        Args:
            **overrides: fields of :class:`BenchSettings` (passed through; checked there).
        """
        small = {
            "fit_demos": 3,
            "repeats": 1,
            "batch": 4,
            "ticks": 100,
            "max_time": 12.0,
            "experiment": "tiny",
            "scaling_demos": [3, 6],
            "scaling_features": [24, 48],
            "scaling_ticks": 50,
            "gradient_demos": 4,
            "gradient_epochs": 30,
        }
        return cls(**{**small, **overrides})


def check_count(name: str, value: object) -> None:
    """Check that option ``name`` holds a whole number >= 1.

    Raises:
        ConfigError: ``value`` is not, naming ``name``.
    """
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ConfigError(f"{name} must be a whole number >= 1, got {value!r}")
