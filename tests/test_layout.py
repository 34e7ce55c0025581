"""The package's layout rules (issue 12): every module small, one job each, named once in the
README's map, and no module reaching into another's private names."""
from __future__ import annotations

import ast
import importlib
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


# ------------------------------------------------ solver statuses: one map per solver (issue 40)

#: modules allowed to read a solver's statuses raw: the independent reference routes (SCIP, and
#: linprog in other variables), which share nothing with the product's solvers but `decide`
RAW_STATUS_EXEMPT = {"reference.py"}
#: calls that return a solver's own status (CLP's code, SCIP's and HiGHS's model status)
STATUS_CALLS = {"getStatusCode", "getStatusString", "getStatus", "getModelStatus"}


def _solver_status_names() -> set[str]:
    """Every status name of the installed Clarabel and CLP, and "optimal" (SCIP's, HiGHS's)."""
    import clarabel
    from cylp.cy import CyClpSimplex
    clp = importlib.import_module(CyClpSimplex.__module__)
    return ({str(v) for v in vars(clarabel.SolverStatus).values() if isinstance(v, clarabel.SolverStatus)}
            | set(clp.problemStatus) | {"optimal"})


def _is_status_map(node: ast.AST) -> bool:
    """A module-level `NAME_STATUS = {...}`: a solver's status map."""
    return (isinstance(node, ast.Assign) and isinstance(node.value, ast.Dict)
            and all(isinstance(t, ast.Name) and t.id.endswith("_STATUS") for t in node.targets))


def _is_solver_status(node: ast.AST) -> bool:
    """x.status, str(x.status), or a call of STATUS_CALLS."""
    if isinstance(node, ast.Call):
        if isinstance(node.func, ast.Attribute) and node.func.attr in STATUS_CALLS:
            return True
        return (isinstance(node.func, ast.Name) and node.func.id == "str" and len(node.args) == 1
                and _is_solver_status(node.args[0]))
    return isinstance(node, ast.Attribute) and node.attr == "status"


def _is_literal(node: ast.AST) -> bool:
    if isinstance(node, (ast.Tuple, ast.List, ast.Set)):
        return all(_is_literal(e) for e in node.elts)
    return isinstance(node, ast.Constant) or (isinstance(node, ast.UnaryOp) and isinstance(node.operand, ast.Constant))


def _raw_statuses(source: str, names: set[str]) -> list[str]:
    """A solver's raw statuses in `source`, outside its status maps (_is_status_map): a
    string naming a solver status, or a solver's status compared with a literal."""
    tree = ast.parse(source)
    skip = {id(n) for top in tree.body if _is_status_map(top) for n in ast.walk(top)}
    found = []
    for node in ast.walk(tree):
        if id(node) in skip:
            continue
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and node.value in names:
            found.append(f"line {node.lineno}: {node.value!r}")
        elif isinstance(node, ast.Compare):
            sides = [node.left, *node.comparators]
            if any(map(_is_solver_status, sides)) and any(map(_is_literal, sides)):
                found.append(f"line {node.lineno}: {ast.unparse(node)}")
    return found


@pytest.mark.parametrize("path", [p for p in sorted(PACKAGE.rglob("*.py")) if p.name not in RAW_STATUS_EXEMPT],
                         ids=_name)
def test_no_raw_solver_status_outside_its_map(path):
    """Each solver's statuses are read once, by its map (conic.CLARABEL_STATUS,
    lp.HIGHS_STATUS, screens.CLP_STATUS) into rows.Status; everything else compares
    Status members."""
    assert _raw_statuses(path.read_text(), _solver_status_names()) == []


def test_raw_status_check_can_fail():
    names = _solver_status_names()
    bad = ('if sol.status == "Solved":\n    pass\n'
           'SETTLED = ("Solved", "PrimalInfeasible")\n'
           'ok = res.status in (0, -1)\n'
           'kind = {0: "optimal"}.get(s.getStatusCode(), "other")\n'
           'same = 1 != lp.getStatusCode()\n'
           'def f(sol):\n    return str(sol.status) not in ["Unsolved"]\n')
    assert sorted(f.split(":")[0] for f in _raw_statuses(bad, names)) == [
        "line 1", "line 1", "line 3", "line 3", "line 4", "line 5", "line 6", "line 8", "line 8"]
    good = ('X_STATUS = {"Solved": Status.FEASIBLE, 0: Status.FEASIBLE}\n'
            'ok = d.status == Status.FEASIBLE\nstatus = X_STATUS.get(res.status, Status.UNDECIDED)\n')
    assert _raw_statuses(good, names) == []


def test_readme_map_names_every_module_once():
    text = (ROOT / "README.md").read_text()
    section = text.split("## How it works", 1)[1].split("\n## ", 1)[0]
    named = re.findall(r"`([a-z_0-9/]+\.py|[a-z_0-9]+/)`", section)
    want = sorted(_name(p) for p in MODULES)
    missing = [m for m in want if named.count(m) != 1]
    unknown = [m for m in named if m not in want and not m.endswith("/")]
    assert not missing and not unknown, f"missing or repeated: {missing}; not a module: {unknown}"


# ---------------------------------------------------------------- the layers (issue 40)

