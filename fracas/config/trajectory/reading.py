"""Reading a deck: file bytes, TOML (nesting and 64-bit integer limits), the deck kind, and
validation into a frozen model (any problem is one :class:`fracas.errors.DeckError`); the
trajectory deck's hash.
"""

from __future__ import annotations

import hashlib
import json
import re
from pathlib import Path
from typing import Any, TypeVar

import tomllib
from pydantic import ValidationError

from fracas.config.trajectory.deck import SourcedDeck, TrajectoryDeck
from fracas.config.trajectory.messages import _line, cut, deck_error, validation_problems
from fracas.config.trajectory.problems import _Given
from fracas.errors import DeckError

#: deepest nesting of arrays / inline tables a deck may use (the schema needs 3)
MAX_NESTING = 16
#: largest deck file (a deck is a page of text; this only stops a runaway file)
MAX_DECK_BYTES = 16 * 1024 * 1024
#: TOML integers are 64-bit signed (TOML 1.0); tomllib accepts any size
_INT_MIN, _INT_MAX = -(2**63), 2**63 - 1


_Deck = TypeVar("_Deck", bound=SourcedDeck)


def _strip_bom(text: str) -> str:
    return text[1:] if text.startswith("\ufeff") else text


_HEADER_RE = re.compile(r"^\s*\[\[?\s*([^\]=]+?)\s*\]\]?\s*(#.*)?$")
_KEY_RE = re.compile(r"^\s*([^=\[\]{}#]+?)\s*=")


def _too_deep_line(text: str, source: str) -> str:
    """The line naming the key whose value nests too deeply (after tomllib's RecursionError)."""
    table, key, depth = "", "", 0
    for number, raw in enumerate(text.splitlines(), start=1):
        if depth == 0:
            m = _HEADER_RE.match(raw)
            if m:
                table = m.group(1).strip()
                continue
            m = _KEY_RE.match(raw)
            if m:
                key = m.group(1).strip().strip("\"'")
        for ch in raw:
            if ch in "[{":
                depth += 1
                if depth > MAX_NESTING:
                    field = f"{table}.{key}" if table else key
                    return (
                        f"{source}: {cut(field or f'line {number}', 80)} = {cut(raw.split('=', 1)[-1].strip())}: "
                        f"arrays / inline tables nested more than {MAX_NESTING} deep (line {number})"
                    )
            elif ch in "]}":
                depth = max(depth - 1, 0)
            elif ch == "#":
                break
    return f"{source}: arrays / inline tables nested more than {MAX_NESTING} deep"


def _scan(data: Any, loc: tuple, out: list[tuple[tuple, Any, str]], depth: int = 0) -> None:
    """Problems no schema can see: integers beyond 64 bits, nesting beyond MAX_NESTING."""
    if isinstance(data, bool):
        return
    if isinstance(data, int):
        if not (_INT_MIN <= data <= _INT_MAX):
            digits = len(str(abs(data)))
            out.append((loc, _Given(cut(str(data))), f"an integer of {digits} digits (TOML integers are 64-bit)"))
        return
    if isinstance(data, (list, dict)):
        if depth > MAX_NESTING:
            while len(loc) > 1 and isinstance(loc[-1], int) and isinstance(loc[-2], int):
                loc = loc[:-1]  # name the key (and its first index), not the whole way down
            out.append(
                (loc, _Given("[…]" if isinstance(data, list) else "{…}"), f"nested more than {MAX_NESTING} deep")
            )
            return
        items = data.items() if isinstance(data, dict) else enumerate(data)
        for k, v in items:
            _scan(v, loc + (k,), out, depth + 1)


def load_toml(text: str, source: str) -> dict:
    """TOML text (a leading BOM dropped) -> data; syntax errors, nesting beyond
    :data:`MAX_NESTING` and integers beyond 64 bits are one-line DeckErrors."""
    text = _strip_bom(text)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise DeckError(f"{source}: TOML syntax error: {exc}") from None
    except RecursionError:
        raise DeckError(_too_deep_line(text, source)) from None
    found: list[tuple[tuple, Any, str]] = []
    _scan(data, (), found)
    if found:
        raise deck_error([_line(source, loc, value, expected) for loc, value, expected in found])
    return data


def _named_mode(data: dict) -> str | None:
    """The mode the data evidently is, for a deck of the wrong kind (None: no evidence)."""
    mode = data.get("mode")
    if mode is not None:
        return mode if isinstance(mode, str) else None
    if "ertraj" in data:
        return "team"
    if any(k in data for k in ("epoch", "initial_state", "spacecraft", "stop")):
        return "propagate"
    return None


_KIND_NAMES = {
    "propagate": ("a trajectory deck", "fracas propagate"),
    "team": ("a TEAM deck", "fracas run"),
    "sweep": ("a sweep deck", "fracas sweep"),
    "tom": ("a TOM deck", "fracas run"),
    "tsim": ("a TSIM deck", "fracas run"),
    "rendezvous": ("a rendezvous deck", "fracas run"),
}


