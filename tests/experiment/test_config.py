"""The real Hydra configs compose for every option of every group and validate; bad values
fail fast with a clear message, before any demonstration is collected."""

from __future__ import annotations

import dataclasses
import pickle
import subprocess
import sys
from pathlib import Path

import pytest
import torch
import yaml
from hydra import compose, initialize_config_dir
from hydra.errors import ConfigCompositionException
from omegaconf import OmegaConf

from cpmp.benchmarks.sim import LEARNED_POLICY
from cpmp.compare.settings import CompareSettings, SweepSettings
from cpmp.config import (
    ACTIVATIONS,
    PREDICTOR_CONFIGS,
    BCConfig,
    FitConfig,
    GoalNearestConfig,
    KLRConfig,
    MLPConfig,
    SequencerConfig,
    TaskConfig,
    TrainerConfig,
    predictor_config,
)
from cpmp.errors import ConfigError, CpmpFileError
from cpmp.experiment.checkpoint_jobs import evaluate_checkpoint, train_from_file
from cpmp.experiment.config import (
    experiment_job,
    fit_settings,
    job_fit_settings,
    predictor_options,
    to_dict,
    validate_common,
)
from cpmp.experiment.fitting import fit_sequencer
from cpmp.experiment.jobs import run_experiment
from cpmp.experiment.settings import ExperimentSettings
from cpmp.predictors import PREDICTORS
from cpmp.predictors.mlp import _ACTIVATIONS
from cpmp.sequencer.sequencer import PAPER_OPTIONS, ConcurrentSequencer
from cpmp.worlds.two_point import make_demonstrations

# One thread: with a second busy process on a 2-core machine, torch's default two threads
# slow LBFGS fits down ~15x (spinning threads), see the fits below.
torch.set_num_threads(1)

ROOT = Path(__file__).resolve().parents[2]
CONF = ROOT / "conf"


def options(group: str) -> list[str]:
    """Every option of a config group: the names of ``conf/<group>/*.yaml``."""
    return sorted(p.stem for p in (CONF / group).glob("*.yaml"))


def compose_cfg(config_name: str, overrides: list[str] | None = None, hydra: bool = False):
    """Compose ``conf/<config_name>.yaml`` as the scripts do (``hydra``: keep ``cfg.hydra``)."""
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        return compose(config_name, overrides=overrides or [], return_hydra_config=hydra)


# config files that are variants of a predictor kind rather than a kind of their own
VARIANTS = {"paper": "klr"}


def test_every_predictor_kind_has_a_config_file():
    assert sorted(set(options("predictor")) - set(VARIANTS)) == sorted(PREDICTORS)


@pytest.mark.parametrize("name", options("predictor"))
def test_predictor_options_compose_and_validate(name):
    cfg = compose_cfg("experiment", [f"predictor={name}"])
    kind, opts = predictor_options(cfg.predictor)
    assert kind == VARIANTS.get(name, name)
    assert "kind" not in opts
    validate_common(cfg)


@pytest.mark.parametrize("kind", sorted(PREDICTORS))
def test_a_kinds_config_file_is_that_kinds_python_defaults(kind):
    """``predictor=<kind>`` on the command line means ``predictor="<kind>"`` in Python."""
    got_kind, opts = predictor_options(compose_cfg("experiment", [f"predictor={kind}"]).predictor)
    assert got_kind == kind
    assert opts == dataclasses.asdict(predictor_config(kind))


def test_paper_variant_is_the_papers_kernel():
    kind, opts = predictor_options(compose_cfg("experiment", ["predictor=paper"]).predictor)
    assert kind == "klr"
    paper = {k: opts[k] for k in ("feature_weighting", "feature_scaling", "path_noise")}
    assert paper == {"feature_weighting": "none", "feature_scaling": "none", "path_noise": "none"}
    assert opts == dataclasses.asdict(predictor_config("klr", **paper))


@pytest.mark.parametrize("name", options("experiment"))
def test_experiment_options_compose_and_validate(name):
    cfg = compose_cfg("experiment", [f"experiment={name}"])
    settings = ExperimentSettings.from_cfg(cfg.experiment)
    assert settings.name == name
    assert 3 * settings.train_per_strategy >= max(settings.train_sizes)


