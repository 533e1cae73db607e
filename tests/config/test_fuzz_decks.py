"""Seeded mutation fuzzing of the bundled decks (trajectory and TEAM) through parse and validate.

Each mutant (1-3 mutations of one bundled deck: delete a key, rename a key with a typo,
replace a value with 0, -1, 1e308, "nan", a 400-digit integer, 3,000-deep nesting, a
100 kB string, a boolean, an empty array or table; duplicate a table; swap two values;
prepend a BOM; truncate the text) goes through :func:`fracas.modes.parse_any` and
:func:`fracas.modes.validate_path` in this process (no JAX).  Nothing may escape but a
DeckError / ConfigError of one line naming the file; validate_path returns one-line
problems and never raises; each deck takes < 2 s (a hang detector, not a speed test).

1,400 mutants (200 per bundled deck, 7 decks), seed 20240808: about 15 s on the 2-core
development machine.
"""

from __future__ import annotations

import random
import re
import shutil
import time
from pathlib import Path

import pytest

from fracas.errors import ConfigError, DeckError
from fracas.modes import parse_any, validate_path

ROOT = Path(__file__).resolve().parents[2]
DECKS = sorted((ROOT / "namelists").glob("*.toml")) + [ROOT / "tests" / "data" / "team_small.toml"]
PER_DECK = 200
SEED = 20240808
BUDGET_S = 2.0

_KEY_LINE = re.compile(r"^(\s*)([A-Za-z_][A-Za-z0-9_]*)(\s*=\s*)(.*)$")
_HEADER = re.compile(r"^\s*\[\[?[^\]]+\]\]?\s*(#.*)?$")
VALUES = (
    "0",
    "-1",
    "1e308",
    "-1e308",
    '"nan"',
    "nan",
    "inf",
    "1" + "0" * 400,
    "[" * 3000 + "]" * 3000,
    "[" * 40 + "1" + "]" * 40,
    '"' + "x" * 100_000 + '"',
    "true",
    "[]",
    "{}",
    '"Goldstone"',
    "1e-9",
    "5e-324",
    '["a", 1, 2.5]',
    "{ sigma = 1e300, tau_days = 0 }",
)


def _typo(rng: random.Random, key: str) -> str:
    i = rng.randrange(len(key))
    op = rng.choice(("drop", "double", "swap", "upper", "suffix"))
    if op == "drop" and len(key) > 1:
        return key[:i] + key[i + 1 :]
    if op == "double":
        return key[:i] + key[i] + key[i:]
    if op == "swap" and i + 1 < len(key):
        return key[:i] + key[i + 1] + key[i] + key[i + 2 :]
    if op == "upper":
        return key.upper()
    return key + "s"


def mutate(rng: random.Random, text: str) -> str:
    lines = text.splitlines()
    keyed = [i for i, line in enumerate(lines) if _KEY_LINE.match(line)]
    op = rng.choice(("delete", "typo", "value", "value", "value", "dup_table", "swap", "bom", "truncate"))
    if op == "bom":
        return "\ufeff" + text
    if op == "truncate":
        return text[: rng.randrange(len(text))]
    if op == "dup_table":
        heads = [i for i, line in enumerate(lines) if _HEADER.match(line)]
        if heads:
            i = rng.choice(heads)
            j = next((h for h in heads if h > i), len(lines))
            lines = lines + lines[i:j]
        return "\n".join(lines) + "\n"
    if not keyed:
        return text
    i = rng.choice(keyed)
    m = _KEY_LINE.match(lines[i])
    if op == "delete":
        del lines[i]
    elif op == "typo":
        lines[i] = m.group(1) + _typo(rng, m.group(2)) + m.group(3) + m.group(4)
    elif op == "value":
        lines[i] = m.group(1) + m.group(2) + m.group(3) + rng.choice(VALUES)
    else:  # swap two values (comments and all)
        j = rng.choice(keyed)
        n = _KEY_LINE.match(lines[j])
        lines[i] = m.group(1) + m.group(2) + m.group(3) + n.group(4)
        lines[j] = n.group(1) + n.group(2) + n.group(3) + m.group(4)
    return "\n".join(lines) + "\n"


def _check_one_line(line: str, sources: tuple[str, ...]) -> None:
    assert "\n" not in line, line[:300]
    assert line.startswith(tuple(f"{s}: " for s in sources)), line[:300]


@pytest.mark.parametrize("deck", DECKS, ids=lambda p: p.name)
def test_mutants_give_one_line_errors(deck, tmp_path):
    rng = random.Random(f"{SEED}-{deck.name}")
    original = deck.read_text(encoding="utf-8")
    # the TEAM decks' trajectory decks, copied beside the mutant (sometimes mutated too)
    traj_names = re.findall(r'^(?:deck|study)\s*=\s*"([^"]+)"', original, flags=re.M)
    for name in traj_names:
        shutil.copy(deck.parent / name, tmp_path / name)
    target = tmp_path / deck.name
    sources = (str(target), *(str(tmp_path / n) for n in traj_names))
    slowest = 0.0
    for k in range(PER_DECK):
        text = original
        for _ in range(rng.choice((1, 1, 2, 3))):
            text = mutate(rng, text)
        for name in traj_names:
            traj_text = (deck.parent / name).read_text(encoding="utf-8")
            if rng.random() < 0.2:
                traj_text = mutate(rng, traj_text)
            (tmp_path / name).write_text(traj_text, encoding="utf-8")
        target.write_text(text, encoding="utf-8")
        t0 = time.perf_counter()
        try:
            parse_any(text, str(target))
        except (DeckError, ConfigError) as exc:
            _check_one_line(str(exc), sources)
            for line in exc.problems:
                _check_one_line(line, sources)
        problems = validate_path(target)
        assert isinstance(problems, list)
        for line in problems:
            _check_one_line(line, sources)
        elapsed = time.perf_counter() - t0
        slowest = max(slowest, elapsed)
        assert elapsed < BUDGET_S, f"mutant {k} of {deck.name} took {elapsed:.1f} s"
    print(f"{deck.name}: {PER_DECK} mutants, slowest {slowest * 1e3:.0f} ms")
