"""The core library stays importable without the simulator, Hydra or rerun (docs/design.md)."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "cpmp"
CORE = sorted(
    [
        *PACKAGE.glob("*.py"),
        *(PACKAGE / "predictors").glob("*.py"),
        *(PACKAGE / "config").glob("*.py"),
    ]
)
FORBIDDEN = ("cpmp.sim", "cpmp.experiment", "hydra", "omegaconf", "mujoco", "rerun")


def imported_modules(path: Path) -> set[str]:
    """Every module an ``import`` / ``from ... import`` statement in ``path`` names."""
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            out.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            out.add(node.module)
            out.update(f"{node.module}.{alias.name}" for alias in node.names)
    return out


def test_core_modules_found() -> None:
    names = {p.name for p in CORE}
    assert {"sequencer.py", "graph.py", "progress.py", "klr.py", "predictors.py"} <= names


@pytest.mark.parametrize("path", CORE, ids=lambda p: str(p.relative_to(PACKAGE)))
def test_core_module_imports_no_upper_layer(path: Path) -> None:
    bad = sorted(
        m for m in imported_modules(path) if any(m == f or m.startswith(f + ".") for f in FORBIDDEN)
    )
    assert not bad, f"{path.relative_to(PACKAGE)} imports {bad}; the core must not"


def test_checker_sees_a_forbidden_import(tmp_path: Path) -> None:
    module = tmp_path / "m.py"
    module.write_text("def f():\n    from cpmp.sim.scene import Box\n    import hydra\n")
    assert {"cpmp.sim.scene", "hydra"} <= imported_modules(module)
