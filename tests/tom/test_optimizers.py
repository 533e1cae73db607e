"""The projected-gradient optimum against a second optimizer (SciPy's SLSQP on the same
scaled problem with the same AD derivatives) and against the analytic optimum, on the
LEO -> GEO two-impulse transfer (``tests/data/hohmann_tom.toml``).

Reference: Hohmann's transfer is the two-impulse optimum between coplanar circular orbits
with r1/r0 = 6.31 < 11.94 (e.g. Vallado, *Fundamentals of Astrodynamics*, §6.3):
dV1 = sqrt(mu/r0)(sqrt(2 r1/(r0 + r1)) - 1), dV2 = sqrt(mu/r1)(1 - sqrt(2 r0/(r0 + r1))),
m_f = m_0 exp(-(dV1 + dV2)/c) = 273.2088 kg with c = 3 km/s (digest V2).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from fracas.config.tom import parse_tom_deck
from fracas.modes.tom import run_tom

ROOT = Path(__file__).resolve().parents[2]
DECK = ROOT / "tests" / "data" / "hohmann_tom.toml"
MU, R0, R1, C = 398600.4418, 6678.137, 42164.17, 3.0


def _hohmann_mass():
    dv1 = math.sqrt(MU / R0) * (math.sqrt(2 * R1 / (R0 + R1)) - 1)
    dv2 = math.sqrt(MU / R1) * (1 - math.sqrt(2 * R0 / (R0 + R1)))
    return 1000.0 * math.exp(-(dv1 + dv2) / C), dv1, dv2


def _run(tmp_path, optimizer):
    text = DECK.read_text(encoding="utf-8").replace("[tom]\n", f'[tom]\noptimizer = "{optimizer}"\n')
    cfg = parse_tom_deck(text, str(DECK))
    prod, _, _ = run_tom(cfg, output=tmp_path / f"{optimizer}.h5", reference_deck=tmp_path / f"{optimizer}.toml")
    return prod


@pytest.mark.slow
def test_projected_gradient_matches_slsqp_and_hohmann(tmp_path):
    """Final masses within 0.1 % of each other (the issue's bound) and, both, within 1e-5 of
    Hohmann's (each stops at its own first-order test: theta < 1e-3 rad for the projected
    gradient; the mass is flat there, dm ~ theta^2); targets within tolerance on
    re-propagation; neither beats Hohmann beyond what the target tolerances allow (1e-5)."""
    m_h, dv1, dv2 = _hohmann_mass()
    assert abs(m_h - 273.2088) < 1e-4
    pg = _run(tmp_path, "projected_gradient")
    sq = _run(tmp_path, "slsqp")
    for prod in (pg, sq):
        assert prod.targets_met, prod.stop_reason
        assert np.all(np.abs(prod.target_error) <= prod.tolerance)
        assert abs(prod.final_mass_kg / m_h - 1.0) < 1e-5, (prod.optimizer, prod.final_mass_kg, m_h)
    assert pg.converged, pg.stop_reason
    assert abs(pg.final_mass_kg / sq.final_mass_kg - 1.0) < 1e-3
    # the projected-gradient answer is Hohmann's: tangential impulses of the right size
    dv_1 = np.hypot(pg.u_final[0], pg.u_final[1])
    dv_2 = np.hypot(pg.u_final[2], pg.u_final[3])
    assert abs(dv_1 - dv1) < 1e-3 and abs(dv_2 - dv2) < 1e-3
