"""The architecture holds: imports point down the layer table of docs/design.md, no import cycle,
no folder over 15 modules, no file-name prefix family standing in for a package."""

from __future__ import annotations

import ast
import re
from collections import defaultdict
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "cpmp"
DESIGN = ROOT / "docs" / "design.md"
CORE_TOP_LAYER = 8
"""Layers 0-8 are the core (docs/design.md): no simulator, experiment, Hydra, MuJoCo or rerun."""
FORBIDDEN_IN_CORE = ("hydra", "omegaconf", "mujoco", "rerun", "pytorch_kinematics")
MAX_MODULES = 15


def module_name(path: Path, root: Path = ROOT) -> str:
    """``cpmp/sequencer/batch.py`` -> ``cpmp.sequencer.batch`` (``__init__`` -> the package)."""
    return ".".join(path.relative_to(root).with_suffix("").parts).removesuffix(".__init__")


def all_modules(package: Path = PACKAGE) -> dict[str, Path]:
    """Every module of the package by dotted name."""
    return {module_name(p, package.parent): p for p in sorted(package.rglob("*.py"))}


def imports_of(path: Path) -> set[str]:
    """Every absolute module an ``import`` / ``from ... import`` anywhere in ``path`` names
    (inside functions and ``TYPE_CHECKING`` blocks too), with ``from a import b`` giving
    both ``a`` and ``a.b``."""
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            out.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            out.add(node.module)
            out.update(f"{node.module}.{alias.name}" for alias in node.names)
    return out


def resolve(name: str, modules: dict[str, Path]) -> str | None:
    """The module of ``modules`` that an imported dotted ``name`` refers to (longest prefix)."""
    while name and name not in modules:
        name = name.rpartition(".")[0]
    return name or None


def import_graph(modules: dict[str, Path]) -> dict[str, set[str]]:
    """Module -> the cpmp modules it imports (a package importing its own submodules and a
    module importing its parent package's face are edges too)."""
    graph: dict[str, set[str]] = defaultdict(set)
    for name, path in modules.items():
        for imported in imports_of(path):
            target = resolve(imported, modules) if imported.startswith("cpmp") else None
            if target and target != name:
                graph[name].add(target)
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def layer_table(text: str) -> dict[str, int]:
    """Package -> layer, from the rows ``| N | `pkg`, `pkg` | ...`` of the design page."""
    layers: dict[str, int] = {}
    for match in re.finditer(r"^\| (\d+) \| ([^|]+) \|", text, re.M):
        for package in re.findall(r"`(cpmp[\w.]*)`", match.group(2)):
            layers[package] = int(match.group(1))
    return layers


def owner(module: str, layers: dict[str, int]) -> str:
    """The package of the layer table that ``module`` belongs to (longest prefix)."""
    best = "cpmp"
    for package in layers:
        if (module == package or module.startswith(package + ".")) and len(package) > len(best):
            best = package
    return best


MODULES = all_modules()
GRAPH = import_graph(MODULES)
LAYERS = layer_table(DESIGN.read_text(encoding="utf-8"))


def test_every_package_has_a_layer() -> None:
    top_level = {module_name(p) for p in PACKAGE.iterdir() if p.suffix == ".py" or p.is_dir()}
    top_level = {m for m in top_level if not m.endswith("__pycache__")}
    missing = sorted(m for m in top_level if m not in LAYERS and m != "cpmp")
    assert not missing, f"add {missing} to the layer table of docs/design.md"


def test_imports_point_down_the_layers() -> None:
    wrong = []
    for module, targets in GRAPH.items():
        mine = owner(module, LAYERS)
        for target in targets:
            theirs = owner(target, LAYERS)
            if theirs != mine and LAYERS[theirs] >= LAYERS[mine]:
                wrong.append(
                    f"{module} (layer {LAYERS[mine]}) imports {target} (layer {LAYERS[theirs]})"
                )
    assert not wrong, "\n".join(sorted(wrong))


def test_no_import_cycle() -> None:
    found = cycles(GRAPH)
    assert not found, "import cycles: " + "; ".join(" <-> ".join(c) for c in found)


@pytest.mark.parametrize(
    "name",
    sorted(
        m
        for m in MODULES
        if owner(m, LAYERS) in LAYERS and LAYERS[owner(m, LAYERS)] <= CORE_TOP_LAYER
    ),
)
def test_core_imports_no_simulator_hydra_or_rerun(name: str) -> None:
    bad = sorted(m for m in imports_of(MODULES[name]) if m.split(".")[0] in FORBIDDEN_IN_CORE)
    assert not bad, f"{name} is core (docs/design.md) but imports {bad}"


def test_no_folder_over_fifteen_modules_and_no_prefix_family() -> None:
    for folder in [PACKAGE, *(p for p in PACKAGE.rglob("*") if p.is_dir())]:
        if folder.name == "__pycache__":
            continue
        files = [p.stem for p in folder.glob("*.py") if p.stem != "__init__"]
        assert len(files) <= MAX_MODULES, f"{folder} has {len(files)} modules"
        prefixes = defaultdict(list)
        for stem in files:
            if "_" in stem:
                prefixes[stem.split("_")[0]].append(stem)
        family = {p: s for p, s in prefixes.items() if len(s) + (p in files) >= 3}
        assert not family, f"{folder}: a prefix family is a package asking to be made: {family}"


def test_the_checks_see_what_they_claim(tmp_path: Path) -> None:
    """The checkers find a cycle through a function-level import, a TYPE_CHECKING import and
    a layer violation, in a made-up package."""
    pkg = tmp_path / "cpmp"
    (pkg / "low").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "low" / "__init__.py").write_text("")
    (pkg / "low" / "a.py").write_text("def f():\n    from cpmp.high import b\n")
    (pkg / "high.py").write_text(
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from cpmp.low.a import f\n"
    )
    modules = all_modules(pkg)
    graph = import_graph(modules)
    assert cycles(graph) == [["cpmp.high", "cpmp.low.a"]]
    layers = layer_table("| 0 | `cpmp.low` | x | y |\n| 1 | `cpmp.high` | x | y |\n")
    assert layers == {"cpmp.low": 0, "cpmp.high": 1}
    assert owner("cpmp.low.a", layers) == "cpmp.low"
    assert LAYERS[owner("cpmp.sequencer.batch", LAYERS)] < LAYERS[owner("cpmp.cli.main", LAYERS)]
