"""The type check (CI step, after ``make test``): mypy over the checked modules, with a ratchet.

    python scripts/typecheck.py            # mypy on the checked modules; exit 1 on any error
    python scripts/typecheck.py --missing  # fully annotated modules not listed yet, sorted by
                                           # whether mypy passes on them (TOML lines to paste)

The checked modules are the list ``modules`` of ``[tool.fracas.typecheck]`` in pyproject.toml
(mypy's settings are ``[tool.mypy]`` there).  The ratchet, tested by
``tests/test_typecheck_ratchet.py`` without running mypy: every module of ``fracas/`` whose
functions are all annotated (every parameter but ``self``/``cls``, and the return) is in
``modules`` -- or in ``pending``, the fully annotated modules mypy does not pass yet, a list that
only shrinks -- and every listed module exists and stays fully annotated.  So a module, once
fully annotated, is checked, and the checked set only grows.  Modules without functions (most
``__init__.py``) are not required; they may be listed.
"""

from __future__ import annotations

import argparse
import ast
import re
import subprocess
import sys
import time
from pathlib import Path

import tomllib

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "fracas"


def config() -> dict[str, list[str]]:
    """``[tool.fracas.typecheck]`` of pyproject.toml: ``modules`` and ``pending`` (paths from the root)."""
    with open(ROOT / "pyproject.toml", "rb") as f:
        table = tomllib.load(f)["tool"]["fracas"]["typecheck"]
    return {"modules": list(table["modules"]), "pending": list(table.get("pending", []))}


# Reading a function's annotations needs only its header (``def name(...) -> ...:``): the headers
# are found with one regular expression that consumes string literals and comments whole (so a
# ``def`` in a docstring is no function) and each is parsed alone, which keeps the ratchet test
# well below a second where ``ast.parse`` of every module takes about one.  A module whose
# headers cannot be read this way is parsed whole.
_STRING = (
    r"'''(?:[^'\\]+|\\[\s\S]|'(?!''))*'''"
    r'|"""(?:[^"\\]+|\\[\s\S]|"(?!""))*"""'
    r"|'(?:[^'\\\n]|\\[\s\S])*'"
    r'|"(?:[^"\\\n]|\\[\s\S])*"'
    r"|\#[^\n]*"
)
_DEF = re.compile(rf"(?P<skip>{_STRING})|^(?P<def>[ \t]*(?:async[ \t]+)?def[ \t]+\w+[ \t]*\()", re.MULTILINE)
_HEADER_END = re.compile(rf"{_STRING}|[()\[\]{{}}:]")

Function = ast.FunctionDef | ast.AsyncFunctionDef


def _headers(src: str) -> list[tuple[int, Function]] | None:
    """(line, header parsed alone) of every ``def`` of ``src``; None where a header does not parse."""
    out: list[tuple[int, Function]] = []
    line, counted = 1, 0
    for m in _DEF.finditer(src):
        if m.group("def") is None:
            continue
        depth, end = 1, -1
        for t in _HEADER_END.finditer(src, m.end()):
            tok = t.group(0)
            if tok in "([{":
                depth += 1
            elif tok in ")]}":
                depth -= 1
            elif tok == ":" and depth == 0:
                end = t.start()
                break
        if end < 0:
            return None
        head = m.group("def").strip().removeprefix("async").lstrip()
        try:
            fn = ast.parse(head + src[m.end() : end] + ": pass").body[0]
        except SyntaxError:
            return None
        if not isinstance(fn, ast.FunctionDef):
            return None
        line += src.count("\n", counted, m.start())
        counted = m.start()
        out.append((line, fn))
    return out


def _functions(src: str) -> list[tuple[int, Function]]:
    """(line, node) of every function (at any depth) of a module's source."""
    heads = _headers(src)
    if heads is not None:
        return heads
    nodes = ast.walk(ast.parse(src))
    return [(n.lineno, n) for n in nodes if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))]


def _annotated(fn: Function) -> bool:
    """Every parameter but ``self``/``cls`` and the return carry an annotation (as house_figures counts)."""
    args = [*fn.args.posonlyargs, *fn.args.args, *fn.args.kwonlyargs]
    args += [a for a in (fn.args.vararg, fn.args.kwarg) if a is not None]
    params = [a for a in args if a.arg not in ("self", "cls")]
    return fn.returns is not None and all(a.annotation is not None for a in params)


def unannotated(path: Path) -> list[str]:
    """Names (with line numbers) of the functions of ``path`` that miss an annotation."""
    fns = _functions(path.read_text(encoding="utf-8"))
    return [f"{fn.name} (line {line})" for line, fn in fns if not _annotated(fn)]


def fully_annotated_modules() -> list[str]:
    """Modules of ``fracas/`` (paths from the root) with at least one function, all annotated."""
    out = []
    for path in sorted(PACKAGE.rglob("*.py")):
        fns = _functions(path.read_text(encoding="utf-8"))
        if fns and all(_annotated(fn) for _, fn in fns):
            out.append(path.relative_to(ROOT).as_posix())
    return out


def missing() -> list[str]:
    """Fully annotated modules in neither ``modules`` nor ``pending``."""
    cfg = config()
    listed = set(cfg["modules"]) | set(cfg["pending"])
    return [m for m in fully_annotated_modules() if m not in listed]


def run_mypy(extra: list[str]) -> int:
    """mypy on the checked modules (``extra``: more mypy options); 0 when it passes, else 1."""
    modules = config()["modules"]
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "mypy", *extra, *modules], cwd=ROOT)
    took = time.perf_counter() - t0
    verdict = "passed" if proc.returncode == 0 else f"FAILED (exit {proc.returncode})"
    print(f"typecheck: mypy on {len(modules)} checked modules {verdict} in {took:.1f} s")
    return 0 if proc.returncode == 0 else 1


def print_missing(extra: list[str]) -> int:
    """The unlisted fully annotated modules as TOML lines: those mypy passes (for ``modules``),
    then those it does not (for ``pending``); 1 when there are any."""
    todo = missing()
    if not todo:
        print("typecheck: every fully annotated module is listed")
        return 0
    proc = subprocess.run(
        [sys.executable, "-m", "mypy", *extra, *todo], cwd=ROOT, capture_output=True, text=True, check=False
    )
    if proc.returncode not in (0, 1):  # mypy could not check them (a syntax error, a bad option)
        print(proc.stdout + proc.stderr, end="")
        return 2
    failing = set(re.findall(r"^(fracas/\S+?\.py):\d+: error:", proc.stdout, flags=re.MULTILINE))
    for title, group in (
        ("modules", [m for m in todo if m not in failing]),
        ("pending", [m for m in todo if m in failing]),
    ):
        print(f"# add to {title} ({len(group)}):")
        for m in group:
            print(f'  "{m}",')
    return 1


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--missing", action="store_true", help="list fully annotated modules not yet listed")
    args, extra = parser.parse_known_args(argv)
    return print_missing(extra) if args.missing else run_mypy(extra)


if __name__ == "__main__":
    sys.exit(main())
