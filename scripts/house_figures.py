"""The house's figures (issue 26): how the package reads, counted from its source.

    python scripts/house_figures.py [PACKAGE_DIR]      # default: fracas/

Prints one table:
- modules over 500 lines, and the largest;
- functions over 80 lines, and the longest (its body, decorators and docstring included);
- mode dispatchers: functions that branch on two or more mode names (``mode == "tom"``,
  ``mode in ("team", ...)``) or results-file kinds, or test a deck against two or more mode
  deck classes;
- the annotated share: functions whose every parameter (but ``self``/``cls``) and return
  carry an annotation, over all functions;
- duplicated blocks: the pair count the workplace ``duplicates`` tool reports for the
  package (six or more shared lines), when that tool is on PATH.
"""

from __future__ import annotations

import ast
import re
import shutil
import subprocess
import sys
from pathlib import Path

MODE_NAMES = {"propagate", "team", "sweep", "tom", "tsim", "rendezvous"}
#: results-file kinds, one a mode (``fracas report`` dispatching on them is a mode dispatcher too)
RESULT_KINDS = {
    "fracas-trajectory",
    "fracas-team-results",
    "fracas sweep table",
    "fracas-tom-results",
    "fracas-tsim-results",
    "fracas-rendezvous-results",
}
DECK_CLASSES = {"TrajectoryDeck", "TeamDeck", "SweepDeck", "TomDeck", "TsimDeck", "RendezvousDeck"}


def _functions(tree: ast.AST):
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            yield node


def _annotated(fn: ast.FunctionDef | ast.AsyncFunctionDef) -> bool:
    args = [*fn.args.posonlyargs, *fn.args.args, *fn.args.kwonlyargs]
    args += [a for a in (fn.args.vararg, fn.args.kwarg) if a is not None]
    params = [a for a in args if a.arg not in ("self", "cls")]
    return fn.returns is not None and all(a.annotation is not None for a in params)


def _mode_names(node: ast.AST) -> set[str]:
    """Mode names a comparison tests against (``x == "tom"``, ``x in ("team", "sweep")``)."""
    names: set[str] = set()
    for sub in ast.walk(node):
        if isinstance(sub, ast.Compare):
            for comp in sub.comparators:
                for c in ast.walk(comp):
                    if isinstance(c, ast.Constant) and (c.value in MODE_NAMES or c.value in RESULT_KINDS):
                        names.add(c.value)
    return names


def _deck_classes(node: ast.AST) -> set[str]:
    names: set[str] = set()
    for sub in ast.walk(node):
        if isinstance(sub, ast.Call) and getattr(sub.func, "id", None) == "isinstance" and len(sub.args) == 2:
            for c in ast.walk(sub.args[1]):
                if isinstance(c, ast.Name) and c.id in DECK_CLASSES:
                    names.add(c.id)
    return names


def _is_dispatcher(fn: ast.AST) -> bool:
    tests = [n.test for n in ast.walk(fn) if isinstance(n, (ast.If, ast.IfExp))]
    modes = set().union(*(_mode_names(t) for t in tests)) if tests else set()
    classes = set().union(*(_deck_classes(t) for t in tests)) if tests else set()
    return len(modes) >= 2 or len(classes) >= 2


def _innermost(fns: list) -> list:
    """Dispatchers not counted twice: a nested function's branches also sit in its parent."""
    inner = []
    for f in fns:
        if not any(g is not f and g.lineno <= f.lineno and f.end_lineno <= g.end_lineno for g in fns):
            inner.append(f)
    return inner


def _duplicate_pairs(package: Path) -> str:
    tool = shutil.which("duplicates")
    if tool is None:
        return "n/a (no duplicates tool)"
    out = subprocess.run([tool, "--repo", str(package), "--seconds", "120"], capture_output=True, text=True).stdout
    first = out.strip().splitlines()[0] if out.strip() else ""
    m = re.match(r"(\d+) pairs?", first)
    return m.group(1) if m else ("0" if first.startswith("no duplicates") else first)


def figures(package: Path) -> list[tuple[str, str]]:
    modules = sorted(package.rglob("*.py"))
    sizes = {p: len(p.read_text(encoding="utf-8").splitlines()) for p in modules}
    big = sorted((n, p) for p, n in sizes.items() if n > 500)
    longest = (0, "")
    n_long = n_fn = n_ann = 0
    dispatchers: list[str] = []
    for p in modules:
        tree = ast.parse(p.read_text(encoding="utf-8"))
        rel = p.relative_to(package.parent)
        fns = list(_functions(tree))
        for fn in fns:
            n_fn += 1
            n_ann += _annotated(fn)
            start = min([fn.lineno, *(d.lineno for d in fn.decorator_list)])
            length = fn.end_lineno - start + 1
            n_long += length > 80
            longest = max(longest, (length, f"{rel}:{fn.name}"))
        disp = _innermost([f for f in fns if _is_dispatcher(f)])
        dispatchers += [f"{rel}:{f.name}" for f in disp]
    top = f" (largest {big[-1][1].relative_to(package.parent)}, {big[-1][0]})" if big else ""
    return [
        ("modules", str(len(modules))),
        ("lines", str(sum(sizes.values()))),
        ("modules over 500 lines", f"{len(big)}{top}"),
        ("functions over 80 lines", str(n_long)),
        ("longest function", f"{longest[0]} lines ({longest[1]})"),
        ("mode dispatchers", f"{len(dispatchers)}: " + ", ".join(dispatchers)),
        ("annotated share", f"{n_ann}/{n_fn} = {100 * n_ann / max(n_fn, 1):.0f} %"),
        ("duplicated blocks (pairs)", _duplicate_pairs(package)),
    ]


def main() -> None:
    package = Path(sys.argv[1] if len(sys.argv) > 1 else Path(__file__).resolve().parents[1] / "fracas")
    rows = figures(package)
    w = max(len(k) for k, _ in rows)
    for k, v in rows:
        print(f"{k:<{w}}  {v}")


if __name__ == "__main__":
    main()
