"""The command-line entry points (``cpmp-*`` console scripts and ``scripts/*.py``): every kind
of bad override ends a Hydra command with exit status 2 and one ``error:`` line naming it,
before torch, Lightning or MuJoCo are imported; ``evaluate`` reports MPs the model does not
know.

Most command lines are run by calling the function a console script calls
(``cpmp.cli.main.<name>_main``, ``scripts/<name>.py`` through :func:`runpy.run_path`) with
``sys.argv`` set, reading its exit status and the process's stderr (file descriptor 2);
the bad overrides that must fail before anything heavy is imported run that way in one fresh
interpreter (:func:`light_runs`). A few commands still run as real processes to prove the
wiring of the installed console scripts: a bad override and a bad value
(:func:`test_a_console_script_exits_2_with_one_error_line`), a job's own user error, a job
that runs from another directory.
"""

from __future__ import annotations

import json
import logging
import pickle
import runpy
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hydra import compose, initialize_config_dir

from cpmp.cli import main as cli
from cpmp.cli.main import COMMANDS, CONF_DIR, _Task, check_command
from cpmp.compare import job as compare_job
from cpmp.data.datafile import save_demonstrations
from cpmp.data.demonstration import Demonstration
from cpmp.errors import ConfigError, CpmpFileError
from cpmp.experiment import jobs as experiment_jobs
from cpmp.experiment.checkpoint_jobs import evaluate_checkpoint

ROOT = Path(__file__).resolve().parents[2]
BIN = Path(sys.executable).parent
HEAVY = ("torch", "lightning", "mujoco", "pytorch_kinematics", "rerun", "matplotlib", "sklearn")


def console_script(name: str) -> str:
    """The installed ``cpmp-<name>`` command (``pip install -e .`` puts it beside python)."""
    path = BIN / f"cpmp-{name.replace('_', '-')}"
    assert path.is_file(), f"{path} is missing: re-install with pip install -e ."
    return str(path)


