"""The mode registry: every mode declared once, read by ``fracas run``, ``validate``,
``report``, sweeps and :func:`load_any`.

A mode is a :class:`fracas.modes.base.Mode`: its deck parser (text -> validated config), its
orchestrator (config -> product and files), its ``fracas run`` command (the orchestrator plus
the terminal report), its results-file kind, reader and report, its ``fracas validate``
checks and the run options it takes.  :data:`REGISTRY` names each mode's module, one line a
mode; the module is imported only when the mode is used, so ``fracas --help`` and a deck's
error stay fast.  Adding a mode is one package (or module) defining ``MODE`` and one line
here (xarray's backend entry points are the model)::

    REGISTRY["toy"] = "mypackage.toy:MODE"

A deck names its mode in its ``mode`` line; without one it is a trajectory deck
(``propagate``), or a TEAM deck written before ``mode`` existed when it has an ``[ertraj]``
table.
"""

from __future__ import annotations

import importlib
from pathlib import Path
from typing import TYPE_CHECKING, Any

from fracas.errors import DeckError

if TYPE_CHECKING:
    from fracas.modes.base import Mode

__all__ = [
    "REGISTRY",
    "MODES",
    "mode",
    "modes",
    "deck_mode",
    "mode_of_deck",
    "mode_for_kind",
    "parse_any",
    "load_any",
    "check_path",
    "validate_path",
]

#: mode name -> "module:attribute" of its :class:`fracas.modes.base.Mode` (one line a mode)
REGISTRY: dict[str, str] = {
    "propagate": "fracas.modes.propagate:MODE",
    "team": "fracas.modes.team:MODE",
    "sweep": "fracas.modes.sweep:MODE",
    "tom": "fracas.modes.tom:MODE",
    "tsim": "fracas.modes.tsim:MODE",
    "rendezvous": "fracas.modes.rendezvous:MODE",
}

#: the modes of this release, in the registry's order (a tuple: read it, never extend it)
MODES: tuple[str, ...] = tuple(REGISTRY)


def mode(name: str) -> Mode:
    """The registered mode ``name`` (its module imported on first use); KeyError if none."""
    module, _, attr = REGISTRY[name].partition(":")
    found = getattr(importlib.import_module(module), attr or "MODE")
    if found.name != name:
        raise RuntimeError(f"{REGISTRY[name]} declares mode {found.name!r}, registered as {name!r}")
    return found


def modes() -> list[Mode]:
    """Every registered mode, in the registry's order."""
    return [mode(name) for name in REGISTRY]


def _expected() -> str:
    return ", ".join(REGISTRY)


def deck_mode(text: str, source: str = "<deck>") -> str:
    """The mode of deck text: its ``mode`` value, else "team" for a legacy TEAM deck (an
    [ertraj] table), else "propagate".  DeckError for a TOML error or an unknown mode."""
    from fracas.config.trajectory import cut, load_toml

    data = load_toml(text, source)
    name = data.get("mode")
    if name is None:
        return "team" if "ertraj" in data else "propagate"
    if isinstance(name, str) and name in REGISTRY:
        return name
    raise DeckError(f"{source}: mode = {cut(repr(name))}: unknown mode (expected one of: {_expected()})")


def mode_of_deck(path: str | Path) -> Mode:
    """The registered mode of the deck at ``path`` (read and its ``mode`` line checked)."""
    from fracas.config.trajectory import read_deck_text

    return mode(deck_mode(read_deck_text(path), str(path)))


def mode_for_kind(kind: str) -> Mode | None:
    """The mode whose results files carry ``file_kind = kind``, or None."""
    for name in REGISTRY:
        m = mode(name)
        if kind in m.results_kinds:
            return m
    return None


def parse_any(text: str, source: str = "<deck>") -> Any:
    """The validated deck of whatever mode ``text`` asks for (its mode's parser)."""
    return mode(deck_mode(text, source)).parse(text, source)


def load_any(path: str | Path) -> Any:
    """Read and validate a deck of any mode; every failure is a one-line DeckError."""
    from fracas.config.trajectory import read_deck_text

    return parse_any(read_deck_text(path), str(path))


def check_path(path: str | Path) -> tuple[str | None, list[str]]:
    """``fracas validate``: (the deck's mode, or None if unreadable; every problem, one line
    each).  The schema's problems (all of them), then its mode's own checks of everything
    the deck names (:attr:`fracas.modes.base.Mode.problems`), without running anything."""
    from fracas.config.trajectory import read_deck_text
    from fracas.errors import FracasError

    src = str(path)
    try:
        text = read_deck_text(path)
        name = deck_mode(text, src)
        deck = mode(name).parse(text, src)
    except FracasError as exc:
        kind = None
        try:
            kind = deck_mode(read_deck_text(path), src)
        except FracasError:
            pass
        return kind, list(exc.problems)
    return name, mode(name).problems(deck)


def validate_path(path: str | Path) -> list[str]:
    """Every problem of the deck at ``path`` (any mode), one line each; [] if it is valid."""
    return check_path(path)[1]
