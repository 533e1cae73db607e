"""Validated, frozen configuration (pydantic; no JAX): decks as the user writes them."""

from fracas.config.trajectory import TrajectoryDeck, load_deck, parse_deck

__all__ = ["TrajectoryDeck", "load_deck", "parse_deck"]