def run(argv: list[str], cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run(argv, cwd=cwd, capture_output=True, text=True, timeout=300)


def one_error_line(code: object, stderr: str, stdout: str = "") -> str:
    """The one ``error:`` line of a failed command (exit status ``code`` 2, no traceback)."""
    assert code == 2, stdout[-2000:] + stderr[-2000:]
    assert "Traceback" not in stderr, stderr
    errors = [line for line in stderr.splitlines() if line.startswith("error:")]
    assert len(errors) == 1, stderr
    return errors[0]


def error_line(proc: subprocess.CompletedProcess) -> str:
    """The one ``error:`` line of a failed process (exit status 2, no traceback)."""
    return one_error_line(proc.returncode, proc.stderr, proc.stdout)


def _no_job(*args: object, **kwargs: object) -> None:
    """Stands in for ``hydra.main`` where the checks must fail first: a command line that
    passed them fails the test here instead of starting a (long) job in the test process."""
    raise AssertionError("the command line passed the checks: Hydra would start the job")


def run_in_process(
    main: Any, argv: list[str], cwd: Path, monkeypatch: pytest.MonkeyPatch, capfd: Any
) -> tuple[object, str, str]:
    """``main()`` as its console script runs it: ``sys.argv`` = ``argv``, working directory
    ``cwd``; ``(exit status, stdout, stderr)`` with both streams read at the file descriptors
    (``capfd``), so output that bypasses ``sys.stderr`` is seen too."""
    monkeypatch.chdir(cwd)
    monkeypatch.setattr(sys, "argv", argv)
    capfd.readouterr()
    with pytest.raises(SystemExit) as info:
        main()
    out, err = capfd.readouterr()
    return info.value.code, out, err


# Every kind of bad override on every Hydra command: (command, argv, words the error names).
# ``{file}`` stands for an existing file. All of them fail in check_command (light imports).
LIGHT_CASES = [
    # an unknown option of a config group
    ("experiment", ["predictor=svm"], ["predictor=svm", "klr_sparse", "paper"]),
    ("train", ["predictor=svm"], ["predictor=svm", "klr_sparse", "paper"]),
    ("evaluate", ["data=nope"], ["data=nope", "default"]),
    ("collect", ["task=defalt"], ["task=defalt", "did you mean task=default"]),
    ("aggregate", ["hydra/launcher=nope"], ["hydra/launcher=nope", "joblib"]),
    ("progress_field", ["predictor=svm"], ["predictor=svm", "klr_sparse"]),
    ("compare", ["experiment=compare_tny"], ["experiment=compare_tny", "compare_tiny"]),
    ("experiment", ["-m", "launcher=slrum"], ["launcher=slrum", "did you mean launcher=slurm"]),
    # an unknown key
    (
        "experiment",
        ["predictr=klr"],
        ["predictr=klr", "did you mean 'predictor'", "write predictor=klr"],
    ),
    # a misspelt key gets the corrected override, not '+' (which would fail at the job's checks)
    (
        "experiment",
        ["sequencer.treshold=0.7"],
        ["did you mean 'sequencer.threshold'", "write sequencer.threshold=0.7"],
    ),
    (
        "experiment",
        ["nokey_at_all=1"],
        ["nokey_at_all=1", "to add a new key write +nokey_at_all=1"],
    ),
    ("experiment", ["experiment.n_boxs=3"], ["experiment.n_boxs", "'experiment.n_boxes'"]),
    # an option that was removed is named so, not offered to be added with '+'
    (
        "experiment",
        ["predictor=klr_sparse", "predictor.method=l1"],
        ["predictor.method=l1: removed option predictor.method", "(method: l1) was removed"],
    ),
    (
        "experiment",
        ["sequencer.start_kernel=isotropic"],
        ["removed option sequencer.start_kernel", "isotropic start heads", "were removed"],
    ),
    ("train", ["data.pth=x.h5"], ["data.pth=x.h5", "'data.path'"]),
    ("evaluate", ["checkpont=m.pt"], ["checkpont=m.pt", "'checkpoint'"]),
    ("collect", ["n_demo=3"], ["n_demo=3", "'n_demos'"]),
    ("aggregate", ["sweepdir=x"], ["sweepdir=x", "'sweep_dir'"]),
    ("progress_field", ["n_trajectory=3"], ["n_trajectory=3", "'n_trajectories'"]),
    ("compare", ["compare.predictor=[klr]"], ["compare.predictor", "'compare.predictors'"]),
    ("compare", ["compare.sweep.support=[1]"], ["compare.sweep.support", "support_scale"]),
    ("experiment", ["+predictor.gamma=2"], ["+predictor.gamma=2", "predictor.gamma=2"]),
    # a value of the wrong type, an override Hydra cannot parse, an unresolvable interpolation
    ("experiment", ["experiment.n_boxes=abc"], ["experiment.n_boxes='abc'", "integer"]),
    ("experiment", ["experiment.seeds=[0,x]"], ["experiment.seeds", "'x'", "integer"]),
    ("experiment", ["predictor.gamma=[1"], ["predictor.gamma=[1"]),
    ("experiment", ["experiment.n_boxes=${nope}"], ["experiment.n_boxes", "nope"]),
    ("experiment", ["predictor=klr,mlp"], ["predictor=klr,mlp", "--multirun"]),
    ("experiment", ["predictor.bias=1"], ["predictor.bias=1", "boolean"]),
    # ... against the schema (cpmp.config) where the default (null) says nothing
    ("experiment", ["predictor.max_support=abc"], ["predictor.max_support=abc", "Integer"]),
    ("experiment", ["--cfg", "job", "trainer.max_epochs=x"], ["trainer.max_epochs=x", "Integer"]),
    ("train", ["seed=abc"], ["seed='abc'", "integer"]),
    ("train", ["seed=-1"], ["seed=-1", "non-negative"]),
    ("evaluate", ["data.split=3"], ["data.split=3", "string"]),
    ("collect", ["balanced=maybe"], ["balanced='maybe'", "boolean"]),
    ("collect", ["n_demos=0"], ["n_demos=0", ">= 1"]),
    ("aggregate", ["hydra.job.chdir=abc"], ["hydra.job.chdir=abc", "bool"]),
    ("progress_field", ["seed=1.5"], ["seed=1.5", "integer"]),
    ("compare", ["compare.sweep.support_scale=[1,x]"], ["support_scale", "'x'", "number"]),
    ("compare", ["experiment.n_boxes=abc"], ["experiment.n_boxes='abc'", "integer"]),
    # ... also through the alias (cpmp-experiment experiment=compare_tiny)
    (
        "experiment",
        ["experiment=compare_tiny", "compare.baseline=[goal_nearest]"],
        ["compare.baseline", "'compare.baselines'"],
    ),
    # a missing file or directory, an unset required path
    ("experiment", ["--config-dir", "nope"], ["--config-dir nope"]),
    ("train", [], ["data.path is required"]),
    ("train", ["data.path=nope.h5"], ["data.path=nope.h5", "no such file"]),
    ("evaluate", ["checkpoint=nope.pt", "data.path={file}"], ["checkpoint=nope.pt"]),
    ("evaluate", ["checkpoint={file}", "data.path=nope.h5"], ["data.path=nope.h5"]),
    ("collect", ["--config-dir", "nope"], ["--config-dir nope"]),
    ("aggregate", ["sweep_dir=nope"], ["sweep_dir=nope", "no such directory"]),
    ("progress_field", ["--config-dir", "nope"], ["--config-dir nope"]),
    ("compare", ["--config-dir", "nope"], ["--config-dir nope"]),
    # a sweep is checked job by job before the first one starts
    (
        "experiment",
        ["-m", "predictor=klr,mlp", "predictor.support_scale=1,2"],
        ["predictor.support_scale=1", "job predictor=mlp predictor.support_scale=1"],
    ),
    # a bad flag
    ("train", ["--nope"], ["--nope"]),
]


def case_id(case: tuple[str, list[str], list[str]]) -> str:
    return f"{case[0]}:{' '.join(case[1]) or '(none)'}"


def fill(argv: list[str], file: Path) -> list[str]:
    return [a.replace("{file}", str(file)) for a in argv]


@pytest.fixture
def some_file(tmp_path: Path) -> Path:
    path = tmp_path / "exists.bin"
    path.write_bytes(b"not read by the checks")
    return path


LIGHT_RUNNER = r"""
import json, os, sys, tempfile, traceback, warnings
from pathlib import Path

from cpmp.cli import main as cli
from cpmp.errors import CpmpError

spec = json.loads(Path(sys.argv[1]).read_text())
seen = {}
real_fail = cli._fail


def observed_fail(err):
    # what the command failed with and where it was raised; then the real _fail
    frames, tb = [], err.__traceback__
    while tb is not None:
        frames.append(tb.tb_frame.f_code.co_name)
        tb = tb.tb_next
    seen.update(cpmp_error=isinstance(err, CpmpError), frames=frames)
    real_fail(err)


def no_job(*args, **kwargs):
    raise AssertionError("the command line passed the checks: Hydra would start the job")


cli._fail = observed_fail
cli.hydra.main = no_job
runs = {}
for case in spec["cases"]:
    cwd = Path(case["cwd"])
    cwd.mkdir()
    os.chdir(cwd)
    seen.clear()
    sys.argv = ["cpmp-" + case["command"].replace("_", "-"), *case["argv"]]
    main = getattr(cli, case["command"] + "_main")
    with tempfile.TemporaryFile() as captured, warnings.catch_warnings():
        # catch_warnings resets the warning registries: a warning shows in every case, as in
        # a fresh process; fd 2 is captured, as a parent process reads stderr
        sys.stderr.flush()
        saved = os.dup(2)
        os.dup2(captured.fileno(), 2)
        try:
            main()
            code = 0
        except SystemExit as done:  # the exit status Python gives SystemExit(code)
            code = 0 if done.code is None else done.code
            if not isinstance(code, int):
                print(code, file=sys.stderr)
                code = 1
        except BaseException:
            traceback.print_exc()
            code = 1
        finally:
            sys.stderr.flush()
            os.dup2(saved, 2)
            os.close(saved)
        captured.seek(0)
        stderr = captured.read().decode()
    runs[case["id"]] = {"code": code, "stderr": stderr, "logs": (cwd / "logs").exists(), **seen}
os.chdir(spec["root"])
passed = [len(cli.check_command(command, argv)) for command, argv in spec["good"]]
heavy = [m for m in spec["heavy"] if m in sys.modules]
Path(spec["out"]).write_text(json.dumps({"runs": runs, "passed": passed, "heavy": heavy}))
"""
"""Runs every case of :data:`LIGHT_CASES` through its command's entry point
(``cli.<command>_main``, with ``sys.argv`` set, in a directory of its own, stderr read at file
descriptor 2) in one fresh interpreter, then checks the good command lines of
:func:`light_runs` with :func:`check_command`, and lists the heavy modules it imported.
``cli._fail`` is wrapped to record the error it prints (its class, where it was raised) and
``hydra.main`` replaced by a stub that fails: none of these command lines may get that far."""


@pytest.fixture(scope="module")
def light_runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """The bad overrides of :data:`LIGHT_CASES`, and six good command lines, run by
    :data:`LIGHT_RUNNER` in one fresh interpreter: ``runs`` (by :func:`case_id`: exit status,
    stderr, whether ``logs/`` was made, the error's class and frames), ``passed`` (the good
    command lines' job counts) and ``heavy`` (heavy modules imported by the end)."""
    root = tmp_path_factory.mktemp("light")
    some_file = root / "exists.bin"
    some_file.write_bytes(b"not read by the checks")
    ids = [case_id(case) for case in LIGHT_CASES]
    assert len(set(ids)) == len(ids), "case ids must be unique"
    cases = [
        {"id": id_, "command": c, "argv": fill(a, some_file), "cwd": str(root / f"case_{i}")}
        for i, (id_, (c, a, _)) in enumerate(zip(ids, LIGHT_CASES, strict=True))
    ]
    good = [
        ("experiment", ["experiment=tiny", "predictor=mlp", "predictor.lr=0.1"]),
        ("train", [f"data.path={some_file}", "seed=3"]),
        ("evaluate", [f"checkpoint={some_file}", f"data.path={some_file}"]),
        ("aggregate", [f"sweep_dir={root}"]),
        ("compare", ["experiment=compare_tiny", "compare.predictors=[klr,mlp]"]),
        ("experiment", ["experiment=compare_tiny"]),
    ]
    out = root / "runs.json"
    spec = {"cases": cases, "good": good, "heavy": HEAVY, "root": str(root), "out": str(out)}
    (root / "spec.json").write_text(json.dumps(spec))
    proc = run([sys.executable, "-c", LIGHT_RUNNER, str(root / "spec.json")], cwd=root)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-3000:]
    results = json.loads(out.read_text())
    assert sorted(results["runs"]) == sorted(ids)
    return {**results, "n_good": len(good)}


