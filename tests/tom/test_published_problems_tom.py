"""TOM from a natural first guess on two published low-thrust problems, against the published
optimum and an independent indirect solution (tests/tom/published_problems.py: SciPy only), and
the written reference deck re-integrated by SciPy's DOP853 from the plain equations.

* Bryson & Ho's maximum-radius transfer (Applied Optimal Control, 1975, sec. 2.5; 193 days):
  published r_f = 1.525 r0; indirect (this repository, solve_bvp + shooting) 1.5252777 r0.
* Taheri, Kolmanovsky & Atkins's Earth-to-Mars minimum-propellant rendezvous (JGCD 39(11),
  2016; 348.795 days, 0.5 N, 2000 s): published m_f = 603.94 kg (g0 = 9.80665 m/s^2; 603.935 kg
  in Tafazzol & Taheri 2024 with g0 = 9.8065); indirect (this repository) 603.940156 kg.

Both decks (namelists/) give no burn structure and no pointing: [tom.first_guess] starts from 24
segments at half throttle (Earth-Mars) or full thrust (Bryson & Ho) along the velocity.

Measured (2026-12-03, 2 cores, benchmarks/bench_tom_published.py: a fresh process with an empty
compilation cache each):
  Bryson & Ho: 1.52517 r0, 7.0e-5 below the indirect optimum (four cubic pointing arcs for a
    thrust angle that turns 290 deg), 1.1e-4 above the published 1.525; first guess 24 segments
    along the velocity, 74 + 3 + 26 iterations (pass 1, targeting, pass 2), 24 s cold, 17 s warm;
  Earth-Mars: 603.93993 kg, 3.7e-7 below the indirect optimum, 1.1e-7 below the published 603.94;
    first guess 24 segments at half throttle along the velocity, 41 + 4 + 26..28 iterations,
    21 s cold, 11 s warm.
Tolerances: the issue's goal is 0.1 % of the published optimum.  The assertions hold TOM to 1e-3 of
the published figure and of the indirect optimum, from below only up to 1e-6 above (TOM's
parametrization cannot beat the continuous-control optimum: a figure above it means a bug).  The
re-integration holds the targets to their deck tolerances (10 km, 1 cm/s; e components 1e-7) with
SciPy at rtol 1e-12, whose own error is ~1e-3 km over these flights.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np
import pytest
import tomllib
from click.testing import CliRunner
from scipy.integrate import solve_ivp

from fracas.cli import main
from fracas.io.tom_results import read_tom_results
from tests.tom import published_problems as pub

ROOT = Path(__file__).resolve().parents[2]
DAY = 86400.0


def _run(tmp_path, name: str):
    deck = ROOT / "namelists" / f"{name}.toml"
    out = tmp_path / f"{name}.h5"
    ref = tmp_path / f"{name}_reference.toml"
    t0 = time.perf_counter()
    r = CliRunner().invoke(main, ["run", str(deck), "-o", str(out), "--reference-deck", str(ref)])
    wall = time.perf_counter() - t0
    assert r.exit_code == 0, r.output
    res = read_tom_results(out)
    print(f"\n{name}: {res['attrs']['stop_reason']}\n  {len(res['iteration'])} iterations (pass 2), {wall:.1f} s")
    return res, ref, wall


def _legendre(s: float, coeffs) -> float:
    p = (s, 0.5 * (3 * s * s - 1), 0.5 * (5 * s**3 - 3 * s))
    return sum(c * q for c, q in zip(coeffs, p))


def _reintegrate(ref_path: Path) -> np.ndarray:
    """The reference deck flown by SciPy DOP853 (rtol 1e-12) from the plain equations: Sun point
    mass, constant thrust T = 2 eta P / c along the velocity-frame pointing law of each arc
    (alpha, beta plus the Legendre series in the arc's normalised time), mdot = -T/c."""
    deck = tomllib.loads(ref_path.read_text(encoding="utf-8"))
    mu = deck["forces"]["overrides"]["sun"]["mu_km3_s2"]
    prop = deck["propulsion"]
    c = prop["exhaust_velocity_km_s"]
    thrust = 2e-3 * prop.get("efficiency", 1.0) * prop["power_kw"] / c * prop.get("thrust_scale", 1.0)
    arcs = deck.get("thrust_arc", [])
    st = deck["initial_state"]["cartesian"]
    y0 = np.array([*st["r_km"], *st["v_km_s"], deck["spacecraft"]["mass_kg"]], float)

    def rhs_for(arc):
        def rhs(t, y):
            r, v, m = y[:3], y[3:6], y[6]
            a = -mu * r / np.linalg.norm(r) ** 3
            if arc is None:
                return np.concatenate([v, a, [0.0]])
            t0, t1 = arc["start_days"] * DAY, arc["stop_days"] * DAY
            s = (2 * t - t0 - t1) / (t1 - t0)
            al = math.radians(arc.get("alpha_deg", 0.0) + _legendre(s, arc.get("alpha_legendre_deg", [])))
            be = math.radians(arc.get("beta_deg", 0.0) + _legendre(s, arc.get("beta_legendre_deg", [])))
            h = np.cross(r, v)
            x, z = v / np.linalg.norm(v), h / np.linalg.norm(h)
            u = math.cos(be) * math.cos(al) * x + math.cos(be) * math.sin(al) * np.cross(z, x) + math.sin(be) * z
            f = thrust * arc.get("throttle", 1.0)
            return np.concatenate([v, a + f / m * u, [-f / c]])

        return rhs

    pieces, t = [], 0.0
    for arc in arcs:
        pieces += [(t, arc["start_days"] * DAY, None), (arc["start_days"] * DAY, arc["stop_days"] * DAY, arc)]
        t = arc["stop_days"] * DAY
    pieces.append((t, deck["stop"]["duration_days"] * DAY, None))
    y = y0
    for ta, tb, arc in pieces:
        if tb > ta:
            sol = solve_ivp(rhs_for(arc), (ta, tb), y, method="DOP853", rtol=1e-12, atol=1e-9)
            assert sol.success
            y = sol.y[:, -1]
    return y


@pytest.mark.slow  # each run compiles its own programs (~1 min cold)
def test_bryson_ho_maximum_radius_from_a_natural_start(tmp_path):
    res, ref, wall = _run(tmp_path, "bryson_ho_tom")
    assert res["attrs"]["converged"] == 1, res["attrs"]["stop_reason"]
    au = 149_597_870.7
    r_f = res["performance_final"] / au
    indirect = pub.bryson_ho_indirect().r_f
    print(f"  r_f {r_f:.7f} r0; indirect {indirect:.7f}; published {pub.BRYSON_HO_PUBLISHED_RF}")
    assert abs(r_f / pub.BRYSON_HO_PUBLISHED_RF - 1.0) < 1e-3
    assert -1e-3 < r_f / indirect - 1.0 < 1e-6
    y = _reintegrate(ref)
    r, v = y[:3], y[3:6]
    mu = 132712440018.0
    e_vec = np.cross(v, np.cross(r, v)) / mu - r / np.linalg.norm(r)
    assert np.linalg.norm(e_vec) < math.sqrt(2) * 1e-7  # both e components within 1e-7
    assert abs(np.linalg.norm(r) - res["performance_final"]) < 1.0  # km: the same trajectory
    assert wall < 300.0  # the goal is cold; the slow-suite log shows the figure


@pytest.mark.slow  # each run compiles its own programs (~1 min cold)
def test_earth_mars_rendezvous_from_a_natural_start(tmp_path):
    res, ref, wall = _run(tmp_path, "earth_mars_rendezvous_tom")
    assert res["attrs"]["converged"] == 1, res["attrs"]["stop_reason"]
    m_f = res["final_mass_kg"]
    indirect = pub.earth_mars_indirect(z0=np.array(pub.EARTH_MARS_COSTATES0)).m_f_kg
    print(f"  m_f {m_f:.6f} kg; indirect {indirect:.6f} kg; published 603.94 (g0 9.80665) / 603.935 (g0 9.8065)")
    assert abs(m_f / 603.94 - 1.0) < 1e-3
    assert -1e-3 < m_f / indirect - 1.0 < 1e-6
    y = _reintegrate(ref)
    d = pub.EARTH_MARS
    assert np.all(np.abs(y[:3] - np.array(d["rf_km"])) <= 10.0), y[:3] - np.array(d["rf_km"])
    assert np.all(np.abs(y[3:6] - np.array(d["vf_km_s"])) <= 1e-5), y[3:6] - np.array(d["vf_km_s"])
    assert abs(y[6] - m_f) < 1e-3  # kg: the same trajectory
    assert wall < 300.0