@pytest.mark.parametrize("group", ["sequencer", "trainer", "task"])
def test_other_groups_compose_and_validate(group):
    for name in options(group):
        cfg = compose_cfg("experiment", [f"{group}={name}"])
        kind, _ = validate_common(cfg)
        assert kind in PREDICTORS
        assert to_dict(cfg[group]), f"{group}={name} composed to nothing"
        assert isinstance(TaskConfig.from_dict(cfg.task), TaskConfig)


def test_sequencer_configs_mean_what_they_say():
    paper = SequencerConfig(**to_dict(compose_cfg("experiment", ["sequencer=paper"]).sequencer))
    assert (paper.threshold, paper.patience, paper.start_rule) == (0.65, 0.05, "independent")
    coupled = SequencerConfig(**to_dict(compose_cfg("experiment", ["sequencer=coupled"]).sequencer))
    assert coupled.start_rule == "learned"
    assert (coupled.coupling, coupled.recovery) == ("context", True)
    assert (paper.switch_rule, coupled.switch_rule) == ("paper", "peak")
    assert coupled.threshold == paper.threshold


def test_paper_options_are_the_paper_configs_and_fit_defaults_the_main_job():
    """``fit(demos, predictor="klr", **PAPER_OPTIONS)`` is ``predictor=paper sequencer=paper``;
    ``fit(demos)`` with no options is the main job's default configuration."""

    seq_keys = set(SequencerConfig.__dataclass_fields__)

    def resolved(cfg, options):
        kind, pred = predictor_options(cfg.predictor)
        seq = to_dict(cfg.sequencer)
        return (
            kind,
            dataclasses.asdict(predictor_config(kind, **pred)),
            dataclasses.asdict(SequencerConfig(**seq)),
        ), (
            "klr",
            dataclasses.asdict(
                predictor_config("klr", **{k: v for k, v in options.items() if k not in seq_keys})
            ),
            dataclasses.asdict(
                SequencerConfig(**{k: v for k, v in options.items() if k in seq_keys})
            ),
        )

    got, want = resolved(
        compose_cfg("experiment", ["predictor=paper", "sequencer=paper"]), PAPER_OPTIONS
    )
    assert got == want
    assert "predictor" not in PAPER_OPTIONS
    got, want = resolved(compose_cfg("experiment"), {})
    assert got == want


def test_quick_is_the_default_experiment():
    assert compose_cfg("experiment").experiment.name == "quick"


def test_full_experiment_has_the_papers_sizes():
    settings = ExperimentSettings.from_cfg(
        compose_cfg("experiment", ["experiment=full"]).experiment
    )
    assert (settings.demos_per_strategy, settings.train_per_strategy) == (5, 3)
    assert settings.train_sizes == [3, 6, 9]
    assert settings.n_boxes == 20


@pytest.mark.parametrize(
    ("name", "target"),
    [("local", "BasicLauncher"), ("joblib", "JoblibLauncher"), ("slurm", "SlurmLauncher")],
)
def test_launcher_options_compose(name, target):
    assert sorted(options("launcher")) == ["joblib", "local", "slurm"]
    cfg = compose_cfg("experiment", ["experiment=tiny", f"launcher={name}"], hydra=True)
    assert cfg.hydra.launcher._target_.endswith(target)
    if name == "joblib":
        assert cfg.hydra.launcher.n_jobs == 2


def test_hydra_output_dirs_are_under_logs():
    cfg = compose_cfg("experiment", hydra=True)
    assert cfg.hydra.job.chdir is False
    run_dir = OmegaConf.to_container(cfg.hydra.run, resolve=False)["dir"]
    assert run_dir.startswith("logs/${hydra.job.name}/")


@pytest.mark.parametrize(
    ("config_name", "overrides"),
    [
        ("train", ["data.path=demos.h5"]),
        ("evaluate", ["data.path=demos.h5", "checkpoint=model.pt"]),
        ("collect", []),
        ("progress_field", []),
        ("aggregate", ["sweep_dir=logs/x"]),
    ],
)
def test_other_entry_configs_compose(config_name, overrides):
    cfg = compose_cfg(config_name, overrides)
    if "predictor" in cfg:
        validate_common(cfg)
    expected = {
        "train": ("data.path", "demos.h5"),
        "evaluate": ("checkpoint", "model.pt"),
        "collect": ("n_demos", 15),
        "progress_field": ("predictor.kind", "klr"),
        "aggregate": ("sweep_dir", "logs/x"),
    }[config_name]
    assert OmegaConf.select(cfg, expected[0]) == expected[1]