@pytest.mark.parametrize("case", LIGHT_CASES, ids=case_id)
def test_bad_override_exits_2_with_one_error_line(case, light_runs):
    """The command's entry point exits with status 2; its stderr is one ``error:`` line, which
    names the override (and the hint); no run directory was made (failed before Hydra ran)."""
    names = case[2]
    result = light_runs["runs"][case_id(case)]
    line = one_error_line(result["code"], result["stderr"])
    assert result["stderr"].strip() == line  # nothing but the error line
    for name in names:
        assert name in line
    assert not result["logs"]  # no run directory: failed before Hydra ran


def test_light_checks_import_no_heavy_module(light_runs):
    """Every bad override above fails in :func:`check_command` with a CpmpError, and every
    good command line passes, in a fresh interpreter that has not imported torch, Lightning,
    MuJoCo, rerun or matplotlib by the end."""
    for id_, result in light_runs["runs"].items():
        assert result.get("cpmp_error") is True, (id_, result)
        assert "check_command" in result["frames"], (id_, result["frames"])
    assert light_runs["passed"] == [1] * light_runs["n_good"]
    assert light_runs["heavy"] == []


@pytest.mark.parametrize(
    ("command", "argv", "n_jobs"),
    [
        ("experiment", ["predictor.gamma=2"], 1),  # an integer where the default is a float
        ("experiment", ["logger.name=null"], 1),  # null where the default is a string
        ("experiment", ["experiment.max_time=5"], 1),  # a null default takes any type
        ("experiment", ["experiment.seeds=[0,1]"], 1),
        ("experiment", ["-m", "predictor=klr,klr_sparse", "predictor.gamma=2,4"], 4),
        ("train", ["-m", "seed=range(3)", "data.path={file}"], 3),
        ("evaluate", ["data.split=null", "checkpoint={file}", "data.path={file}"], 1),
        ("experiment", ["--cfg", "job", "experiment.n_boxes=-1"], 0),  # prints, runs nothing
        ("experiment", ["--help"], 0),
    ],
)
def test_good_command_lines_pass_the_checks(command, argv, n_jobs, some_file):
    jobs = check_command(command, fill(argv, some_file))
    assert len(jobs) == n_jobs
    if n_jobs == 4:
        combos = {(j.cfg.predictor.kind, j.cfg.predictor.gamma) for j in jobs}
        assert combos == {("klr", 2), ("klr", 4), ("klr_sparse", 2), ("klr_sparse", 4)}
    if command == "train":
        assert [j.cfg.seed for j in jobs] == [0, 1, 2]


