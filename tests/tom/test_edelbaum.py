"""Low-thrust TOM against Edelbaum's circle-to-circle transfer (Edelbaum 1961, ARS Journal
31(8), "Propulsion requirements for controllable satellites"; digest tom-tsim-guidance.md V3/V4).

The deck ``namelists/near_earth_spiral_tom.toml``: 7000 -> 9000 km, 13 N on 1000 kg
(c = 30 km/s), yaw angle constant on each of two arcs with its sign switched at the
antinodes, the end of thrusting free; targets a (0.1 km) and i (1e-4 deg); maximize m_f.

* Coplanar (target i unchanged): Edelbaum's dV = v0 - v1, within 1 %.  The optimizer must
  also find that any yaw wastes propellant (|beta| -> 0).
* 2 deg plane change: Edelbaum's dV = sqrt(v0^2 - 2 v0 v1 cos(pi di / 2) + v1^2) = 0.97208
  km/s, within 3 %.  Why 3 % holds with room: Edelbaum's result is the optimum of the
  orbit-averaged problem with continuously varying yaw (v sin beta = const); two constant
  yaw arcs cost 0.012 % more in that averaged model (for a single constant yaw:
  Delta i = (2/pi) tan(beta) ln(v0/v1) gives dV = (v0 - v1)/cos(beta) = 0.97220 km/s), and
  the departure from averaging at a thrust/gravity ratio of 1.6e-3 is of the same order;
  3 % (the issue's bound) also admits a local optimum of the two-arc parametrization.  The
  non-averaged optimum may beat the averaged one slightly, so the lower bound is -1 %.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from fracas.config.tom import parse_tom_deck
from fracas.modes.tom import run_tom

pytestmark = pytest.mark.slow  # DOP853 with thrust: the AD program compiles in ~40 s cold

ROOT = Path(__file__).resolve().parents[2]
DECK = ROOT / "namelists" / "near_earth_spiral_tom.toml"
MU = 398600.4418  # the Earth's GM in fracas's constants (EGM/DE421 value)
C = 30.0
V0, V1 = math.sqrt(MU / 7000.0), math.sqrt(MU / 9000.0)


def _run(tmp_path, text):
    cfg = parse_tom_deck(text, str(DECK))
    prod, _, _ = run_tom(cfg, output=tmp_path / "s.h5", reference_deck=tmp_path / "s.toml")
    assert prod.converged, prod.stop_reason
    return prod, C * math.log(1000.0 / prod.final_mass_kg)


def test_coplanar_spiral_dv_within_1_percent_of_edelbaum(tmp_path):
    text = DECK.read_text(encoding="utf-8").replace("value = 26.5", "value = 28.5")
    prod, dv = _run(tmp_path, text)
    assert abs(dv / (V0 - V1) - 1.0) < 0.01, (dv, V0 - V1)
    # yaw buys nothing without a plane change: the optimizer removed it (deg)
    assert np.all(np.abs(prod.u_final[1:]) < 1.0), prod.u_final


def test_plane_change_spiral_dv_within_3_percent_of_edelbaum(tmp_path):
    prod, dv = _run(tmp_path, DECK.read_text(encoding="utf-8"))
    di = math.radians(2.0)
    edelbaum = math.sqrt(V0**2 - 2 * V0 * V1 * math.cos(math.pi * di / 2) + V1**2)
    assert abs(edelbaum - 0.97208) < 5e-5  # the digest's number for this transfer
    assert -0.01 < dv / edelbaum - 1.0 < 0.03, (dv, edelbaum)
    # the achieved plane change (targets within tolerance) and yaw of Edelbaum's size (~22-25 deg)
    assert abs(prod.achieved[1] - 26.5) <= 1e-4
    assert np.all((-30.0 < prod.u_final[1:]) & (prod.u_final[1:] < -18.0)), prod.u_final
