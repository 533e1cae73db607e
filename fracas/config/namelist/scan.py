"""Reading a namelist deck's text: the file (:func:`_read_text`), what f90nml skips (the mode
label and text outside any group, :func:`_scan_outside`, hand-parsed) and the groups by f90nml
(:func:`_parse`: ``&GROUP ... /`` and ``$GROUP ... $END``, repeated groups, indices from 1),
with one-line errors for indices below 1 and values past the indices written."""

from __future__ import annotations

import contextlib
import io
import re
import warnings
from pathlib import Path
from typing import Any

import f90nml

from fracas.config.namelist.fields import _MODE_LABELS
from fracas.config.trajectory import cut
from fracas.config.trajectory.reading import read_deck_bytes
from fracas.errors import DeckError

_GROUP_START = re.compile(r"^\s*[&$]([A-Za-z][A-Za-z0-9_]*)")
_GROUP_END = re.compile(r"(/|[&$]END\b|\$)\s*$", re.IGNORECASE)
_STRINGS = re.compile(r"'(?:[^']|'')*'|\"(?:[^\"]|\"\")*\"")


def _scan_outside(text: str) -> tuple[str | None, list[tuple[int, str]]]:
    """Hand scan of what f90nml skips: (the mode label, [(line number, text outside any group)])."""
    label, outside, inside = None, [], False
    for number, raw in enumerate(text.splitlines(), start=1):
        line = _STRINGS.sub("''", raw).split("!")[0]
        if not line.strip():
            continue
        if not inside:
            m = _GROUP_START.match(line)
            if m is None:
                word = line.strip().upper()
                if label is None and not outside and word in _MODE_LABELS:
                    label = word
                else:
                    outside.append((number, raw.strip()))
                continue
            inside = True
            line = line[m.end() :]
            if m.group(1).upper() == "END":
                inside = False
                continue
        if _GROUP_END.search(line) or re.search(r"[&$]END\b", line, re.IGNORECASE):
            inside = False
    return label, outside


def _read_text(text_or_path: str | Path, source: str | None) -> tuple[str, str]:
    """(text, source) of a namelist deck given as text or as a path."""
    if isinstance(text_or_path, Path) or (
        isinstance(text_or_path, str) and "\n" not in text_or_path and not re.search(r"[&$=]", text_or_path)
    ):
        p = Path(text_or_path)
        src = source or str(p)
        raw = read_deck_bytes(p, src, "a FRACAS namelist deck")
        try:
            return raw.decode("utf-8"), src
        except UnicodeDecodeError:
            return raw.decode("latin-1"), src  # old decks: any 8-bit text
    return str(text_or_path), source or "<namelist>"


def _dropped_value(message: str) -> str:
    """The problem behind f90nml's "Value X is not assigned to any variable" warning: more
    values than the indices written take (``IATT(2) = 2, 2``: f90nml keeps the first only),
    naming the variable as written when the parser's frame shows it."""
    import sys

    m = re.search(r"Value (.*) is not assigned to any variable", message)
    value = m.group(1) if m else "?"
    name, group, bounds = None, None, None
    frame = sys._getframe(1)
    while frame is not None:
        if frame.f_code.co_name == "_parse_variable" and name is None:
            name = frame.f_locals.get("v_name")
            bounds = frame.f_locals.get("v_idx_bounds")
        if "g_name" in frame.f_locals and group is None:
            group = frame.f_locals.get("g_name")
        frame = frame.f_back
    if name is None:
        return f"value {cut(value, 40)} is not assigned to any variable: expected one value per index written"
    where = f"${str(group or '?').upper()}.{str(name).upper()}"
    if bounds:
        where += "(" + ",".join(_bound_text(b) for b in bounds) + ")"
        low = [b[0] for b in bounds if isinstance(b, (tuple, list)) and b and b[0] is not None]
        if low and min(low) < 1:
            return f"{where}: index {min(low)}: {_BELOW_ONE}"
    return (
        f"{where} = ..., {cut(value, 40)}: more values than the indices written (the extra ones would be "
        f"dropped); expected one value per index, or a range {str(name).upper()}(k:m) = ..."
    )


_BELOW_ONE = "expected indices from 1 (FRACAS arrays start at 1; nothing below 1 is read)"


def _bound_text(b: Any) -> str:
    try:
        lo, hi, step = b
    except (TypeError, ValueError):
        return str(b)
    if hi is None or (lo is not None and hi == lo + 1 and step in (None, 1)):
        return str(lo)
    return f"{'' if lo is None else lo}:{hi - 1}" + ("" if step in (None, 1) else f":{step}")


def _parse(text: str, src: str) -> list[tuple[str, int, dict]]:
    """[(GROUP, occurrence, {NAME: value})] in deck order, by f90nml."""
    parser = f90nml.Parser()
    parser.global_start_index = 1
    dropped: list[str] = []
    try:
        with contextlib.redirect_stdout(io.StringIO()), warnings.catch_warnings():  # the tokenizer prints
            warnings.showwarning = lambda message, *_a, **_k: dropped.append(_dropped_value(str(message)))
            warnings.simplefilter("always")
            nml = parser.reads(text)
    except Exception as exc:  # f90nml raises ValueError, AssertionError, IndexError ... on bad text
        why = str(exc).strip() or type(exc).__name__
        raise DeckError(
            f"{src}: not a readable namelist deck ({cut(why, 80)}); expected &GROUP ... / or $GROUP ... $END"
        ) from None
    if dropped:
        raise DeckError(f"{src}: {dropped[0]}")
    out = []
    seen: dict[str, int] = {}
    for name, body in nml.items():  # a repeated group comes once per occurrence (or as a list)
        for b in body if isinstance(body, list) else [body]:
            group = name.upper()
            for var, first in getattr(b, "start_index", {}).items():
                if any(i is not None and i < 1 for i in first):
                    idx = ",".join("1" if i is None else str(i) for i in first)
                    low = min(i for i in first if i is not None)
                    raise DeckError(f"{src}: ${group}.{var.upper()}({idx}): index {low}: {_BELOW_ONE}")
            occ = seen.get(group, 0)
            seen[group] = occ + 1
            out.append((group, occ, {k.upper(): v for k, v in b.items()}))
    if not out:
        raise DeckError(f"{src}: no namelist groups found; expected &GROUP ... / or $GROUP ... $END (e.g. $DATA)")
    return out
