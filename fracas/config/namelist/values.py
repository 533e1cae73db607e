"""One namelist variable -> TOML data: a value type-checked and converted by its field
(:func:`_scalar`), written at its TOML path (:func:`_set`), a whole variable (scalar, list,
``NAME(k)`` entries or ``NAME(j,k)`` arrays) filled into its deck's data (:func:`_fill`), and
lists of tables with a hole refused (:func:`_fix_lists`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from fracas.config.namelist.fields import NmlField
from fracas.config.namelist.results import _loc_text, _show, _where
from fracas.config.trajectory import cut
from fracas.errors import DeckError

_NUM = (int, float)
#: string fields written as given (names, files, dates); the others are matched without regard to case
_KEEP_CASE = {"TITLE", "EPOCH", "DECK", "STMFIL", "RESULT", "PLOT", "REFDK", "PUFILE", "KPUNCH", "CPUNCH", "TPUNCH"}
_KEEP_CASE |= {"APSTAT", "TEAMDK", "GNAME", "NAME", "USRGAN", "CEPOCH", "EPOCHF", "TCFLD"}


def _choices(name: str) -> tuple[str, ...] | None:
    from fracas.guidance.target_kinds import TARGET_KINDS

    if name in ("FRAME", "CFRAME"):
        return ("EME2000", "ECLIPJ2000", "BODY_EQUATOR")
    if name in ("TNAME", "GTARG"):
        return tuple(TARGET_KINDS)
    return None


def _case(name: str, v: str) -> str:
    """A string value as the TOML schema spells it: enumerations matched without regard to case
    (FRACAS decks are upper case), names and file names as given."""
    if name in _KEEP_CASE:
        return v
    choices = _choices(name)
    if choices is not None:
        for c in choices:
            if c.lower() == v.lower():
                return c
        return v
    return v.lower()


# C901 on purpose: one branch per namelist value kind (real, integer, logical, text, code lists)
def _scalar(f: NmlField, v: Any, where: str) -> Any:  # noqa: C901
    """One namelist value -> its TOML value (type checked, converted); DeckError naming the field."""
    kind = f.kind
    if kind in ("reals",):
        kind = "real"
    if kind == "strs":
        kind = "str"
    bad = None
    if kind in ("real", "msig"):
        if isinstance(v, bool) or not isinstance(v, _NUM) or not math.isfinite(float(v)):
            bad = "a number"
        else:
            return float(v) * f.scale if f.scale != 1.0 else float(v)
    elif kind == "int":
        if isinstance(v, bool) or not isinstance(v, int):
            bad = "an integer"
        else:
            return v
    elif kind in ("str", "key"):
        if not isinstance(v, str):
            bad = "a quoted string"
        else:
            return _case(f.name, v.strip())
    elif kind == "bool":
        if not isinstance(v, bool):
            bad = "a logical (T or F)"
        else:
            return v
    elif kind == "boolstr":
        if isinstance(v, bool):
            return v
        if isinstance(v, str) and v.strip().lower() == "if_missing":
            return "if_missing"
        bad = "a logical (T or F) or 'IF_MISSING'"
    elif kind == "any":
        if isinstance(v, (bool, int, float, str)):
            return v.strip() if isinstance(v, str) else v
        bad = "a number, logical or string"
    elif kind == "epoch":
        if isinstance(v, str):
            return v.strip()
        if isinstance(v, _NUM) and not isinstance(v, bool):
            return float(v)
        bad = "an ISO date string or a Julian date"
    elif kind == "code":
        names = dict(f.codes)
        if isinstance(v, int) and not isinstance(v, bool) and v in names:
            return names[v]
        if isinstance(v, str) and v.strip().lower() in names.values():
            return v.strip().lower()
        bad = "one of " + ", ".join(f"{c} ({n})" for c, n in f.codes)
    if bad is None:
        bad = "a value"
    raise DeckError(f"{where} = {cut(_show(v), 40)}: expected {bad}")


def _set(root: dict, path: tuple, value: Any) -> None:
    """Set ``value`` at ``path`` (str keys, int list indices) creating dicts and lists."""
    cur: Any = root
    for i, part in enumerate(path):
        last = i == len(path) - 1
        nxt: Any = None if last else ([] if isinstance(path[i + 1], int) else {})
        if isinstance(part, int):
            while len(cur) <= part:
                cur.append(None if last else type(nxt)())
            if last:
                cur[part] = value
            else:
                if cur[part] is None:
                    cur[part] = nxt
                cur = cur[part]
        else:
            if last:
                cur[part] = value
            else:
                cur = cur.setdefault(part, nxt)


def _as_list(v: Any) -> list:
    return v if isinstance(v, list) else [v]


def _trim(v: list) -> list:
    while v and v[-1] is None:
        v = v[:-1]
    return v


@dataclass
class _Target:
    """Where a mode's groups write: part name -> TOML data, and provenance for error lines."""

    parts: dict[str, dict] = field(default_factory=dict)
    origin: dict[tuple[str, str], str] = field(default_factory=dict)  # (part, toml path text) -> $GROUP.NAME(k)
    mapped: int = 0