def test_config_dir_adds_options_of_your_own(tmp_path):
    (tmp_path / "predictor").mkdir()
    (tmp_path / "predictor" / "mine.yaml").write_text(
        "defaults:\n  - klr\n  - _self_\ngamma: 3.0\n"
    )
    (job,) = check_command("experiment", ["--config-dir", str(tmp_path), "predictor=mine"])
    assert (job.cfg.predictor.kind, job.cfg.predictor.gamma) == ("klr", 3.0)
    with pytest.raises(ConfigError, match=r"predictor\.gamma='x'.*default is 3\.0"):
        check_command("experiment", ["-cd", str(tmp_path), "predictor=mine", "predictor.gamma=x"])


def test_check_command_raises_cpmp_errors(tmp_path):
    with pytest.raises(ConfigError, match="predictr"):
        check_command("experiment", ["predictr=klr"])
    with pytest.raises(CpmpFileError, match=r"nope\.h5"):
        check_command("train", [f"data.path={tmp_path / 'nope.h5'}"])


# Bad values the job's own checks find (they import torch; MuJoCo for the task): still one line,
# still before Hydra starts the job (no run directory).
DEEP_CASES = [
    ("train", ["data.path={file}", "sequencer.threshold=2"], ["sequencer.threshold=2"]),
    ("collect", ["task.max_time=-1"], ["task.max_time=-1", "max_time"]),
    ("progress_field", ["predictor.gamma=-1"], ["predictor.gamma=-1", "gamma"]),
    (
        "experiment",
        ["-m", "experiment.n_boxes=2,-1"],
        ["experiment.n_boxes must be >= 1, got -1", "job experiment.n_boxes=-1"],
    ),
    ("compare", ["sequencer=goal_nearest"], ["job's sequencer", "learned one"]),
    ("compare", ["compare.sweep.train_sizes=[4]"], ["compare.sweep.train_sizes", "[3, 9]"]),
    (
        "experiment",
        ["experiment=compare_tiny", "compare.sweep.support_scale=[0]"],
        ["compare.sweep.support_scale", "numbers > 0"],
    ),
]