#: the package's layers, bottom first: a module imports only from its own layer or below,
#: counting every import (inside functions and TYPE_CHECKING blocks too); within a layer,
#: no cycle. The parallel engine sits below everything that knows of wedging.
LAYERS = [
    ["version", "errors"],
    ["nodesets", "exact", "environment", "files", "progress", "dense", "forked"],
    ["parallel"],
    ["models"],
    ["scene"],
    ["contact"],
    ["results"],
    ["solvers"],
    ["rays", "reference"],
    ["patterns"],
    ["mu_c"],
    ["post"],
    ["run"],
    ["api"],
    ["cli", "__main__", ""],
]


def _module(path: pathlib.Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def import_graph() -> dict[str, set[str]]:
    """module -> the package modules it imports, every import statement counted."""
    names = {_module(p): p for p in PACKAGE.rglob("*.py")}
    graph = {}
    for name, path in names.items():
        package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
        out = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                out |= {a.name for a in node.names}
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    up = package.split(".")[: len(package.split(".")) - node.level + 1]
                    base = ".".join(up + ([node.module] if node.module else []))
                out |= {f"{base}.{a.name}" if f"{base}.{a.name}" in names else base for a in node.names}
        graph[name] = {m for m in out if m in names and m != name}
    return graph


def layer_of(module: str) -> int:
    top = module.split(".")[1] if "." in module else ""
    return next(i for i, layer in enumerate(LAYERS) if top in layer)


def back_edges(graph: dict[str, set[str]]) -> list[str]:
    return sorted(f"{a} -> {b}" for a, bs in graph.items() for b in bs if layer_of(b) > layer_of(a))


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in graph:
        if v not in index:
            visit(v)
    return out


def test_every_module_has_a_layer():
    assert all(layer_of(m) is not None for m in import_graph())


def test_imports_go_down_the_layers():
    assert back_edges(import_graph()) == []


def test_no_import_cycle():
    assert cycles(import_graph()) == []


def test_layer_checks_can_fail():
    """A solver importing the pipeline is a back edge; two modules importing each other a cycle."""
    graph = import_graph()
    graph["hpcwedge.solvers.lp"] = graph["hpcwedge.solvers.lp"] | {"hpcwedge.run.pipeline"}
    assert back_edges(graph) == ["hpcwedge.solvers.lp -> hpcwedge.run.pipeline"]
    assert any("hpcwedge.solvers.lp" in c for c in cycles(graph))


def test_the_parallel_engine_imports_nothing_of_the_domain():
    below = {"hpcwedge.version", "hpcwedge.errors", "hpcwedge.files", "hpcwedge.progress", "hpcwedge.dense",
             "hpcwedge"}
    for name, deps in import_graph().items():
        if name.startswith("hpcwedge.parallel"):
            assert {d for d in deps if not d.startswith("hpcwedge.parallel")} <= below, name


SOLVER_MODULES = ["hpcwedge.solvers.conic", "hpcwedge.solvers.socp", "hpcwedge.solvers.lp",
                  "hpcwedge.solvers.milp", "hpcwedge.solvers.screens", "hpcwedge.solvers.feasibility",
                  "hpcwedge.mu_c.critical", "hpcwedge.mu_c.dinkelbach", "hpcwedge.mu_c.kkt",
                  "hpcwedge.mu_c.global_search", "hpcwedge.patterns.tree", "hpcwedge.patterns.job",
                  "hpcwedge.rays.faces", "hpcwedge.rays.dd", "hpcwedge.rays.numerics", "hpcwedge.mu_c.bracket",
                  "hpcwedge.mu_c.exact_2d", "hpcwedge.reference", "hpcwedge.post.recovery", "hpcwedge.run.pipeline"]


@pytest.mark.parametrize("module", SOLVER_MODULES)
def test_a_solver_module_loads_no_hdf5_mpi_or_petsc(module):
    import subprocess
    import sys
    code = f"import sys, {module}; print(sorted(m for m in ('h5py', 'mpi4py', 'petsc4py') if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"


# ---------------------------------------------------------------- short functions (issue 40)

MAX_FUNCTION_LINES = 80


def long_functions(source: str, limit: int = MAX_FUNCTION_LINES) -> list[str]:
    """'name (n lines)' of every function or method of `source` longer than `limit` lines,
    from its def line to its last line (nested functions counted in their own right too)."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            n = node.end_lineno - node.lineno + 1
            if n > limit:
                found.append(f"{node.name} ({n} lines)")
    return found


def test_no_function_is_long():
    offenders = [f"{_name(p)}: {f}" for p in sorted(PACKAGE.rglob("*.py")) for f in long_functions(p.read_text())]
    assert offenders == [], f"functions over {MAX_FUNCTION_LINES} lines: {offenders}"


def test_long_function_check_can_fail():
    """A function and a method one line over the limit are named; one at the limit is not."""
    def body(indent: str) -> str:
        return "".join(f"{indent}x{i} = {i}\n" for i in range(MAX_FUNCTION_LINES - 1))
    source = (f"def short():\n{body('    ')}\n"                       # def + 79 lines: at the limit
              f"class C:\n    def long(self):\n{body(' ' * 8)}        pass\n\n"
              f"async def later():\n{body('    ')}    await x\n")
    assert sorted(long_functions(source)) == [f"later ({MAX_FUNCTION_LINES + 1} lines)",
                                              f"long ({MAX_FUNCTION_LINES + 1} lines)"]
