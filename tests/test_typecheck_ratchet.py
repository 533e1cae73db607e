"""The type-check ratchet (``[tool.fracas.typecheck]`` in pyproject.toml; mypy itself runs in
CI through ``scripts/typecheck.py``, not here): a fully annotated module must be listed, and a
listed module must exist and stay fully annotated, so the checked set only grows."""

from __future__ import annotations

import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("typecheck", ROOT / "scripts" / "typecheck.py")
assert _spec is not None and _spec.loader is not None
typecheck = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(typecheck)


def test_listed_modules_exist_once():
    cfg = typecheck.config()
    listed = cfg["modules"] + cfg["pending"]
    assert [m for m in listed if not (ROOT / m).is_file()] == [], (
        "listed in [tool.fracas.typecheck] of pyproject.toml but not a file (moved? list its new path)"
    )
    assert sorted({m for m in listed if listed.count(m) > 1}) == [], "listed twice (modules and pending are disjoint)"


def test_fully_annotated_modules_are_listed():
    missing = typecheck.missing()
    assert missing == [], (
        f"fully annotated but not type-checked: {missing}; add them to `modules` of [tool.fracas.typecheck] "
        "in pyproject.toml (`python scripts/typecheck.py --missing` prints the lines, and which mypy "
        "does not pass yet: those go to `pending`)"
    )


def test_listed_modules_stay_annotated():
    cfg = typecheck.config()
    lost = {m: typecheck.unannotated(ROOT / m) for m in cfg["modules"] + cfg["pending"] if (ROOT / m).is_file()}
    lost = {m: fns for m, fns in lost.items() if fns}
    assert lost == {}, (
        f"type-checked modules with unannotated functions: {lost}; annotate every parameter (but self/cls) "
        "and the return (the checked set only grows)"
    )
