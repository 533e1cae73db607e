"""The deck's [integrator] section: methods, step control and their refusals (each a one-line
DeckError naming the file, the field and what was expected), and the settings the core gets."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from fracas.build import build_propagation
from fracas.config.trajectory import parse_deck
from fracas.errors import DeckError

ROOT = Path(__file__).resolve().parents[2]
LEO = (ROOT / "namelists" / "leo_j2.toml").read_text()
SPIRAL = (ROOT / "namelists" / "near_earth_spiral.toml").read_text()


def _with_integrator(text: str, body: str) -> str:
    head, rest = text.split("[integrator]\n", 1)
    tail = rest[rest.index("\n[") :]
    return head + "[integrator]\n" + body + "\n" + tail


def _settings(text: str):
    return build_propagation(parse_deck(text, "d.toml")).model.integrator


def test_auto_picks_dprkn12_without_thrust_and_dop853_with_thrust():
    """The default: tolerance control, Cowell, DPRKN12 (special RKN: acceleration independent of
    velocity and mass) without thrust, DOP853 with thrust arcs; no step limit."""
    ig = _settings(_with_integrator(LEO, ""))
    assert (ig.method, ig.formulation, ig.step_control, ig.tolerance) == ("dprkn12", "cowell", "tolerance", 1e-12)
    assert ig.dt_max_s == math.inf
    ig = _settings(_with_integrator(SPIRAL, "tolerance = 1e-10"))
    assert (ig.method, ig.formulation, ig.step_control, ig.tolerance) == ("dop853", "cowell", "tolerance", 1e-10)


def test_c_nom_keeps_fracas_integrator():
    """A deck that sets c_nom (every pre-tolerance deck) keeps FRACAS's Encke + RKN4 with the
    c_nom rule and its 4000 s step limit (Doc. 4)."""
    ig = _settings(_with_integrator(LEO, "c_nom = 0.05"))
    assert (ig.method, ig.formulation, ig.step_control, ig.c_nom, ig.dt_max_s) == (
        "rkn4",
        "encke",
        "c_nom",
        0.05,
        4000.0,
    )
    ig = _settings(_with_integrator(LEO, 'method = "dprkn12"\nformulation = "encke"\nstep_control = "c_nom"'))
    assert (ig.method, ig.formulation, ig.step_control) == ("dprkn12", "encke", "c_nom")


@pytest.mark.parametrize(
    "deck,body,field,expected",
    [
        (SPIRAL, 'method = "dprkn12"', "integrator.method", "independent of velocity and mass"),
        (LEO, 'method = "rkn4"\nstep_control = "tolerance"', "integrator.step_control", "no embedded error"),
        (LEO, 'step_control = "tolerance"\nc_nom = 0.1', "integrator.c_nom", "applies only with"),
        (LEO, "c_nom = 0.1\ntolerance = 1e-9", "integrator.tolerance", "applies only with"),
        (LEO, "tolerance = 1e-20", "integrator.tolerance", ""),
        (LEO, 'method = "rk45"', "integrator.method", ""),
    ],
)
def test_refusals_name_the_field(deck, body, field, expected):
    """A special RKN method with thrust, rkn4 under tolerance control, c_nom under tolerance
    control, a tolerance under the c_nom rule, out-of-range and unknown values."""
    with pytest.raises(DeckError) as info:
        parse_deck(_with_integrator(deck, body), "d.toml")
    msg = str(info.value)
    assert msg.startswith("d.toml: ") and field in msg and expected in msg, msg
    assert "\n" not in msg.strip()  # one line
