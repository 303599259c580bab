"""``cpmp-import`` (scripts/import.py): one command turns a recording into a
demonstration file and prints the summary and the file's path last; a bad configuration or a
failed import ends with exit status 2, one ``error:`` line and no output file.

The first command runs as a process of its own; the others (:func:`batched`) run one after
another in one fresh interpreter, each as ``python scripts/import.py ...`` runs it
(``tests/cli/conftest.py``)."""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pytest
import yaml
from omegaconf import OmegaConf

from cpmp.cli.checks import check_command_line, check_jobs
from cpmp.cli.import_job import IMPORT_COMMAND, import_job
from cpmp.data import list_splits, load_demonstrations, mp_sequences
from cpmp.errors import ConfigError, CpmpFileError, DataError

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "scripts" / "import.py"

MAPPING = {
    "source": "mimicgen",
    "rate": 20.0,
    "features": [{"key": "obs/eef_pos", "names": ["x", "z"]}],
    "labels": {"arm": {"subtasks": [{"mp": "reach", "signal": "reached"}, {"mp": "lift"}]}},
}


def write_recording(path: Path, n_demos: int = 4) -> Path:
    """A MimicGen-style file: the arm reaches along x, then lifts along z; ``reached`` turns
    1 when the reach is done."""
    with h5py.File(path, "w") as f:
        for k in range(n_demos):
            t_reach = 0.8 + 0.1 * k
            t = np.arange(0.0, t_reach + 1.0, 0.05)
            x = np.clip(t / t_reach, 0, 1)
            z = np.clip((t - t_reach) / 1.0, 0, 1)
            g = f.create_group(f"data/demo_{k}")
            g.create_dataset("obs/eef_pos", data=np.column_stack([x, z]))
            g.create_dataset("datagen_info/subtask_term_signals/reached", data=(t >= t_reach) * 1)
    return path


@pytest.fixture
def inputs(tmp_path):
    mapping = tmp_path / "mapping.yaml"
    mapping.write_text(yaml.safe_dump(MAPPING))
    return mapping, write_recording(tmp_path / "recording.hdf5")


def run(args: list[str], cwd: Path) -> subprocess.CompletedProcess:
    argv = [sys.executable, str(SCRIPT), *args, f"hydra.run.dir={cwd / 'run'}"]
    return subprocess.run(argv, cwd=cwd, capture_output=True, text=True, timeout=300)


def drop_signals(recording: Path, demos: range) -> None:
    """Delete the ``reached`` termination signal of ``demo_<k>`` for every ``k`` of ``demos``."""
    with h5py.File(recording, "a") as f:
        for k in demos:
            del f[f"data/demo_{k}/datagen_info/subtask_term_signals/reached"]


@pytest.fixture(scope="module")
def batched(tmp_path_factory, run_scripts: Callable[..., list[Any]]) -> dict[str, tuple[Path, Any]]:
    """The failing and skipping imports, each in a directory of its own with its own mapping
    and recording, run as :func:`run` runs them (``hydra.run.dir`` = ``<dir>/run``) in one
    fresh interpreter: ``{name: (directory, what the command left)}``."""
    root = tmp_path_factory.mktemp("import_runs")
    cases: dict[str, tuple[range, list[str]]] = {
        "failed": (range(2, 3), ["output=demos.hdf5"]),
        "skip": (range(2, 3), ["output={dir}/demos.hdf5", "on_error=skip"]),
        "all_bad": (range(4), ["output=demos.hdf5", "on_error=skip"]),
    }
    runs, dirs = [], {}
    for name, (bad, args) in cases.items():
        cwd = root / name
        cwd.mkdir()
        mapping = cwd / "mapping.yaml"
        mapping.write_text(yaml.safe_dump(MAPPING))
        recording = write_recording(cwd / "recording.hdf5")
        drop_signals(recording, bad)
        argv = [f"mapping={mapping}", f"input={recording}"]
        argv += [a.replace("{dir}", str(cwd)) for a in args] + [f"hydra.run.dir={cwd / 'run'}"]
        runs.append((SCRIPT, argv, cwd))
        dirs[name] = cwd
    return dict(zip(cases, zip(dirs.values(), run_scripts(runs, root), strict=True), strict=True))