@pytest.mark.parametrize("case", DEEP_CASES, ids=case_id)
def test_bad_value_fails_before_the_job_starts(case, tmp_path, some_file, monkeypatch, capfd):
    """The command's entry point exits with status 2 and one ``error:`` line naming the value,
    and made no run directory (Hydra never started: ``hydra.main`` would fail the test)."""
    command, argv, names = case
    monkeypatch.setattr(cli.hydra, "main", _no_job)
    main = getattr(cli, f"{command}_main")
    argv = [f"cpmp-{command.replace('_', '-')}", *fill(argv, some_file)]
    code, out, err = run_in_process(main, argv, tmp_path, monkeypatch, capfd)
    line = one_error_line(code, err, out)
    for name in names:
        assert name in line
    assert not (tmp_path / "logs").exists()


@pytest.mark.parametrize("case", [LIGHT_CASES[0], DEEP_CASES[0]], ids=case_id)
def test_a_console_script_exits_2_with_one_error_line(case, tmp_path, some_file):
    """The installed console script, as a process: a bad override (caught by the light checks)
    and a bad value (caught by the job's own checks) end it with exit status 2, one
    ``error:`` line naming them, and no run directory."""
    command, argv, names = case
    proc = run([console_script(command), *fill(argv, some_file)], cwd=tmp_path)
    line = error_line(proc)
    if case in LIGHT_CASES:
        assert proc.stderr.strip() == line  # nothing but the error line
    for name in names:
        assert name in line
    assert not (tmp_path / "logs").exists()


