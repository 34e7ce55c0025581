"""The package's layout rules (issue 12): every module small, one job each, named once in the
README's map, and no module reaching into another's private names."""
from __future__ import annotations

import ast
import pathlib
import re

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "hpcwedge"
MAX_LINES = 500
MODULES = sorted(p for p in PACKAGE.rglob("*.py") if p.name not in ("__init__.py", "__main__.py"))


def _name(path: pathlib.Path) -> str:
    return path.relative_to(PACKAGE).as_posix()


@pytest.mark.parametrize("path", MODULES, ids=_name)
def test_module_is_small(path):
    n = len(path.read_text().splitlines())
    assert n <= MAX_LINES, f"{_name(path)}: {n} lines (at most {MAX_LINES})"


def _private_imports(path: pathlib.Path) -> list[str]:
    """`from .x import _y` and `x._y` of a package module x, in one module's source."""
    tree = ast.parse(path.read_text())
    modules = {p.stem for p in PACKAGE.rglob("*.py")} | {"hpcwedge"}
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and (node.level or (node.module or "").startswith("hpcwedge")):
            found += [f"from {node.module} import {a.name}" for a in node.names
                      if a.name.startswith("_") and not a.name.startswith("__")]
        elif (isinstance(node, ast.Attribute) and node.attr.startswith("_") and not node.attr.startswith("__")
              and isinstance(node.value, ast.Name) and node.value.id in modules):
            found.append(f"{node.value.id}.{node.attr}")
    return found


@pytest.mark.parametrize("path", MODULES, ids=_name)
def test_no_private_imports(path):
    assert _private_imports(path) == []


def test_private_import_check_can_fail(tmp_path):
    bad = PACKAGE / "run" / "pipeline.py"
    src = tmp_path / "m.py"
    src.write_text("from .dd import _secret\nfrom . import dd\nx = dd._other\n")
    assert _private_imports(src) == ["from dd import _secret", "dd._other"]
    assert bad.exists()


def test_readme_map_names_every_module_once():
    text = (ROOT / "README.md").read_text()
    section = text.split("## How it works", 1)[1].split("\n## ", 1)[0]
    named = re.findall(r"`([a-z_0-9/]+\.py|[a-z_0-9]+/)`", section)
    want = sorted(_name(p) for p in MODULES)
    missing = [m for m in want if named.count(m) != 1]
    unknown = [m for m in named if m not in want and not m.endswith("/")]
    assert not missing and not unknown, f"missing or repeated: {missing}; not a module: {unknown}"
