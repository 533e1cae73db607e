"""One line per deck problem: ``source: field.path = value: expected`` (from pydantic's
errors and :class:`~fracas.config.trajectory.problems.FieldProblem`), for every deck kind.
"""

from __future__ import annotations

import datetime as _dt
import difflib
import json
import types
import typing
from typing import Annotated, Any

from pydantic import BaseModel, ValidationError

from fracas.config.trajectory.deck import TrajectoryDeck
from fracas.config.trajectory.problems import FieldProblem, FieldProblems, _Given
from fracas.errors import DeckError

#: longest echo of a value in an error line
ECHO_CHARS = 40


def _fmt_value(v: Any) -> str:
    if isinstance(v, _Given):
        return str(v)
    if isinstance(v, (_dt.date, _dt.datetime)):
        s = v.isoformat()
    else:
        try:
            s = json.dumps(v, default=str)
        except (TypeError, ValueError, RecursionError):
            s = repr(v)
    return cut(s)


def cut(s: str, n: int = ECHO_CHARS) -> str:
    """``s`` cut to ``n`` characters with "…" (values echoed in error lines)."""
    return s if len(s) <= n else s[: n - 1] + "…"


def _fmt_loc(loc: tuple) -> str:
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        elif part == "[key]":
            continue
        else:
            out += ("." if out else "") + str(part)
    return out or "<deck>"


def _strip(ann: Any) -> Any:
    """Drop Annotated and Optional wrappers from a type annotation."""
    while True:
        origin = typing.get_origin(ann)
        if origin is Annotated:
            ann = typing.get_args(ann)[0]
        elif origin in (typing.Union, types.UnionType):
            args = [a for a in typing.get_args(ann) if a is not type(None)]
            if len(args) != 1:
                return ann
            ann = args[0]
        else:
            return ann


def _model_at(loc: tuple, root: type[BaseModel] | None = None) -> type[BaseModel] | None:
    """The pydantic model class that the location ``loc`` points into (best effort)."""
    cur: Any = root or TrajectoryDeck
    for part in loc:
        cur = _strip(cur)
        origin = typing.get_origin(cur)
        if origin is list:
            cur = typing.get_args(cur)[0]
        elif origin is dict:
            cur = typing.get_args(cur)[1]
        elif isinstance(cur, type) and issubclass(cur, BaseModel) and part in cur.model_fields:
            cur = cur.model_fields[part].annotation
        else:
            return None
    cur = _strip(cur)
    return cur if isinstance(cur, type) and issubclass(cur, BaseModel) else None


def _num(x: Any) -> str:
    return f"{x:g}" if isinstance(x, (int, float)) else str(x)


# C901 on purpose: one branch per pydantic error type, each its own wording
def _expected(err: dict) -> str:  # noqa: C901
    typ, ctx = err["type"], err.get("ctx") or {}
    if typ == "missing":
        return "required"
    if typ == "greater_than":
        return f"must be > {_num(ctx['gt'])}"
    if typ == "greater_than_equal":
        return f"must be >= {_num(ctx['ge'])}"
    if typ == "less_than":
        return f"must be < {_num(ctx['lt'])}"
    if typ == "less_than_equal":
        return f"must be <= {_num(ctx['le'])}"
    if typ in ("too_short", "too_long"):
        lo, hi = ctx.get("min_length"), ctx.get("max_length")
        if lo is not None and lo == hi:
            return f"must have exactly {lo} entries"
        return err["msg"].replace("Input should have", "must have").replace("List should have", "must have")
    if typ in ("float_type", "float_parsing"):
        return "must be a number"
    if typ in ("int_type", "int_parsing", "int_from_float"):
        return "must be an integer"
    if typ == "bool_type":
        return "must be true or false"
    if typ == "string_type":
        return "must be a string"
    if typ == "list_type":
        return "must be a list"
    if typ in ("dict_type", "model_type", "model_attributes_type"):
        return "must be a table"
    if typ == "finite_number":
        return "must be a finite number"
    msg = err["msg"]
    for prefix in ("Value error, ", "Assertion failed, "):
        if msg.startswith(prefix):
            msg = msg[len(prefix) :]
    return msg.replace("Input should be", "must be")


def _data_at(data: Any, loc: tuple) -> Any:
    for part in loc:
        if isinstance(data, dict) and part in data:
            data = data[part]
        elif isinstance(data, list) and isinstance(part, int) and 0 <= part < len(data):
            data = data[part]
        else:
            return None
    return data


def _line(source: str, loc: tuple, value: Any, expected: str, missing: bool = False) -> str:
    field = _fmt_loc(loc)
    if value is None or missing:
        return f"{source}: {field}: {expected}"
    return f"{source}: {field} = {_fmt_value(value)}: {expected}"


def validation_problems(
    exc: ValidationError, source: str, root: type[BaseModel] | None = None, data: Any = None
) -> list[str]:
    """Every error of ``exc``, one line each (``source: field.path = value: expected``).

    Unknown keys come first (a typo usually also makes a required key "missing"); when a
    known key that the table does not give is close to the unknown one, the line says
    ``did you mean``.  ``data``: the TOML data validated (for the keys a table gives).
    """
    errs = sorted(exc.errors(), key=lambda e: e["type"] != "extra_forbidden")
    lines: list[str] = []
    for err in errs:
        loc = tuple(err["loc"])
        problem = (err.get("ctx") or {}).get("error")
        if isinstance(problem, FieldProblems):
            lines += [_line(source, loc + p.field, p.value, p.expected) for p in problem.problems]
            continue
        if isinstance(problem, FieldProblem):
            lines.append(_line(source, loc + problem.field, problem.value, problem.expected))
            continue
        value = err.get("input")
        expected = _expected(err)
        if err["type"] == "extra_forbidden":
            parent = _model_at(loc[:-1], root)
            known = list(parent.model_fields) if parent is not None else []
            given = _data_at(data, loc[:-1])
            free = [k for k in known if not (isinstance(given, dict) and k in given)]
            key = str(loc[-1]) if loc else ""
            close = difflib.get_close_matches(key.lower(), free, n=1, cutoff=0.6)
            if close:
                lines.append(f"{source}: {cut(_fmt_loc(loc), 80)}: unknown key; did you mean {close[0]}?")
                continue
            expected = "unknown field" + (f" (expected one of: {', '.join(known)})" if known else "")
        lines.append(_line(source, loc, value, expected, missing=err["type"] == "missing"))
    return lines


def first_and_count(problems: list[str]) -> str:
    """The first problem line, with " (and N more errors)" when there are more."""
    line = problems[0]
    if len(problems) > 1:
        n = len(problems) - 1
        line += f" (and {n} more error{'s' if n > 1 else ''})"
    return line


def format_validation_error(exc: ValidationError, source: str, root: type[BaseModel] | None = None) -> str:
    """One line for the first error of ``exc``: ``source: field.path = value: expected``."""
    return first_and_count(validation_problems(exc, source, root))


def deck_error(problems: list[str]) -> DeckError:
    """One DeckError carrying every problem line (``str`` is the first, counted)."""
    return DeckError(first_and_count(problems), problems=problems)
