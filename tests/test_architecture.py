"""House rules for the package's structure: the import-linter contracts of pyproject.toml
(layers, forbidden imports), no import cycles between modules, and what importing the
numerical core loads.

Every check runs in a subprocess with the tree under test as working directory and first on
PYTHONPATH, so that it analyses that checkout (this one, or a copy in a temporary directory
for the negative controls) and never the editable install.  grimp (import-linter's graph
library) reads the source; it counts function-local imports and ignores those under
``if TYPE_CHECKING:``.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

# What the numerical core must not load when imported (issue "One house for three modes").
EDGE_LIBRARIES = ("pydantic", "h5py", "tomllib", "click", "matplotlib", "rich")

_LINT = "import sys; from importlinter.cli import lint_imports_command; sys.exit(lint_imports_command())"

_GRAPH = """
import json, sys, grimp, fracas
g = grimp.build_graph("fracas", exclude_type_checking_imports=True, cache_dir=None)
edges = {}
for m in sorted(g.modules):
    for t in sorted(g.find_modules_directly_imported_by(m)):
        lines = sorted({d["line_number"] for d in g.get_import_details(importer=m, imported=t)})
        edges.setdefault(m, []).append([t, lines])
json.dump({"file": fracas.__file__, "modules": sorted(g.modules), "edges": edges}, sys.stdout)
"""


def _run(tree: Path, *args: str) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(tree))
    return subprocess.run([sys.executable, *args], cwd=tree, env=env, capture_output=True, text=True, timeout=300)


def _analysed_file(tree: Path) -> Path:
    proc = _run(tree, "-c", "import fracas; print(fracas.__file__)")
    assert proc.returncode == 0, proc.stderr
    return Path(proc.stdout.strip()).resolve()


def lint_imports(tree: Path) -> subprocess.CompletedProcess:
    """`lint-imports` over ``tree`` with the contracts of ``tree/pyproject.toml``."""
    assert _analysed_file(tree) == (tree / "fracas" / "__init__.py").resolve(), "wrong fracas analysed"
    return _run(tree, "-c", _LINT, "--no-cache", "--no-logo", str(tree / "pyproject.toml"))


def import_graph(tree: Path) -> dict:
    proc = _run(tree, "-c", _GRAPH)
    assert proc.returncode == 0, proc.stderr
    graph = json.loads(proc.stdout)
    assert Path(graph["file"]).resolve() == (tree / "fracas" / "__init__.py").resolve()
    return graph


def strongly_connected_components(nodes, successors) -> list[list[str]]:
    """Tarjan's algorithm; components in reverse topological order, each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in successors(v):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            out.append(sorted(comp))

    for v in sorted(nodes):
        if v not in index:
            visit(v)
    return out


def import_cycles(graph: dict) -> list[str]:
    """One description per strongly connected component of more than one module (or a module
    importing itself): its modules and the imports inside it, with line numbers."""
    edges = {m: dict(targets) for m, targets in graph["edges"].items()}
    found = []
    for comp in strongly_connected_components(graph["modules"], lambda m: sorted(edges.get(m, {}))):
        members = set(comp)
        if len(comp) == 1 and comp[0] not in edges.get(comp[0], {}):
            continue
        inner = [
            f"    {m} -> {t} (l.{', '.join(map(str, edges[m][t]))})"
            for m in comp
            for t in sorted(edges.get(m, {}))
            if t in members
        ]
        found.append(f"cycle of {len(comp)} modules: {', '.join(comp)}\n" + "\n".join(inner))
    return found


def copy_tree(tmp_path: Path) -> Path:
    tree = tmp_path / "tree"
    shutil.copytree(ROOT / "fracas", tree / "fracas", ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copy(ROOT / "pyproject.toml", tree / "pyproject.toml")
    return tree


def append(path: Path, text: str) -> None:
    path.write_text(path.read_text() + "\n" + text + "\n")


# ---------------------------------------------------------------- (a) the contracts


def test_import_contracts_are_kept():
    proc = lint_imports(ROOT)
    assert proc.returncode == 0, "import-linter contracts broken:\n" + proc.stdout + proc.stderr


# ---------------------------------------------------------------- (b) no import cycles


def test_no_import_cycles():
    cycles = import_cycles(import_graph(ROOT))
    assert not cycles, "import cycles in fracas (function-local imports count):\n" + "\n".join(cycles)


def test_scc_search():
    succ = {"a": ["b"], "b": ["c"], "c": ["a", "d"], "d": [], "e": ["e"]}
    comps = strongly_connected_components(succ, lambda v: succ[v])
    assert sorted(comps) == [["a", "b", "c"], ["d"], ["e"]]


# ---------------------------------------------------------------- (c) negative controls


def test_contracts_catch_forbidden_imports(tmp_path):
    """The contracts fail on a copy with forbidden imports injected, and name the modules."""
    tree = copy_tree(tmp_path)
    append(tree / "fracas" / "filters" / "covariance.py", "import h5py  # injected")
    append(tree / "fracas" / "dynamics" / "kepler.py", "from fracas.config import team  # injected")
    # a module that does not exist today is covered as soon as it appears
    (tree / "fracas" / "tom.py").write_text("import matplotlib  # injected\n")
    # an unplaced new top-level module breaks the exhaustive layers contract
    (tree / "fracas" / "newthing.py").write_text("X = 1\n")
    proc = lint_imports(tree)
    out = proc.stdout + proc.stderr
    assert proc.returncode != 0, out
    for expected in (
        "fracas.filters.covariance -> h5py",
        "fracas.dynamics.kepler -> fracas.config",
        "fracas.dynamics is not allowed to import fracas.config",
        "fracas.filters is not allowed to import h5py",
        "fracas.tom is not allowed to import matplotlib",
        "fracas.newthing",
    ):
        assert expected in out, f"{expected!r} not in the report:\n{out}"


def test_cycle_check_catches_a_cycle(tmp_path):
    tree = copy_tree(tmp_path)
    append(tree / "fracas" / "constants.py", "def _f():\n    from fracas import timescales  # injected")
    cycles = import_cycles(import_graph(tree))
    assert any("fracas.constants, fracas.timescales" in c for c in cycles), cycles
    assert any("fracas.constants -> fracas.timescales" in c for c in cycles), cycles


# ---------------------------------------------------------------- (d) what the core loads


_LOADED = "import importlib, json, sys; importlib.import_module(sys.argv[1]); print(json.dumps(sorted(sys.modules)))"


@pytest.mark.parametrize(
    "module, must_not_load",
    [
        ("fracas.team.engine", EDGE_LIBRARIES),
        ("fracas.config", ("jax",)),
        ("fracas.config.team", ("jax",)),
    ],
)
def test_import_does_not_load(module, must_not_load):
    proc = _run(ROOT, "-c", _LOADED, module)
    assert proc.returncode == 0, proc.stderr
    loaded = set(json.loads(proc.stdout))
    fracas_loaded = sorted(m for m in loaded if m.startswith("fracas"))
    bad = [m for m in must_not_load if m in loaded]
    assert not bad, f"import {module} loads {bad}; fracas modules loaded: {fracas_loaded}"
