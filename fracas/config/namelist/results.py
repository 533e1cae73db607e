"""What an import returns (:class:`ImportResult`, :class:`Unmapped`) and the small text forms
shared by the reader and the writer: a namelist value as a deck shows it (:func:`_show`), a TOML
path as text (:func:`_loc_text`) and the ``source: $GROUP.NAME(j,k)`` head of an error line
(:func:`_where`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from fracas.config.trajectory import cut


@dataclass(frozen=True)
class Unmapped:
    """A namelist field the import could not map: ``$NAMELIST.NAME = value: reason``."""

    namelist: str
    name: str
    value: Any
    reason: str

    def __str__(self) -> str:
        if self.namelist == "-":  # text outside any group
            return f"{self.name}: {cut(_show(self.value), 40)}: {self.reason}"
        return f"${self.namelist}.{self.name} = {cut(_show(self.value), 40)}: {self.reason}"


@dataclass
class ImportResult:
    """The TOML deck written from a namelist deck.

    ``toml``: the main deck's text; ``mode``: its mode; ``companions``: file name (relative to
    the main deck) -> TOML text of a sub-deck it names; ``unmapped``: every field not mapped;
    ``notes``: conversions applied and defaults assumed; ``mapped``: how many fields mapped;
    ``decks``: part ("traj", "team", "tom", "tsim") -> the TOML data written for it."""

    toml: str
    mode: str
    companions: dict[str, str] = field(default_factory=dict)
    unmapped: list[Unmapped] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    mapped: int = 0
    decks: dict[str, dict] = field(default_factory=dict)


def _show(v: Any) -> str:
    if isinstance(v, bool):
        return ".TRUE." if v else ".FALSE."
    if isinstance(v, str):
        return repr(v)
    if isinstance(v, list):
        return ", ".join(_show(x) for x in v)
    if isinstance(v, dict):
        return "{" + ", ".join(v) + "}"
    return str(v)


def _loc_text(path: tuple) -> str:
    """A TOML path as text: ``a.b[2].c``."""
    out = ""
    for p in path:
        out += f"[{p}]" if isinstance(p, int) else (("." if out else "") + str(p))
    return out


def _where(src: str, group: str, name: str, k: int | None = None, j: int | None = None) -> str:
    """``src: $GROUP.NAME``, ``NAME(k)`` or ``NAME(j,k)``: the head of an error line."""
    idx = "" if k is None else (f"({k})" if j is None else f"({j},{k})")
    return f"{src}: ${group}.{name}{idx}"