@pytest.mark.slow
def test_user_error_inside_the_job_exits_2(tmp_path, some_file):
    """A damaged checkpoint is found by the job: the same one-line error and status 2."""
    proc = run(
        [
            console_script("evaluate"),
            f"checkpoint={some_file}",
            f"data.path={some_file}",
            f"hydra.run.dir={tmp_path / 'run'}",
        ],
        cwd=tmp_path,
    )
    assert str(some_file) in error_line(proc)


@pytest.mark.parametrize("script", sorted(COMMANDS))
def test_scripts_are_wrappers_of_the_commands(script, tmp_path, monkeypatch, capfd):
    """``python scripts/<script>.py nokey=1`` (the file run as ``__main__``, as python runs
    it) checks the command line of command ``script``: exit status 2 and one error line
    naming that command's config."""
    path = ROOT / "scripts" / f"{script}.py"
    monkeypatch.setattr(cli.hydra, "main", _no_job)
    code, out, err = run_in_process(
        lambda: runpy.run_path(str(path), run_name="__main__"),
        [str(path), "nokey=1"],
        tmp_path,
        monkeypatch,
        capfd,
    )
    assert f"the {script} config has no key 'nokey'" in one_error_line(code, err, out)


def test_help_lists_the_config_groups(tmp_path, monkeypatch, capfd):
    """``cpmp-experiment --help`` exits with status 0 and lists every predictor option."""
    argv = ["cpmp-experiment", "--help"]
    code, out, err = run_in_process(cli.experiment_main, argv, tmp_path, monkeypatch, capfd)
    assert code == 0, err
    predictors = ", ".join(sorted(p.stem for p in (CONF_DIR / "predictor").glob("*.yaml")))
    assert f"predictor: {predictors}" in out


@pytest.mark.slow
def test_command_runs_from_anywhere_into_logs_of_its_job(tmp_path):
    """The installed command finds the repository's conf/ from another directory and names
    its run directory after the job."""
    proc = run([console_script("progress_field"), "n_trajectories=2"], cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-3000:]
    png = Path(proc.stdout.strip().splitlines()[-1])
    assert png.is_file() and png.name == "progress_field.png"
    assert png.parent.parent == tmp_path / "logs" / "progress_field"
    assert (png.parent / "progress_field.log").is_file()
    assert json.loads((png.parent / "progress_field.json").read_text())["n_trajectories"] == 2


def test_task_pickles_with_its_job_name():
    """The joblib and SLURM launchers pickle the task; Hydra reads the job name from it."""
    task = pickle.loads(pickle.dumps(_Task("collect")))
    assert (task.name, task.__module__) == ("collect", "collect")


def test_console_scripts_run_their_command(monkeypatch):
    """``cpmp-<name>`` of pyproject's [project.scripts] is ``cli.<name>_main``, which runs
    Hydra command ``name`` (and says so in its docstring)."""
    import tomllib

    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    ran: list[str] = []
    monkeypatch.setattr(cli, "run_command", ran.append)
    for name in sorted(COMMANDS):
        script = f"cpmp-{name.replace('_', '-')}"
        assert scripts[script] == f"cpmp.cli.main:{name}_main"
        main = getattr(cli, f"{name}_main")
        assert main.__name__ == f"{name}_main"
        assert main.__doc__ == f"``{script}``: {COMMANDS[name].summary}."
        main()
    assert ran == sorted(COMMANDS)


def test_conf_dir_is_the_repository_conf():
    assert CONF_DIR == ROOT / "conf"
    assert sorted(COMMANDS) == sorted(p.stem for p in CONF_DIR.glob("*.yaml"))