def _wrong_kind(data: dict, source: str, cls: type[SourcedDeck]) -> None:
    want = cls.model_fields["mode"].default
    got = _named_mode(data)
    if got is None or got == want or got not in _KIND_NAMES:
        return
    how = (
        f'mode = "{got}"'
        if "mode" in data
        else ("it has an [ertraj] table" if got == "team" else "it has no [ertraj] table")
    )
    what, command = _KIND_NAMES[got]
    raise DeckError(f"{source}: this is {what} ({how}), not {_KIND_NAMES[want][0]}: run it with {command}")


def parse_sourced(text: str, source: str, cls: type[_Deck]) -> _Deck:
    """Validate TOML text as a ``cls`` deck; any problem -> DeckError('source: field = value: expected').

    The DeckError's ``problems`` lists every problem found, one line each."""
    text = _strip_bom(text)
    data = load_toml(text, source)
    _wrong_kind(data, source, cls)
    return validate_sourced(data, source, cls, text=text)


def validate_sourced(
    data: dict, source: str, cls: type[_Deck], path: str | None = None, text: str | None = None
) -> _Deck:
    """Validate a deck's data (a TOML document, or one a program builds) as a ``cls`` deck
    that remembers ``path`` (default ``source``: relative paths resolve against it) and
    ``text``; any problem -> DeckError naming ``source``, every problem one line."""
    try:
        deck = cls.model_validate(data, context={"source": source})
    except ValidationError as exc:
        raise deck_error(validation_problems(exc, source, cls, data)) from None
    except RecursionError:  # defensive: load_toml bounds the nesting
        raise DeckError(f"{source}: nested too deeply to validate") from None
    deck._source_path = source if path is None else path
    deck._source_text = text
    return deck


def parse_deck(text: str, source: str = "<deck>") -> TrajectoryDeck:
    """Validate trajectory-deck TOML text; any problem -> one-line DeckError."""
    return parse_sourced(text, source, TrajectoryDeck)


def read_deck_bytes(path: str | Path, source: str, expected: str = "a TOML deck file") -> bytes:
    """The bytes of a deck file (at most MAX_DECK_BYTES); every failure is a one-line
    DeckError naming ``source`` (a folder: "is a directory, expected ``expected``").  Only a
    regular file is read (a FIFO or a device is refused before reading), and at most
    MAX_DECK_BYTES + 1 bytes of it (:func:`fracas.io.inputs.read_bounded`); the file is
    noted as an input of the run (no output may replace it)."""
    from fracas.io.inputs import read_bounded

    return read_bounded(path, MAX_DECK_BYTES, DeckError, expected, source)


def read_deck_text(path: str | Path) -> str:
    """The UTF-8 text of a deck file; every failure is a one-line DeckError."""
    source = str(path)
    raw = read_deck_bytes(path, source)
    if raw.startswith(b"\xef\xbb\xbf"):
        raw = raw[3:]
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise DeckError(f"{source}: not UTF-8 text (byte {exc.start})") from None


def load_deck(path: str | Path) -> TrajectoryDeck:
    """Read and validate a trajectory deck; every failure is a one-line DeckError."""
    return parse_deck(read_deck_text(path), str(path))


_HASH_PREFIX = "fracas-trajectory-deck/1\n"


def trajectory_hash(deck) -> str:
    """SHA-256 (hex) of the canonical form of a validated :class:`TrajectoryDeck`.

    The canonical form is the validated model as JSON (defaults filled in, floats in
    shortest round-trip form, keys sorted, no whitespace) behind a version prefix, so
    comments, layout, key order, ``7000`` vs ``7000.0``, a default written out or left
    implicit and the file's name or place do not change the hash; any changed value does
    (with ``[initial_state.oem]``, the state read from the OEM counts too).
    Every section counts (title and ``[output]`` included): the file is tied to exactly
    the deck it was built from (FRACAS writes ERTRAJ at the head of the STM tape).  The
    ``mode`` line and ``[limits]`` do not count (they say what to do with the trajectory and
    how big a run may get, not what the trajectory is).
    """
    dump = deck.model_dump(mode="json", exclude={"mode", "limits"})
    oem = deck.initial_state.oem
    if oem is not None:  # the state read from the OEM counts, not only the file's name
        dump["initial_state"]["oem"]["state"] = [*oem.r_km, *oem.v_km_s]
    else:  # a deck without [initial_state.oem] keeps the hash it had before the option existed
        dump["initial_state"].pop("oem", None)
    for arc in dump.get("thrust_arc", []):  # constant-pointing arcs keep the hash they had before the laws
        for key in ("alpha_legendre_deg", "beta_legendre_deg"):
            if not arc.get(key):
                arc.pop(key, None)
    body = json.dumps(
        dump,
        sort_keys=True,
        separators=(",", ":"),
        ensure_ascii=True,
        allow_nan=False,
    )
    return hashlib.sha256((_HASH_PREFIX + body).encode("utf-8")).hexdigest()
