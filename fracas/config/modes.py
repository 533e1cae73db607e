"""Which mode a deck asks for (its ``mode`` line) and the validated deck of that mode.

``mode = "team"`` (TEAM covariance analysis), ``mode = "sweep"`` (a TEAM study run with
fields varied, :mod:`fracas.config.sweep`), ``mode = "tom"`` (TOM targeting and
optimization, :mod:`fracas.config.tom`), ``mode = "tsim"`` (TSIM Monte Carlo,
:mod:`fracas.config.tsim`), ``mode = "rendezvous"`` (two-vehicle navigation,
:mod:`fracas.config.rendezvous`) or ``mode = "propagate"`` (a trajectory deck; the
default, so every trajectory deck stays valid as written).  TEAM
decks written before ``mode`` existed are still recognised by their ``[ertraj]`` table.
"""

from __future__ import annotations

from pathlib import Path

from fracas.config.trajectory import cut, load_toml
from fracas.errors import DeckError

__all__ = ["MODES", "PLANNED_MODES", "deck_mode", "parse_any", "load_any"]

MODES = ("propagate", "team", "sweep", "tom", "tsim", "rendezvous")
PLANNED_MODES: tuple[str, ...] = ()


def deck_mode(text: str, source: str = "<deck>") -> str:
    """The mode of deck text: its ``mode`` value, else "team" for a legacy TEAM deck (an
    [ertraj] table), else "propagate".  DeckError for a TOML error or an unknown mode."""
    data = load_toml(text, source)
    mode = data.get("mode")
    if mode is None:
        return "team" if "ertraj" in data else "propagate"
    if isinstance(mode, str) and mode in MODES:
        return mode
    if isinstance(mode, str) and mode in PLANNED_MODES:
        raise DeckError(
            f'{source}: mode = "{mode}": not available in this release (expected one of: {", ".join(MODES)})'
        )
    raise DeckError(f"{source}: mode = {cut(repr(mode))}: unknown mode (expected one of: {', '.join(MODES)})")


def parse_any(text: str, source: str = "<deck>"):
    """The validated deck of whatever mode ``text`` asks for (TrajectoryDeck, TeamDeck or SweepDeck)."""
    mode = deck_mode(text, source)
    if mode == "sweep":
        from fracas.config.sweep import parse_sweep_deck

        return parse_sweep_deck(text, source)
    if mode == "tom":
        from fracas.config.tom import parse_tom_deck

        return parse_tom_deck(text, source)
    if mode == "tsim":
        from fracas.config.tsim import parse_tsim_deck

        return parse_tsim_deck(text, source)
    if mode == "rendezvous":
        from fracas.config.rendezvous import parse_rendezvous_deck

        return parse_rendezvous_deck(text, source)
    if mode == "team":
        from fracas.config.team import parse_team_deck

        return parse_team_deck(text, source)
    from fracas.config.trajectory import parse_deck

    return parse_deck(text, source)


def load_any(path: str | Path):
    """Read and validate a deck of any mode; every failure is a one-line DeckError."""
    from fracas.config.trajectory import read_deck_text

    return parse_any(read_deck_text(path), str(path))
