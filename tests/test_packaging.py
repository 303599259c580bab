"""cpmp as a package: the extras along the layers, the core without them, the wheel anywhere.

- pyproject.toml: the core dependencies, one extra per optional layer, ``all`` = every extra,
  and every third-party module cpmp imports is declared in one of them;
- the core (data, sequencer, predictors, evaluation, baselines, worlds) fits, steps, saves and
  loads in an interpreter where every package outside the core's dependencies is hidden, and an
  optional layer imported there says which extra to install;
- conf/ is the package ``cpmp._conf``: the checkout's folder in the editable install, a copy in
  the wheel, which runs ``cpmp-experiment`` and ``cpmp-train`` from a folder outside the
  checkout (slow: builds and installs the wheel, then runs the main job).
"""

from __future__ import annotations

import ast
import importlib
import importlib.metadata
import json
import os
import shutil
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

import pytest
import tomllib
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name

from cpmp.config.paths import CONF_PACKAGE, conf_dir

ROOT = Path(__file__).resolve().parents[1]
PROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
CORE = {"torch", "numpy", "h5py", "lightning", "scipy", "pyyaml", "typing-extensions"}
LAYER_EXTRAS = ["sim", "rerun", "import", "baselines", "jobs"]
OPTIONAL_LAYERS = {
    "cpmp.sim": "sim",
    "cpmp.recordings": "rerun",
    "cpmp.importers": "import",
    "cpmp.experiment": "jobs",
    "cpmp.cli": "jobs",
}
"""Each optional layer's package and the extra its import asks for when it is missing."""
MUST_BE_HIDDEN = {
    "mujoco",
    "pytorch_kinematics",
    "rerun",
    "rosbags",
    "pyarrow",
    "hydra",
    "omegaconf",
    "dtw",
    "sklearn",
    "matplotlib",
}


def names(requirements: list[str]) -> set[str]:
    return {canonicalize_name(Requirement(r).name) for r in requirements}


def test_the_core_and_one_extra_per_layer() -> None:
    extras = PROJECT["optional-dependencies"]
    assert PROJECT["dependencies"][0] == "torch==2.13.0"  # pinned first (scripts/install.sh)
    assert names(PROJECT["dependencies"]) == CORE
    assert sorted(extras) == sorted([*LAYER_EXTRAS, "all", "dev"])
    (everything,) = extras["all"]
    assert Requirement(everything).name == "cpmp"
    assert Requirement(everything).extras == set(LAYER_EXTRAS)
    declared = [names(extras[e]) for e in LAYER_EXTRAS]
    assert all(not (d & CORE) for d in declared), "a core dependency is repeated in an extra"
    assert sum(map(len, declared)) == len(set().union(*declared)), "a package in two extras"
    assert names(extras["sim"]) >= {"mujoco", "pytorch-kinematics"}
    assert names(extras["baselines"]) >= {"scikit-learn", "dtw-python"}
    assert names(extras["jobs"]) >= {"hydra-core", "matplotlib"}


