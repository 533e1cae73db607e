"""The mode registry (:mod:`fracas.modes`): every mode declared once, and a new mode added by
one package plus one registry line (the toy mode of :mod:`tests.modes.toy`, driven through
``load_any``, ``fracas run``, ``validate``, ``report`` and ``sweep``).

References: the toy's period against Kepler's third law, T = 2 pi sqrt(a^3 / mu), written
here (a = 7000 km, mu = 398600.4418 km^3/s^2: 5828.516 s, to the printed 1e-3 s); the
bundled decks' ``mode`` lines; the command line's own messages.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import pytest
from click.testing import CliRunner

from fracas import modes
from fracas.cli import main
from fracas.errors import DeckError
from fracas.modes.base import RUN_OPTION_FLAGS

ROOT = Path(__file__).resolve().parents[2]
TOY_DECK = 'mode = "toy"\ntitle = "a circular orbit"\n[orbit]\nradius_km = 7000.0\n'


@pytest.fixture
def toy(monkeypatch):
    """The one registry line that adds the toy mode."""
    monkeypatch.setitem(modes.REGISTRY, "toy", "tests.modes.toy:MODE")


def _cli(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def test_every_registered_mode_declares_itself_once():
    """Each registry line names a Mode of its own name; no results-file kind belongs to two
    modes; the run options a mode takes are ones the command line has."""
    seen: dict[str, str] = {}
    for name in modes.REGISTRY:
        m = modes.mode(name)
        assert m.name == name and m.noun and m.summary
        for kind in m.results_kinds:
            assert kind not in seen, f"{kind!r} is claimed by {seen[kind]} and {name}"
            seen[kind] = name
        assert m.run_options <= set(RUN_OPTION_FLAGS)
    assert modes.MODES == ("propagate", "team", "sweep", "tom", "tsim", "rendezvous")


def test_every_bundled_deck_names_a_registered_mode():
    """The bundled decks' ``mode`` lines (read here with a regular expression, not the parser)
    are registry names, and the registry reads each deck as that mode."""
    for deck in sorted((ROOT / "namelists").glob("*.toml")):
        text = deck.read_text(encoding="utf-8")
        m = re.search(r'(?m)^mode\s*=\s*"(\w+)"', text)
        expected = m.group(1) if m else ("team" if re.search(r"(?m)^\[ertraj\]", text) else "propagate")
        assert modes.deck_mode(text, str(deck)) == expected, deck
        assert modes.mode_of_deck(deck).name == expected


def test_unknown_mode_lists_the_registry():
    with pytest.raises(DeckError, match=r"mode = 'toy': unknown mode \(expected one of: propagate, team, sweep"):
        modes.deck_mode(TOY_DECK, "x.toml")


def test_a_toy_mode_is_one_package_and_one_registry_line(toy, tmp_path):
    """With the toy's registry line: load_any gives its deck, ``fracas validate`` runs its
    checks, ``fracas run`` its orchestrator and ``fracas report`` its report; nothing else in
    fracas knows the toy."""
    from tests.modes.toy import ToyDeck, read_toy_results

    deck = tmp_path / "toy.toml"
    deck.write_text(TOY_DECK, encoding="utf-8")
    cfg = modes.load_any(deck)
    assert isinstance(cfg, ToyDeck) and cfg.orbit.radius_km == 7000.0

    r = _cli("validate", deck)
    assert r.exit_code == 0 and f"ok: {deck} (toy)" in r.output, r.output

    out = tmp_path / "toy.h5"
    r = _cli("run", deck, "-o", out)
    assert r.exit_code == 0, r.output
    kepler_s = 2.0 * math.pi * math.sqrt(7000.0**3 / 398600.4418)
    assert abs(kepler_s - 5828.516) < 1e-3  # the figure in the module docstring
    assert read_toy_results(out) == pytest.approx(kepler_s, rel=1e-15)  # same formula, same float64
    assert f"period {kepler_s:.3f} s" in r.output

    r = _cli("report", out)
    assert r.exit_code == 0 and f"toy results file: {out}: period {kepler_s:.3f} s" in r.output, r.output


def test_the_toy_refuses_what_it_does_not_take(toy, tmp_path):
    """Options the toy does not declare, its own validation check, and sweeps (it is not a
    sweep study): each a one-line error from the generic command line."""
    deck = tmp_path / "toy.toml"
    deck.write_text(TOY_DECK, encoding="utf-8")
    r = _cli("run", deck, "--stm", tmp_path / "x.h5")
    assert r.exit_code == 2
    assert '--stm is for TEAM decks (mode = "team"), not for toy decks' in " ".join(r.output.split())

    low = tmp_path / "low.toml"
    low.write_text(TOY_DECK.replace("7000.0", "6000.0"), encoding="utf-8")
    r = _cli("validate", low)
    assert r.exit_code == 2 and "orbit.radius_km: inside the Earth" in r.output

    r = _cli("sweep", deck, "--vary", "orbit.radius_km=7000,8000", "--workers", "0")
    assert r.exit_code == 2 and 'not mode = "toy"' in " ".join(r.output.split()), r.output


def test_without_its_line_the_toy_is_unknown(tmp_path):
    deck = tmp_path / "toy.toml"
    deck.write_text(TOY_DECK, encoding="utf-8")
    r = _cli("run", deck)
    assert r.exit_code == 2 and "unknown mode" in r.output