@pytest.mark.slow
def test_one_command_imports_prints_the_summary_and_the_path_last(inputs, tmp_path):
    mapping, recording = inputs
    out = tmp_path / "demos.hdf5"
    proc = run(
        [f"mapping={mapping}", f"input={recording}", f"output={out}", "test=[demo_1]"], tmp_path
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    lines = proc.stdout.strip().splitlines()
    assert lines[-1] == str(out)
    assert "demo_1 [test]" in proc.stdout and "reach -> lift" in proc.stdout
    assert "sequence graphs" in proc.stdout and "* reach [4 activations] -> lift" in proc.stdout
    assert list_splits(out) == {"train": ["demo_0", "demo_2", "demo_3"], "test": ["demo_1"]}
    demos = load_demonstrations(out)
    assert [mp_sequences(d) for d in demos] == [{"arm": ["reach", "lift"]}] * 4
    assert (tmp_path / "run" / "summary.txt").read_text().startswith("imported 4 demonstration(s)")


def test_a_failed_import_is_one_error_line_and_no_file(batched):
    """demo_2 lacks its signal: exit status 2, one error line naming it, no file (nor temp)."""
    tmp_path, proc = batched["failed"]
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    errors = [line for line in proc.stderr.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and "demo_2: no termination signal reached" in errors[0]
    assert not (tmp_path / "run" / "demos.hdf5").exists()
    assert not list((tmp_path / "run").glob("*.hdf5*"))  # no temporary left either


def _check(argv: list[str]) -> None:
    check_jobs(IMPORT_COMMAND, check_command_line(IMPORT_COMMAND, argv))


def test_the_command_line_is_checked_before_the_import(inputs, tmp_path):
    mapping, recording = inputs
    with pytest.raises(ConfigError, match="mapping is required: add mapping=<path>"):
        _check([f"input={recording}"])
    with pytest.raises(CpmpFileError, match=r"input=.*nope.hdf5: no such file or directory"):
        _check([f"mapping={mapping}", f"input={tmp_path / 'nope.hdf5'}"])
    with pytest.raises(ConfigError, match=r"test_fraction=.*expected a number"):
        _check([f"mapping={mapping}", f"input={recording}", "test_fraction=half"])
    with pytest.raises(ConfigError, match="test_fraction must be < 1"):
        _check([f"mapping={mapping}", f"input={recording}", "test_fraction=1.0"])
    bad = tmp_path / "bad.yaml"
    bad.write_text(yaml.safe_dump({**MAPPING, "rates": 20}))
    with pytest.raises(ConfigError, match=r"unknown key.* rates"):
        _check([f"mapping={bad}", f"input={recording}"])
    _check([f"mapping={mapping}", f"input={recording}", "test_fraction=0.25", "seed=3"])


def test_the_job_writes_relative_outputs_into_the_run_directory(inputs, tmp_path, capsys):
    mapping, recording = inputs
    cfg = OmegaConf.create(
        {
            "mapping": str(mapping),
            "input": str(recording),
            "output": "out.hdf5",
            "test_fraction": 0.5,
            "seed": 1,
            "test": [],
        }
    )
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    path = import_job(cfg, run_dir)
    assert path == run_dir / "out.hdf5" and len(list_splits(path)["test"]) == 2
    assert "splits: train: 2, test: 2" in capsys.readouterr().out
    cfg.input = str(tmp_path / "mapping.yaml")  # not HDF5
    with pytest.raises(CpmpFileError, match=r"cannot open .* as HDF5"):
        import_job(cfg, tmp_path)
    cfg.input = str(recording)
    cfg.mapping = str(tmp_path / "wrong.yaml")
    (tmp_path / "wrong.yaml").write_text(
        yaml.safe_dump({**MAPPING, "features": [{"key": "obs/eef_pos", "index": [5]}]})
    )
    with pytest.raises(DataError, match=r"obs/eef_pos has 2 element\(s\)"):
        import_job(cfg, tmp_path)
    assert not (tmp_path / "out.hdf5").exists()


def test_on_error_skip_imports_the_rest_reports_and_exits_3(batched):
    """demo_2 lacks its signal, ``on_error=skip``: the other three are written, the skipped one
    is reported (stdout and a JSON file), exit status 3."""
    tmp_path, proc = batched["skip"]
    out = tmp_path / "demos.hdf5"
    assert proc.returncode == 3, proc.stderr[-3000:]
    assert "error:" not in proc.stderr
    lines = proc.stdout.strip().splitlines()
    assert lines[-1] == str(out) and lines[0].startswith("imported 3 demonstration(s), skipped 1")
    assert "skipped 1 demonstration(s) (on_error: skip):" in proc.stdout
    assert "demo_2: no termination signal reached" in proc.stdout
    assert list_splits(out) == {"train": ["demo_0", "demo_1", "demo_3"]}
    report = json.loads((tmp_path / "demos.hdf5.skipped.json").read_text())
    assert [s["demo"] for s in report["skipped"]] == ["demo_2"]
    assert f"skipped demonstrations: {out}.skipped.json" in proc.stdout


def test_on_error_skip_with_every_demo_bad_is_one_error_line_and_no_file(batched):
    """Every demo lacks its signal, ``on_error=skip``: exit status 2, one error line, no file."""
    tmp_path, proc = batched["all_bad"]
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    errors = [line for line in proc.stderr.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and "every demonstration failed to import (4 skipped" in errors[0]
    assert not list((tmp_path / "run").glob("demos.hdf5*"))


def test_on_error_is_checked_with_the_command_line(inputs):
    mapping, recording = inputs
    with pytest.raises(ConfigError, match=r"on_error='later': give on_error=raise"):
        _check([f"mapping={mapping}", f"input={recording}", "on_error=later"])
    _check([f"mapping={mapping}", f"input={recording}", "on_error=skip"])