def test_task_config_round_trips_through_the_composed_task():
    composed = to_dict(compose_cfg("experiment").task)
    task = TaskConfig.from_dict(composed)
    assert task == TaskConfig()
    # the pacing options (demo_*, robot_*) are left out of the plain form while unset
    unpaced = {k: v for k, v in composed.items() if not k.startswith(("demo_", "robot_"))}
    assert task.to_dict() == unpaced and len(unpaced) == len(composed) - 6
    assert TaskConfig.from_dict(task.to_dict()) == task


# ------------------------------------------------------------------------ the one schema
SCHEMAS = {
    "trainer": TrainerConfig,
    "sequencer": SequencerConfig,
    "task": TaskConfig,
    "experiment": ExperimentSettings,
}


def defaults_of(cls: type) -> dict:
    """A dataclass's defaults as YAML writes them (tuples as lists)."""
    out = {}
    for f in dataclasses.fields(cls):
        value = f.default if f.default_factory is dataclasses.MISSING else f.default_factory()
        out[f.name] = list(value) if isinstance(value, tuple) else value
    return out


def yaml_values(path: Path) -> dict:
    """The values a config file writes itself (no ``defaults`` list)."""
    raw = yaml.safe_load(path.read_text()) or {}
    raw.pop("defaults", None)
    return raw


@pytest.mark.parametrize("group", ["predictor", "sequencer", "trainer", "task"])
def test_group_options_compose_to_every_option_of_their_dataclass(group):
    for name in options(group):
        node = to_dict(compose_cfg("experiment", [f"{group}={name}"])[group])
        kind = node.pop("kind", None)
        if group == "predictor":
            cls = PREDICTOR_CONFIGS[kind]
        elif kind == "goal_nearest":
            cls = GoalNearestConfig
        elif kind == "bc":
            cls = BCConfig
        else:
            cls = SCHEMAS[group]
        assert list(node) == [f.name for f in dataclasses.fields(cls)], name


def test_experiment_node_composes_to_every_setting():
    for name in options("experiment"):
        node = to_dict(compose_cfg("experiment", [f"experiment={name}"]).experiment)
        assert list(node) == [f.name for f in dataclasses.fields(ExperimentSettings)], name


def written_values(group: str, path: Path) -> list[tuple[str, object, dict]]:
    """``(key, value, the schema's defaults)`` of every value ``path`` writes itself, for the
    options that start from a schema; ``[]`` for an option extending another option of its
    group (``klr_full``)."""
    values = yaml_values(path)
    if group == "experiment":
        schemas = {"experiment": ExperimentSettings, "task": TaskConfig}
        out = [
            (key, value, defaults_of(schemas[node]))
            for node in schemas
            for key, value in values.get(node, {}).items()
        ]
        compare = dict(values.get("compare", {}))
        sweep = compare.pop("sweep", {})
        out += [(key, value, defaults_of(CompareSettings)) for key, value in compare.items()]
        out += [(key, value, defaults_of(SweepSettings)) for key, value in sweep.items()]
        return out
    first = yaml.safe_load(path.read_text()).get("defaults", [""])[0]
    if group == "predictor":
        if not first.startswith("/schema_predictor_"):
            return []
        cls = PREDICTOR_CONFIGS[first.removeprefix("/schema_predictor_")]
        assert "kind" not in values, f"{path.name}: the schema carries the kind"
    elif first == "/schema_sequencer_goal_nearest":
        cls = GoalNearestConfig
        assert "kind" not in values, f"{path.name}: the schema carries the kind"
    elif first == "/schema_sequencer_bc":
        cls = BCConfig
        assert "kind" not in values, f"{path.name}: the schema carries the kind"
    else:
        cls = SCHEMAS[group]
    return [(key, value, defaults_of(cls)) for key, value in values.items()]


