"""Every option of cpmp as a dataclass: the one schema of the Hydra configs in ``conf/``.

Each group of ``conf/`` (``predictor``, ``sequencer``, ``trainer``, ``task``) is built on one
of these classes, registered by :mod:`cpmp.experiment.config`; the YAML files hold only what
differs from the defaults written here, and each class's docstring says what every option
means. The classes validate themselves when built (``__post_init__``): wrong values raise
:class:`~cpmp.errors.ConfigError`.

This package imports neither torch nor MuJoCo, so that a command line is checked before
either is loaded; the classes are re-exported where they are used (:mod:`cpmp.predictors`,
:mod:`cpmp.sequencer.sequencer`, :mod:`cpmp.predictors.training`, :mod:`cpmp.sim`).
:mod:`cpmp.config.paths` says where ``conf/`` itself is installed.
"""

from cpmp.config.bc import BCConfig, bc_options
from cpmp.config.fit import FIT_OPTIONS, FitConfig
from cpmp.config.goal_nearest import GoalNearestConfig, goal_nearest_options
from cpmp.config.predictors import (
    ACTIVATIONS,
    DTYPES,
    FLOAT32_FROM_SAMPLES,
    PREDICTOR_CONFIGS,
    SCALINGS,
    SKLEARN_SOLVERS,
    DTWConfig,
    KLRConfig,
    MLPConfig,
    PredictorConfig,
    RegressionClipConfig,
    SklearnKLRConfig,
    SparseKLRConfig,
    TimePhaseConfig,
    predictor_config,
    predictor_config_class,
    predictor_option_names,
    resolved_dtype,
)
from cpmp.config.sequencer import (
    BRANCHES,
    COUPLINGS,
    NONFINITE_POLICIES,
    START_RULES,
    SWITCH_RULES,
    SequencerConfig,
    existing_sequencer_options,
)
from cpmp.config.task import TaskConfig
from cpmp.config.trainer import SOLVERS, SolverOptions, TrainerConfig

__all__ = [
    "ACTIVATIONS",
    "BRANCHES",
    "COUPLINGS",
    "DTYPES",
    "FIT_OPTIONS",
    "FLOAT32_FROM_SAMPLES",
    "NONFINITE_POLICIES",
    "PREDICTOR_CONFIGS",
    "SCALINGS",
    "SKLEARN_SOLVERS",
    "SOLVERS",
    "START_RULES",
    "SWITCH_RULES",
    "BCConfig",
    "DTWConfig",
    "FitConfig",
    "GoalNearestConfig",
    "KLRConfig",
    "MLPConfig",
    "PredictorConfig",
    "RegressionClipConfig",
    "SequencerConfig",
    "SklearnKLRConfig",
    "SolverOptions",
    "SparseKLRConfig",
    "TaskConfig",
    "TimePhaseConfig",
    "TrainerConfig",
    "bc_options",
    "existing_sequencer_options",
    "goal_nearest_options",
    "predictor_config",
    "predictor_config_class",
    "predictor_option_names",
    "resolved_dtype",
]