def test_every_imported_package_is_declared() -> None:
    """A third-party module imported anywhere in cpmp/ comes from a declared distribution."""
    declared = set(CORE)
    for extra in LAYER_EXTRAS:
        declared |= names(PROJECT["optional-dependencies"][extra])
    distributions = importlib.metadata.packages_distributions()
    undeclared = {}
    for path in sorted((ROOT / "cpmp").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                modules = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                modules = [node.module]
            else:
                continue
            for module in modules:
                top = module.partition(".")[0]
                if top in sys.stdlib_module_names or top in {"cpmp", "__future__"}:
                    continue
                dists = {canonicalize_name(d) for d in distributions.get(top, [top])}
                if not dists & declared:
                    undeclared[f"{path.relative_to(ROOT)}: {module}"] = sorted(dists)
    assert not undeclared, f"declare these in pyproject.toml: {undeclared}"


CORE_RUN = r"""
import importlib.machinery, importlib.metadata, json, sys
from pathlib import Path

from packaging.requirements import Requirement
from packaging.utils import canonicalize_name

core_requirements, out, optional_layers = json.loads(sys.argv[1])
dists = {canonicalize_name(d.metadata["Name"]): d for d in importlib.metadata.distributions()}
core, todo = {"cpmp"}, [Requirement(r).name for r in core_requirements]
while todo:  # the core's dependencies and theirs: what `pip install cpmp` installs
    name = canonicalize_name(todo.pop())
    if name in core or name not in dists:
        continue
    core.add(name)
    for line in dists[name].requires or []:
        requirement = Requirement(line)
        if requirement.marker is None or requirement.marker.evaluate({"extra": ""}):
            todo.append(requirement.name)
hidden = {
    module
    for module, owners in importlib.metadata.packages_distributions().items()
    if not {canonicalize_name(d) for d in owners} & core
}


class HideTheExtras(importlib.machinery.PathFinder):
    # Every module and distribution outside the core is not installed, as far as this
    # interpreter can tell (import, importlib.util.find_spec and importlib.metadata).

    @classmethod
    def find_spec(cls, name, path=None, target=None):
        if name.partition(".")[0] in hidden:
            return None
        return super().find_spec(name, path, target)

    @classmethod
    def find_distributions(cls, *args, **kwargs):
        for dist in super().find_distributions(*args, **kwargs):
            if canonicalize_name(dist.metadata["Name"]) in core:
                yield dist


assert not [m for m in sys.modules if m.partition(".")[0] in hidden]
sys.meta_path[:] = [
    HideTheExtras if f is importlib.machinery.PathFinder else f for f in sys.meta_path
]

import numpy as np
import torch

torch.set_num_threads(1)
import cpmp
import cpmp.baselines
import cpmp.data
import cpmp.evaluation
import cpmp.graph
import cpmp.predictors
import cpmp.progress
import cpmp.sequencer
import cpmp.worlds
from cpmp.data import load_demonstrations, save_demonstrations
from cpmp.evaluation import load_sequencer
from cpmp.sequencer import ConcurrentSequencer
from cpmp.worlds.two_point import make_demonstrations

out = Path(out)
demos = make_demonstrations(4, seed=0)
save_demonstrations(out / "demos.h5", demos)
demos = load_demonstrations(out / "demos.h5")
seq = ConcurrentSequencer.fit(demos, seed=0)
active = seq.reset(0.0, demos[0].features[0])
for t, x in zip(demos[0].time[1:], demos[0].features[1:]):
    active = seq.step(t, x)
seq.save(out / "model.pt")
loaded = load_sequencer(out / "model.pt")
x = demos[1].features[::10]
same = bool(np.array_equal(seq.progress(x), loaded.progress(x)))
leaked = sorted(m for m in sys.modules if m.partition(".")[0] in hidden)

errors = {}
for layer in optional_layers:
    try:
        __import__(layer)
        errors[layer] = None
    except cpmp.MissingExtraError as err:
        errors[layer] = str(err)
try:
    ConcurrentSequencer.fit(demos, predictor="sklearn_klr", seed=0)
    errors["sklearn_klr"] = None
except cpmp.MissingExtraError as err:
    errors["sklearn_klr"] = str(err)
print(json.dumps({
    "hidden": sorted(hidden),
    "events": len(seq.events),
    "active": active,
    "same": same,
    "leaked": leaked,
    "errors": errors,
}))
"""


@pytest.mark.slow
def test_the_core_runs_without_the_extras(tmp_path: Path) -> None:
    """Fit, step, save and load with only the core's dependencies importable; an optional
    layer then names its extra."""
    args = json.dumps([PROJECT["dependencies"], str(tmp_path), list(OPTIONAL_LAYERS)])
    proc = subprocess.run(
        [sys.executable, "-c", CORE_RUN, args],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=300,
        env={k: v for k, v in os.environ.items() if k != "PYTHONPATH"},
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    result = json.loads(proc.stdout.strip().splitlines()[-1])
    assert MUST_BE_HIDDEN <= set(result["hidden"])  # the run hid what it claims to
    assert result["leaked"] == []
    assert result["events"] > 0 and result["same"]  # the fitted model switched; loads back
    assert (tmp_path / "model.pt").is_file()
    expected = {**OPTIONAL_LAYERS, "sklearn_klr": "baselines"}
    for what, extra in expected.items():
        message = result["errors"][what]
        assert message is not None, f"{what} imported without its extra"
        assert f"pip install 'cpmp[{extra}]'" in message, message


def test_conf_is_the_checkouts_folder_in_the_editable_install() -> None:
    """Edits to conf/ take effect: the package is the folder itself, not a copy."""
    assert conf_dir() == ROOT / "conf"
    assert Path(importlib.import_module(CONF_PACKAGE).__file__).parent == ROOT / "conf"


def _copy_checkout(target: Path) -> Path:
    """The checkout's files a build reads (pip builds in place: build/ and egg-info go here)."""
    shutil.copytree(
        ROOT,
        target,
        ignore=shutil.ignore_patterns(
            ".git",
            ".venv",
            "logs",
            "build",
            "dist",
            "outputs",
            "multirun",
            "*.egg-info",
            "__pycache__",
            ".pytest_cache",
            ".ruff_cache",
            "*.rrd",
            ".gl",
            ".whl",
        ),
    )
    return target


def _run(command: list[str], cwd: Path, env: dict[str, str]) -> str:
    proc = subprocess.run(command, cwd=cwd, env=env, capture_output=True, text=True, timeout=400)
    assert proc.returncode == 0, f"{' '.join(command)}:\n{proc.stdout[-2000:]}{proc.stderr[-3000:]}"
    return proc.stdout


@pytest.mark.slow
def test_the_wheel_runs_outside_the_checkout(tmp_path: Path) -> None:
    """Build the wheel, install it into a fresh venv that reuses this venv's packages (no
    download), then run cpmp-experiment experiment=tiny and cpmp-train on its demonstrations
    from a folder outside the checkout."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    source = _copy_checkout(tmp_path / "source")
    wheels = tmp_path / "wheels"
    pip = [sys.executable, "-m", "pip"]
    _run([*pip, "wheel", "-q", "--no-deps", "--no-build-isolation", "--no-index", "-w",
          str(wheels), str(source)], tmp_path, env)  # fmt: skip
    (wheel,) = wheels.glob("cpmp-*.whl")
    packaged = {
        name.removeprefix("cpmp/_conf/")
        for name in zipfile.ZipFile(wheel).namelist()
        if name.startswith("cpmp/_conf/")
    }
    conf = {p.relative_to(ROOT / "conf").as_posix() for p in (ROOT / "conf").rglob("*.yaml")}
    assert conf and conf <= packaged  # every config travels in the wheel

    venv = tmp_path / "venv"
    _run([sys.executable, "-m", "venv", "--without-pip", str(venv)], tmp_path, env)
    python = venv / "bin" / "python"
    site = _run([str(python), "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"],
                tmp_path, env).strip()  # fmt: skip
    # The dependencies: this venv's site-packages, after the new venv's own (where cpmp goes).
    Path(site, "cpmp_test_dependencies.pth").write_text(sysconfig.get_path("purelib") + "\n")
    _run([*pip, "--python", str(python), "install", "-q", "--no-deps", "--no-index", str(wheel)],
         tmp_path, env)  # fmt: skip

    outside = tmp_path / "elsewhere"
    outside.mkdir()
    where = _run(
        [str(python), "-c", "import cpmp.config.paths as p; print(p.conf_dir(), p.__file__)"],
        outside,
        env,
    ).split()
    assert all(path.startswith(site) for path in where), where  # the wheel's copy, conf included

    experiment = outside / "experiment"
    printed = _run(
        [str(venv / "bin" / "cpmp-experiment"), "experiment=tiny", f"hydra.run.dir={experiment}"],
        outside,
        env,
    )
    assert printed.strip().splitlines()[-1] == str(experiment / "report.json")
    report = json.loads((experiment / "report.json").read_text())
    assert report["reproduction"]

    train = outside / "train"
    printed = _run(
        [
            str(venv / "bin" / "cpmp-train"),
            f"data.path={experiment / 'seed_0' / 'demos.h5'}",
            f"hydra.run.dir={train}",
        ],
        outside,
        env,
    )
    assert printed.strip().splitlines()[-1] == str(train / "model.pt")
    assert (train / "model.pt").is_file()