@pytest.mark.parametrize("group", ["predictor", "sequencer", "trainer", "task", "experiment"])
def test_no_config_file_restates_a_default(group):
    """A value written in ``conf/<group>/*.yaml`` differs from the schema's default: no default
    is written twice (the dataclasses of cpmp.config are the one place)."""
    checked = 0
    for path in sorted((CONF / group).glob("*.yaml")):
        for key, value, defaults in written_values(group, path):
            assert key in defaults, f"{path.name}: {key} is not an option"
            assert value != defaults[key], f"{path.name}: {key}: {value!r} is the default"
            checked += 1
    if group in ("trainer", "task"):
        assert checked == 0  # every option is the dataclass's default
    else:
        assert checked > 0


def test_every_predictor_kind_has_its_options_class():

    assert list(PREDICTOR_CONFIGS) == list(PREDICTORS)
    for kind, cls in PREDICTORS.items():
        assert cls.config_class is PREDICTOR_CONFIGS[kind]
    assert tuple(_ACTIVATIONS) == ACTIVATIONS


def test_the_schema_imports_neither_torch_nor_mujoco():
    code = (
        "import sys, cpmp.config, cpmp.experiment.config; "
        "print([m for m in ('torch', 'lightning', 'mujoco') if m in sys.modules])"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert proc.stdout.strip() == "[]"


@pytest.mark.parametrize(
    ("override", "key"),
    [
        ("experiment.n_boxes=abc", "experiment.n_boxes"),
        ("predictor.bias=maybe", "predictor.bias"),
        ("trainer.max_epochs=1.5", "trainer.max_epochs"),
        ("task.width_range=[0.1,x]", "task.width_range"),
    ],
)
def test_the_schema_rejects_a_value_of_the_wrong_type(override, key):

    with pytest.raises(ConfigCompositionException, match=key.replace(".", r"\.")):
        compose_cfg("experiment", [override])


def test_learned_policy_of_the_simulator_benchmark_is_the_main_jobs_default():

    main = job_fit_settings(compose_cfg("experiment")).fit
    assert FitConfig.from_options(**LEARNED_POLICY) == main


def test_fit_settings_are_converted_once_into_typed_configs():
    cfg = compose_cfg("experiment", ["predictor=mlp", "sequencer=paper", "trainer.lr=0.5"])
    settings = job_fit_settings(cfg)
    assert settings.goal_nearest is None
    assert isinstance(settings.fit.predictor_config, MLPConfig)
    assert settings.fit.predictor_config.hidden == (32, 32)
    assert settings.fit.predictor_config.lr == 0.5  # the trainer's rate, recorded in the model
    assert settings.fit.sequencer == SequencerConfig(**to_dict(cfg.sequencer))
    assert settings.fit.trainer.lr == 0.5
    # a predictor without an Adam rate keeps its options (the rate is not an option of klr)
    klr = job_fit_settings(compose_cfg("experiment", ["predictor=klr", "trainer.lr=0.5"]))
    assert not hasattr(klr.fit.predictor_config, "lr")
    baseline = job_fit_settings(compose_cfg("experiment", ["sequencer=goal_nearest"]))
    assert baseline.goal_nearest is not None and baseline.goal_nearest.hold_time == 0.1
    # the baseline needs no predictor group (experiment=compare runs it without one) ...
    alone = fit_settings({}, {"kind": "goal_nearest", "hold_time": 0.3})
    assert alone.goal_nearest.hold_time == 0.3
    assert alone.baseline == "goal_nearest" and alone.bc is None
    # sequencer=bc likewise, with its own options
    bc = job_fit_settings(compose_cfg("experiment", ["sequencer=bc", "sequencer.threshold=0.7"]))
    assert bc.bc == BCConfig(threshold=0.7) and bc.goal_nearest is None
    assert bc.baseline_options() == {"kind": "bc", **dataclasses.asdict(BCConfig(threshold=0.7))}
    assert fit_settings({}, {"kind": "bc", "gamma": 8.0}).bc.gamma == 8.0
    with pytest.raises(ConfigError, match=r"unknown option.*hold_time.*sequencer=bc"):
        fit_settings({}, {"kind": "bc", "hold_time": 0.3})
    with pytest.raises(ConfigError, match=r"sequencer\.kind must be 'goal_nearest', 'bc'"):
        fit_settings({}, {"kind": "nearest"})
    # ... the learned sequencer does
    with pytest.raises(ConfigError, match=r"predictor\.kind must be one of"):
        fit_settings({}, None)


def test_experiment_job_is_typed_and_picklable():

    job = experiment_job(compose_cfg("experiment", ["experiment=tiny"]))
    assert job.settings.name == "tiny" and job.task == TaskConfig()
    assert experiment_job(job) is job
    assert pickle.loads(pickle.dumps(job)) == job


def test_keyword_fit_is_the_typed_fit(tmp_path):

    demos = make_demonstrations(2, seed=0)
    by_keyword = ConcurrentSequencer.fit(
        demos, "klr", seed=3, logger=None, gamma=2.0, threshold=0.7
    )
    typed = ConcurrentSequencer.fit_config(
        demos,
        FitConfig(
            "klr",
            KLRConfig(gamma=2.0),
            SequencerConfig(threshold=0.7),
            TrainerConfig(),
            seed=3,
        ),
    )
    assert typed.config == by_keyword.config
    assert typed.predictor.config == by_keyword.predictor.config
    for (name, a), b in zip(
        typed.predictor.state_dict().items(),
        by_keyword.predictor.state_dict().values(),
        strict=True,
    ):
        assert torch.equal(a, b), name
    with pytest.raises(ConfigError, match="MLPConfig"):
        FitConfig("mlp", KLRConfig())
    with pytest.raises(ConfigError, match="unknown option 'gama'"):
        FitConfig.from_options("klr", gama=2.0)


# ---------------------------------------------------------------------------- bad values
def test_unknown_predictor_names_the_valid_ones():
    cfg = compose_cfg("experiment", ["predictor.kind=svm"])
    with pytest.raises(ConfigError, match="svm") as err:
        predictor_options(cfg.predictor)
    for name in PREDICTORS:
        assert name in str(err.value)


def test_unknown_predictor_option_is_a_config_error():
    cfg = compose_cfg("experiment", ["+predictor.kernel=rbf"])
    with pytest.raises(ConfigError, match="kernel"):
        predictor_options(cfg.predictor)


@pytest.mark.parametrize(
    ("override", "match"),
    [
        ("experiment.n_boxes=-1", "n_boxes"),
        ("experiment.demos_per_strategy=0", "demos_per_strategy"),
        ("experiment.seeds=[-1]", "seeds"),
        ("experiment.seeds=[]", "seeds"),
        ("experiment.train_sizes=[3,99]", r"train_sizes must lie in 1\.\.6"),
        ("experiment.train_per_strategy=3", "smaller than demos_per_strategy"),
        ("experiment.strategy_grid=[1,4]", "strategy_grid"),
        ("experiment.record=some", "record"),
        ("experiment.max_time=0", "max_time"),
        ("+experiment.n_box=3", "unknown experiment option.*n_box"),
        ("experiment.seeds=[0,0]", "seeds has duplicates"),
        ("experiment.train_sizes=[3,3]", "train_sizes has duplicates"),
    ],
)
def test_bad_experiment_values_raise_config_error(override, match):
    cfg = compose_cfg("experiment", ["experiment=quick", override])
    with pytest.raises(ConfigError, match=match):
        ExperimentSettings.from_cfg(cfg.experiment)


@pytest.mark.parametrize(
    ("key", "value", "match"),
    [
        ("n_boxes", 2.5, "n_boxes must be an integer"),
        ("seeds", [True], "seeds must be integers"),
        ("workers", 0, "workers must be an integer >= 1"),
        ("feature_noise", float("inf"), "feature_noise must be finite"),
    ],
)
def test_bad_experiment_values_from_a_mapping_raise_config_error(key, value, match):
    """Values the schema turns away at composition still fail the settings' own checks when
    they come as a plain mapping (the Python API, a worker's dict)."""
    quick = to_dict(compose_cfg("experiment").experiment)
    with pytest.raises(ConfigError, match=match):
        ExperimentSettings.from_cfg({**quick, key: value})


@pytest.mark.parametrize(
    "override",
    [
        "predictor.kind=svm",
        "experiment.n_boxes=-1",
        "+task.box_colour=red",
        "task.box_height=0.5",
        "sequencer.threshold=1.5",
        "trainer.val_fraction=1.5",
        "trainer.lbfgs_history_size=0",
    ],
)
def test_run_experiment_fails_before_collecting(tmp_path, override):
    cfg = compose_cfg("experiment", ["experiment=tiny", override])
    with pytest.raises(ConfigError):
        run_experiment(cfg, tmp_path)
    assert not (tmp_path / "seed_0").exists()


def test_train_without_data_path_or_file(tmp_path):
    with pytest.raises(ConfigError, match=r"data\.path is required"):
        train_from_file(compose_cfg("train"), tmp_path)
    missing = tmp_path / "nope.h5"
    with pytest.raises(CpmpFileError, match=r"nope\.h5"):
        train_from_file(compose_cfg("train", [f"data.path={missing}"]), tmp_path)
    assert not (tmp_path / "model.pt").exists()


def test_train_with_bad_predictor_fails_before_reading_data(tmp_path):
    cfg = compose_cfg("train", [f"data.path={tmp_path / 'nope.h5'}", "predictor.kind=svm"])
    with pytest.raises(ConfigError, match=r"predictor\.kind"):
        train_from_file(cfg, tmp_path)


def test_evaluate_without_checkpoint_or_with_missing_one(tmp_path):
    data = f"data.path={tmp_path / 'nope.h5'}"
    with pytest.raises(ConfigError, match="checkpoint is required"):
        evaluate_checkpoint(compose_cfg("evaluate", [data]), tmp_path)
    cfg = compose_cfg("evaluate", [data, f"checkpoint={tmp_path / 'model.pt'}"])
    with pytest.raises(CpmpFileError, match=r"model\.pt"):
        evaluate_checkpoint(cfg, tmp_path)


def test_evaluate_with_missing_demo_file(tmp_path):

    cfg = compose_cfg("train", ["logger=none"])
    seq = fit_sequencer(make_demonstrations(2, seed=0), cfg.predictor, None, cfg.trainer)
    checkpoint = seq.save(tmp_path / "model.pt")
    cfg = compose_cfg("evaluate", [f"data.path={tmp_path / 'nope.h5'}", f"checkpoint={checkpoint}"])
    with pytest.raises(CpmpFileError, match=r"nope\.h5"):
        evaluate_checkpoint(cfg, tmp_path)
    assert not (tmp_path / "evaluation.json").exists()


def test_to_dict_rejects_non_mappings():
    assert to_dict(None) == {}
    with pytest.raises(ConfigError, match="mapping"):
        to_dict([1, 2])


def test_script_with_bad_value_exits_2_with_one_error_line(tmp_path, run_script):
    run_dir = tmp_path / "run"
    argv = ["experiment=tiny", "experiment.n_boxes=-1", f"hydra.run.dir={run_dir}"]
    proc = run_script("experiment.py", *argv)
    assert proc.returncode == 2, proc.stderr
    errors = [line for line in proc.stderr.splitlines() if line.startswith("error:")]
    assert len(errors) == 1, proc.stderr
    assert "experiment.n_boxes must be >= 1, got -1" in errors[0]
    assert "Traceback" not in proc.stderr
    # Failed during validation, before the (slow) collection of demonstrations.
    assert not (run_dir / "seed_0" / "demos.h5").exists()
    assert not (run_dir / "report.json").exists()


def test_fit_sequencer_with_the_default_trainer_config():
    """The trainer's ``lr`` (null by default) and an Adam predictor's own ``lr`` must not clash;
    a trainer ``lr`` that is set overrides the predictor's."""

    demos = make_demonstrations(2, seed=0)
    overrides = ["predictor=mlp", "logger=none", "trainer.max_epochs=2"]
    cfg = compose_cfg("train", overrides)
    seq = fit_sequencer(demos, cfg.predictor, None, cfg.trainer)
    assert seq.predictor.config.lr == cfg.predictor.lr
    cfg = compose_cfg("train", [*overrides, "trainer.lr=0.005"])
    assert fit_sequencer(demos, cfg.predictor, None, cfg.trainer).predictor.config.lr == 0.005
