"""docs/importing.md runs as written: its Python blocks write the example recordings and fit
on an import, its commands import each source, its printed summary is what the command
prints, and its mappings are the files in conf/import/.

The doc's three commands run one after another in one fresh interpreter (:func:`doc_runs`),
each as ``python scripts/import.py ...`` runs it, by the batch runner of
``tests/cli/conftest.py``."""

from __future__ import annotations

import os
import re
import runpy
from pathlib import Path
from typing import Any

import pytest

from cpmp.data import list_splits, load_demonstrations, mp_sequences
from cpmp.importers import load_mapping

ROOT = Path(__file__).resolve().parents[2]
DOC = ROOT / "docs" / "importing.md"
TEXT = DOC.read_text(encoding="utf-8")
EXAMPLES = "/tmp/cpmp_examples"


def blocks(language: str) -> list[str]:
    return re.findall(rf"^```{language}\n(.*?)^```", TEXT, re.S | re.M)


def commands() -> list[str]:
    """The doc's ``scripts/import.py`` commands on the example recordings (continued
    lines joined)."""
    lines = []
    for block in blocks("bash"):
        for command in block.replace("\\\n", " ").splitlines():
            if "import.py" in command and EXAMPLES in command:
                lines.append(" ".join(command.split()))
    return lines


@pytest.fixture(scope="module")
def examples(tmp_path_factory):
    """Run the doc's Python blocks (writing to a temporary folder) from the repository root;
    returns the folder and the blocks' namespace."""
    folder = tmp_path_factory.mktemp("docs") / "cpmp_examples"
    namespace: dict = {"__name__": "__doc_example__"}
    cwd = Path.cwd()
    try:
        os.chdir(ROOT)
        for i, block in enumerate(blocks("python")):
            code = block.replace(EXAMPLES, str(folder))
            exec(compile(code, f"docs/importing.md python block {i + 1}", "exec"), namespace)
    finally:
        os.chdir(cwd)
    return folder, namespace


def test_the_python_blocks_write_recordings_and_fit_on_an_import(examples):
    folder, ns = examples
    assert sorted(p.name for p in (folder / "bags").iterdir()) == [f"run_{k}" for k in range(4)]
    assert (folder / "lerobot" / "meta" / "info.json").is_file()
    result = ns["result"]
    assert result.path == folder / "from_python.hdf5" and len(result.splits["test"]) == 1
    assert ns["replay"]["sequence_match"] == {"left_arm": 1.0, "right_arm": 1.0}


@pytest.fixture(scope="module")
def doc_runs(examples, tmp_path_factory) -> list[Any]:
    """The doc's import commands on the example recordings, each from the repository root with
    a run directory of its own, run in one fresh interpreter as ``python <script> ...`` runs
    them: what each left (exit status, stdout, stderr)."""
    folder, _ = examples
    root = tmp_path_factory.mktemp("doc_runs")
    runs = []
    for index, command in enumerate(commands()):
        argv = command.replace(EXAMPLES, str(folder)).split()
        assert argv[0] == ".venv/bin/python" and argv[1] == "scripts/import.py", argv
        runs.append((argv[1], [*argv[2:], f"hydra.run.dir={root / str(index) / 'run'}"], ROOT))
    run_scripts = runpy.run_path(str(ROOT / "tests" / "cli" / "conftest.py"))["_run_scripts"]
    return run_scripts(runs, root)


@pytest.mark.parametrize("index", range(3))
def test_each_import_command_runs(examples, doc_runs, index):
    """The doc's command ``index`` exits with status 0, prints the demonstration file's path
    last, and the file holds the four demonstrations with their MP sequences (the first
    command: prints the summary shown in the doc and holds out demo_run_2)."""
    folder, _ = examples
    proc = doc_runs[index]
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = Path(proc.stdout.strip().splitlines()[-1])
    assert out.parent == folder and out.is_file()
    expected = {"left_arm": ["hold", "push"], "right_arm": ["reach", "grasp", "lift"]}
    assert [mp_sequences(d) for d in load_demonstrations(out)] == [expected] * 4
    if index == 0:  # the printed summary shown in the doc, line by line
        (shown,) = [
            b for b in blocks("text") if b.startswith("imported 4 demonstration(s) from rosbag")
        ]
        for line in shown.replace(EXAMPLES, str(folder)).splitlines():
            if line and line != "...":
                assert line in proc.stdout.splitlines(), line
        assert list_splits(out)["test"] == ["demo_run_2"]


def test_there_is_one_command_per_source():
    sources = [re.search(r"mapping=conf/import/(\w+)_example.yaml", c).group(1) for c in commands()]
    assert sources == ["rosbag", "lerobot", "mimicgen"]


@pytest.mark.parametrize("source", ["rosbag", "lerobot", "mimicgen"])
def test_the_doc_shows_the_example_mapping_files(source):
    path = ROOT / "conf" / "import" / f"{source}_example.yaml"
    body = "\n".join(line for line in path.read_text().splitlines() if not line.startswith("#"))
    assert body.strip() + "\n" in blocks("yaml")
    assert type(load_mapping(path)).__name__.lower().startswith(source[:3])