def test_inspect_rrd_reports_unreadable_files(tmp_path, monkeypatch, capfd):
    """``cpmp-inspect-rrd`` (installed, and ``inspect_rrd_entry`` in pyproject) exits with
    status 2 and one stderr line naming an unreadable file."""
    import tomllib

    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    assert scripts["cpmp-inspect-rrd"] == "cpmp.cli.main:inspect_rrd_entry"
    console_script("inspect_rrd")  # installed
    bad = tmp_path / "bad.rrd"
    bad.write_text("not an rrd")
    argv = ["cpmp-inspect-rrd", str(bad)]
    code, _, err = run_in_process(cli.inspect_rrd_entry, argv, tmp_path, monkeypatch, capfd)
    assert code == 2
    assert err.count("\n") == 1 and "bad.rrd" in err


# ---------------------------------------------------------- evaluate: MPs the model lacks
def renamed(demo: Demonstration, old: str, new: str) -> Demonstration:
    """``demo`` with MP ``old`` called ``new``."""
    labels = {v: np.where(lab == old, new, lab) for v, lab in demo.labels.items()}
    return Demonstration(
        time=demo.time,
        features=demo.features,
        labels=labels,
        feature_names=demo.feature_names,
        name=demo.name,
    )


def evaluate(tmp_path: Path, seq, demos: list[Demonstration]) -> dict:
    checkpoint = seq.save(tmp_path / "model.pt")
    data = tmp_path / "test.h5"
    save_demonstrations(data, demos, splits={"test": list(range(len(demos)))})  # held out
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        cfg = compose("evaluate", [f"checkpoint={checkpoint}", f"data.path={data}"])
    return json.loads(evaluate_checkpoint(cfg, tmp_path).read_text())


def test_evaluate_reports_mps_the_model_does_not_know(tmp_path, fitted_klr, test_demos, caplog):
    demos = list(test_demos)
    victim = next(i for i, d in enumerate(demos) if "b_wait" in set(d.labels["b"]))
    demos[victim] = renamed(demos[victim], "b_wait", "b_pause")
    n_renamed = sum(s.mp == "b_pause" for s in demos[victim].segments("b"))
    with caplog.at_level(logging.WARNING, logger="cpmp.experiment.checkpoint_jobs"):
        out = evaluate(tmp_path, fitted_klr, demos)
    assert out["unknown_mps"] == [
        {
            "variable": "b",
            "mp": "b_pause",
            "known_variable": True,
            "activations": n_renamed,
            "demos": [demos[victim].name],
        }
    ]
    total = sum(len(d.segments(v)) for d in demos for v in d.variables)
    assert out["progress"]["n_activations"] == total - n_renamed
    warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warnings) == 1 and f"b/b_pause ({n_renamed}x)" in warnings[0]
    markdown = (tmp_path / "evaluation.md").read_text()
    assert "MPs the model does not know" in markdown
    assert f"| b | b_pause | {n_renamed} | {demos[victim].name} |" in markdown


def test_evaluate_of_known_mps_reports_none(tmp_path, fitted_klr, test_demos, caplog):
    with caplog.at_level(logging.WARNING, logger="cpmp.experiment.checkpoint_jobs"):
        out = evaluate(tmp_path, fitted_klr, list(test_demos))
    assert out["unknown_mps"] == []
    assert not [r for r in caplog.records if r.levelno == logging.WARNING]
    assert "does not know" not in (tmp_path / "evaluation.md").read_text()


@pytest.mark.parametrize(
    ("argv", "ran"),
    [
        (["experiment=compare_tiny"], "compare"),
        (["experiment=tiny"], "experiment"),
    ],
)
def test_experiment_compare_is_an_alias_of_the_compare_command(argv, ran, monkeypatch, tmp_path):
    """``cpmp-experiment experiment=compare_tiny`` runs the comparison's job (the command line
    dispatches it; the main job itself knows no comparison), any other experiment the main
    job."""
    calls: list[str] = []
    monkeypatch.setattr(compare_job, "run_compare", lambda cfg, d: calls.append("compare"))
    monkeypatch.setattr(
        experiment_jobs, "run_experiment", lambda cfg, d: calls.append("experiment")
    )
    (job,) = check_command("experiment", argv)
    COMMANDS["experiment"].check(job.cfg)
    COMMANDS["experiment"].job(job.cfg, tmp_path)
    assert calls == [ran]
    (own,) = check_command("compare", argv)
    if ran == "compare":  # the alias composes the same job as the command itself
        assert own.cfg.compare == job.cfg.compare and own.cfg.experiment == job.cfg.experiment
