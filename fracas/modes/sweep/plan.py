"""A sweep's plan (:mod:`fracas.modes.sweep.run`; docs/sweep.md): the sweep deck the command line
gives (``--vary FIELD=VALUES``), each study's deck and key, the table's path and units, the
STM file and results folder, the groups of studies that run as batched computations and the
tasks the studies to run are cut into.
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import tomllib

from fracas.config.sweep import (
    SweepDeck,
    is_numeric_field,
    load_sweep_deck,
    output_unit,
    parse_field_path,
    varied_deck,
)
from fracas.config.team import TeamDeck
from fracas.config.trajectory import read_deck_text
from fracas.errors import DeckError
from fracas.modes import stm as stm_mode
from fracas.modes.base import default_output

__all__ = [
    "vary",
    "vary_many",
    "study_deck",
    "base_hash",
    "study_key",
    "plain",
    "input_unit",
    "table_units",
    "table_path",
    "stm_file",
    "results_dir",
    "tables_exist",
    "batch_groups",
    "plan_tasks",
    "parse_vary",
    "with_vary",
    "sweep_deck_for",
]


# ----------------------------------------------------------------------------- the studies' decks
def vary(deck: TeamDeck, field: str, value: Any) -> TeamDeck:
    """``deck`` with ``field`` (a dotted path, list entries by index: ``tracking[0].sigma``)
    set to ``value``, validated again (every validator runs); the base deck's
    ``source_path``/``source_text`` are kept so relative paths resolve as before.  A refused
    value is a one-line DeckError naming the field."""
    return vary_many(deck, {field: value})


def vary_many(deck: TeamDeck, values: dict[str, Any]) -> TeamDeck:
    """:func:`vary` for several fields at once (validated once, after all are set;
    :func:`fracas.config.sweep.varied_deck`)."""
    return varied_deck(deck, values)


def study_deck(base: TeamDeck, fields: tuple[str, ...], values: tuple) -> TeamDeck:
    """The TeamDeck of one study: ``base`` with ``fields`` set to ``values``; studies share no
    side outputs (no per-study STM build, no punch file) and compute no error budget (the
    table has no budget output; it would cost one covariance pass per error source)."""
    cfg = vary_many(base, dict(zip(fields, values)))
    upd: dict[str, Any] = {}
    if cfg.budget.enabled:
        upd["budget"] = cfg.budget.model_copy(update={"enabled": False})
    if cfg.errcon.build_stm:
        upd["errcon"] = cfg.errcon.model_copy(update={"build_stm": False})
    if cfg.punch is not None:
        upd["punch"] = None
    if upd:
        src, text = cfg._source_path, cfg._source_text
        cfg = cfg.model_copy(update=upd)
        cfg._source_path, cfg._source_text = src, text
    return cfg


# ----------------------------------------------------------------------------- keys
def base_hash(deck: TeamDeck) -> str:
    """SHA-256 (hex) of the base study's deck text and of its trajectory deck's text."""
    h = hashlib.sha256((deck.source_text or json.dumps(deck.model_dump(mode="json"), sort_keys=True)).encode())
    try:
        h.update(b"\0" + read_deck_text(deck.resolve(deck.ertraj.deck)).encode())
    except DeckError:
        pass
    return h.hexdigest()


def study_key(base: str, fields: tuple[str, ...], values: tuple) -> str:
    """16 hex digits naming one study: the base hash and the varied values."""
    text = json.dumps([base, list(fields), [plain(v) for v in values]])
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def plain(v: Any) -> Any:
    """``v`` as a Python value (a numpy scalar's ``item()``)."""
    return v.item() if isinstance(v, np.generic) else v


# ----------------------------------------------------------------------------- the table's path and units
_SUFFIX_UNITS = (
    ("_km_s", "km/s"),
    ("_km", "km"),
    ("_kg", "kg"),
    ("_days", "d"),
    ("_hours", "h"),
    ("_deg", "deg"),
    ("_s", "s"),
)


def input_unit(deck: TeamDeck, field: str) -> str:
    """The unit of a varied field as the deck writes it (from its name; a tracking sigma from
    its type; "deck" where the unit is the parameter label's, e.g. a parameter sigma)."""
    from fracas.config.team import SIGMA_UNITS

    parts = parse_field_path(field)
    names = [p for p in parts if isinstance(p, str)]
    last = names[-1]
    if len(parts) >= 3 and parts[0] == "tracking" and last == "sigma" and isinstance(parts[1], int):
        if parts[1] < len(deck.tracking):
            return str(SIGMA_UNITS[deck.tracking[parts[1]].type][0])
    if len(names) >= 2 and names[-2] == "proportionality" and last == "sigma":
        return "1"
    for n in reversed(names):
        for suf, unit in _SUFFIX_UNITS:
            if n.endswith(suf):
                return unit
    return "deck"


def table_units(base: TeamDeck, fields: tuple[str, ...], outputs: list[str]) -> dict[str, str]:
    """The units of the table's columns known before any study runs: each varied field's
    (:func:`input_unit`) and each output's whose unit its name gives."""
    units: dict[str, str] = {f: input_unit(base, f) for f in fields}
    units.update({n: u for n in outputs if (u := output_unit(n)) is not None})
    return units


def table_path(cfg: SweepDeck) -> Path:
    """The deck's ``[output] table``, else ``out/<deck stem>.h5``."""
    if cfg.output.table:
        return cfg.resolve(cfg.output.table)
    return default_output(cfg.source_path)


def stm_file(cfg: SweepDeck, base: TeamDeck, todo: list[int]) -> str | None:
    """The sweep's STM file (``sweep.stm_file``; built first when it is missing and studies
    are to run), or None."""
    sw = cfg.sweep
    if not sw.stm_file:
        return None
    stm_path = cfg.resolve(sw.stm_file)
    if not stm_path.exists() and todo:
        stm_mode.build_stm(base, stm_path)
    return str(stm_path)


def results_dir(cfg: SweepDeck, beside: Callable[[str], Path], out: Path) -> Path | None:
    """The folder (made here) of each study's results file with ``sweep.keep_results``, or None."""
    sw = cfg.sweep
    if not sw.keep_results:
        return None
    res_dir = beside(sw.results_folder) if sw.results_folder else out.parent / f"{out.stem}_results"
    res_dir.mkdir(parents=True, exist_ok=True)
    return res_dir


# ----------------------------------------------------------------------------- groups and tasks
def tables_exist(base: TeamDeck, fields: tuple[str, ...]) -> bool:
    """Whether every numeric field of ``fields`` lies in a table (or list) the base study
    has, so that setting it changes a number and adds no table (a [gencov] or a thrust-noise
    component the study does not have would change its structure)."""
    cur0 = base.model_dump(mode="python")
    for f in fields:
        if not is_numeric_field(f):
            continue
        cur: Any = cur0
        for p in parse_field_path(f)[:-1]:
            try:
                cur = cur[p]
            except (KeyError, IndexError, TypeError):
                return False
            if cur is None:
                return False
    return True


def _groups(studies: list[tuple], fields: tuple[str, ...]) -> dict[int, str]:
    """Study index -> its group (the values of its structural fields), for the studies whose
    group has two or more members (the others run one by one)."""
    numeric = [is_numeric_field(f) for f in fields]
    if not any(numeric):
        return {}
    groups: dict[str, list[int]] = {}
    for i, v in enumerate(studies):
        groups.setdefault(json.dumps([plain(x) for x, num in zip(v, numeric) if not num]), []).append(i)
    return {i: g for g, idx in groups.items() if len(idx) >= 2 for i in idx}


def batch_groups(base: TeamDeck, studies: list[tuple], fields: tuple[str, ...], batch: bool) -> dict[int, str]:
    """:func:`_groups` of a sweep that may batch (``batch``: batching asked for and no study
    keeps its results), else none."""
    # guidance and reset studies are not batched (fracas.team.batch.prepare): one by one from the start
    batchable = not base.guidance and not any(e.type == "reset" for e in base.event)
    return _groups(studies, fields) if (batch and batchable) else {}


def plan_tasks(todo: list[int], group_of: dict[int, str], max_batch: int, n_workers: int) -> list[tuple]:
    """("group", indices, group, pad) chunks (about one per worker, at most ``max_batch``
    studies each) and ("one", index) tasks, in the order of ``todo``."""
    from fracas.team.batch import batch_size

    by_group: dict[str, list[int]] = {}
    for i in todo:
        if i in group_of:
            by_group.setdefault(group_of[i], []).append(i)
    out: list[tuple] = []
    for g, idx in by_group.items():
        c = max(1, min(max_batch, math.ceil(len(idx) / max(1, n_workers))))
        pad = batch_size(c)
        out += [("group", idx[j : j + c], g, pad) for j in range(0, len(idx), c)]
    return out + [("one", i) for i in todo if i not in group_of]


# ----------------------------------------------------------------------------- the deck from the command line
def _value(text: str) -> Any:
    """One command-line value as TOML reads it (1e-3 -> float, true -> bool, "x" -> str);
    a bare word that is not TOML is a string."""
    try:
        return tomllib.loads(f"v = {text.strip()}")["v"]
    except tomllib.TOMLDecodeError:
        return text.strip()


def parse_vary(spec: str) -> dict[str, Any]:
    """``FIELD=VALUES`` -> a ``[[sweep.vary]]`` table: ``a=1,2,3`` (values), ``a=0.1:1:5``
    (start:stop:num, linear), ``a=log:1e-3:1e-1:5`` (logarithmic).  DeckError if malformed."""
    if "=" not in spec:
        raise DeckError(f"--vary {spec!r}: expected FIELD=VALUES, e.g. thrust_noise.proportionality.sigma=0.01,0.02")
    field, _, rhs = spec.partition("=")
    field, rhs = field.strip(), rhs.strip()
    if not rhs:
        raise DeckError(f"--vary {spec!r}: no values after '='")
    if ":" in rhs and not rhs.startswith(("'", '"')):
        parts = rhs.split(":")
        spacing = "linear"
        if parts[0].strip().lower() in ("log", "lin", "linear"):
            spacing = "log" if parts[0].strip().lower() == "log" else "linear"
            parts = parts[1:]
        if len(parts) != 3:
            raise DeckError(f"--vary {spec!r}: a range is start:stop:num or log:start:stop:num")
        try:
            start, stop, num = float(parts[0]), float(parts[1]), int(parts[2])
        except ValueError:
            raise DeckError(f"--vary {spec!r}: start and stop must be numbers, num an integer") from None
        return {"field": field, "start": start, "stop": stop, "num": num, "spacing": spacing}
    return {"field": field, "values": [_value(v) for v in rhs.split(",") if v.strip()]}


def with_vary(cfg: SweepDeck, specs: list[str]) -> SweepDeck:
    """``cfg`` with the command line's ``--vary`` entries (replacing entries of the same field)."""
    from pydantic import ValidationError

    from fracas.config.trajectory import deck_error, validation_problems

    if not specs:
        return cfg
    new = [parse_vary(s) for s in specs]
    named = {v["field"] for v in new}
    data = cfg.model_dump(mode="python", exclude_unset=True)
    data["sweep"]["vary"] = [v for v in data["sweep"].get("vary", []) if v["field"] not in named] + new
    src = f"{cfg.source_path or '<deck>'} (with --vary)"
    try:
        out = SweepDeck.model_validate(data)
    except ValidationError as exc:
        raise deck_error(validation_problems(exc, src, SweepDeck, data)) from None
    out._source_path, out._source_text = cfg._source_path, cfg._source_text
    return out


def sweep_deck_for(deck_path: str | Path, specs: list[str]) -> SweepDeck:
    """The sweep deck of ``deck_path``: a sweep deck (``--vary`` adds or replaces fields) or a
    TEAM deck swept over the ``--vary`` fields (at least one)."""
    from fracas.modes import mode_of_deck

    path = Path(deck_path)
    mode = mode_of_deck(path)
    if mode.name == "sweep":
        return with_vary(load_sweep_deck(path), specs)
    if not mode.sweep_study:
        raise DeckError(f'{path}: a sweep runs a TEAM deck or a sweep deck (mode = "sweep"), not mode = "{mode.name}"')
    if not specs:
        raise DeckError(f"{path}: a TEAM deck: give the fields to vary with --vary FIELD=VALUES")
    from fracas.config.trajectory import validate_sourced

    data = {
        "mode": "sweep",
        "sweep": {"study": path.name, "vary": [parse_vary(s) for s in specs]},
        "output": {"table": f"out/{path.stem}_sweep.h5"},
    }
    return validate_sourced(data, f"{path} (--vary)", SweepDeck, path=str(path))