#: the most entries an indexed namelist variable may give (the TOML decks' own event and arc
#: limits are of this order; fracas.config.limits)
MAX_ENTRIES = 20_000


def _split_blanks(f: NmlField, items: list) -> list:
    """A list of strings given as one blank-separated string (``MSTA(k) = 'GOLDSTONE MADRID'``)."""
    if f.kind == "strs" and len(items) == 1 and isinstance(items[0], str) and " " in items[0].strip():
        return items[0].split()  # hand-parsed: a blank-separated list in one string
    return items


def _fill(tgt: _Target, part: str, prefix: tuple, f: NmlField, value: Any, src: str, group: str) -> None:
    """Write one namelist variable's value(s) into the part's data."""
    root = tgt.parts.setdefault(part, {})
    if f.name == "S" and group == "SMAG":
        _set(root, prefix + f.path, _as_list(value))
        tgt.mapped += 1
        return
    star = f.path.index("*") if f.indexed else None
    list_kind = f.kind in ("reals", "strs")
    if star is None:
        if list_kind:
            items = _split_blanks(f, _as_list(value))
            if any(x is None for x in _trim(items)):
                j = _trim(items).index(None) + 1
                raise DeckError(
                    f"{_where(src, group, f.name, j)}: not given; expected a value at every index from 1 to "
                    f"{len(_trim(items))} (the highest index written)"
                )
            conv = [_scalar(f, x, f"{_where(src, group, f.name)}({j + 1})") for j, x in enumerate(_trim(items))]
            _set(root, prefix + f.path, conv)
        else:
            if isinstance(value, list):
                raise DeckError(
                    f"{_where(src, group, f.name)} = {cut(_show(value), 40)}: expected one value, not a list"
                )
            _set(root, prefix + f.path, _scalar(f, value, _where(src, group, f.name)))
        tgt.origin[(part, _loc_text(prefix + f.path))] = f"${group}.{f.name}"
        tgt.mapped += 1
        return
    head, tail = f.path[:star], f.path[star + 1 :]
    entries = _as_list(value)
    if len(entries) > MAX_ENTRIES:  # a huge index (TON(3000000) = 1.0) would build millions of tables
        raise DeckError(
            f"{_where(src, group, f.name, len(entries))}: index {len(entries)}: expected at most {MAX_ENTRIES} entries"
        )
    if list_kind and entries and not any(isinstance(e, list) for e in entries):
        entries = [entries]  # NAME = a, b (no index): the values of entry 1
    for k, entry in enumerate(entries, start=1):
        if entry is None:
            continue
        if list_kind:
            items = _split_blanks(f, _trim(_as_list(entry)))
            if not items:
                continue  # NAME(:,k) all empty: entry k does not give it
            if any(x is None for x in items):
                raise DeckError(f"{_where(src, group, f.name, k)}: has an empty element")
            v = [_scalar(f, x, _where(src, group, f.name, k, j + 1)) for j, x in enumerate(items)]
        else:
            if isinstance(entry, list):
                raise DeckError(f"{_where(src, group, f.name, k)}: expected one value per entry")
            v = _scalar(f, entry, _where(src, group, f.name, k))
        path = prefix + head + (k - 1,) + tail + (("*",) if f.kind == "key" else ())
        _set(root, path, v)
        tgt.origin[(part, _loc_text(path))] = f"${group}.{f.name}({k})"
        tgt.mapped += 1


def _fix_lists(data: Any, src: str, where: str = "") -> Any:
    """Lists of tables with a hole (NAME(3) given, NAME(2) not) -> DeckError; recurse."""
    if isinstance(data, dict):
        return {k: _fix_lists(v, src, f"{where}.{k}" if where else k) for k, v in data.items()}
    if isinstance(data, list):
        if any(isinstance(x, dict) for x in data) and any(x is None for x in data):
            k = data.index(None)
            raise DeckError(f"{src}: {where}[{k}]: entry {k + 1} is not given (the arrays skip it)")
        return [_fix_lists(x, src, f"{where}[{i}]") for i, x in enumerate(data)]
    return data
