"""Backward propagation from a deck (final time before the epoch), end to end through
load -> build -> propagate.

References, none produced by this code: scipy ``solve_ivp`` DOP853 (rtol 1e-12, atol 1e-9)
on the plain two-body + J2 equations written out below and integrated backward; the deck's
own initial state (forward then backward returns to it); the rocket equation and the
constant-power mass flow for the mass; Kepler's equation for the time a backward
propagation reaches a radius.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from fracas.build import build_propagation
from fracas.config.trajectory import parse_deck
from fracas.integrate.propagate import propagate

DAY = 86400.0
MU, J2, RE = 398600.4418, 1.08262668e-3, 6378.137
R0, V0 = [7000.0, 0.0, 0.0], [0.0, 7.5, 1.0]
EARTH = f"""
[forces]
j2 = true
[forces.overrides.earth]
mu_km3_s2 = {MU}
j2 = {J2}
radius_km = {RE}
[integrator]
c_nom = 0.03
"""


def _deck(stop: str, r=R0, v=V0, m=1000.0, iso="2030-01-02T00:00:00", extra=""):
    return parse_deck(
        f"""
[epoch]
iso = "{iso}"
[initial_state]
centre = "earth"
[initial_state.cartesian]
r_km = {list(r)}
v_km_s = {list(v)}
[spacecraft]
mass_kg = {m}
{EARTH}
{extra}
[stop]
{stop}
""",
        "d.toml",
    )


def _run(deck):
    prob = build_propagation(deck)
    tr = propagate(prob.model, prob.params, prob.ephem, prob.epoch_et_s, prob.x0, prob.t_out)
    return prob, tr


def _dop853_backward(pole, t_eval):
    """Plain equations (two-body + J2 about ``pole``) integrated backward by DOP853."""

    def rhs(t, y):
        r, v = y[:3], y[3:]
        rn = np.linalg.norm(r)
        s = r @ pole / rn
        a = -MU * r / rn**3 - 1.5 * J2 * MU * RE**2 / rn**4 * ((1 - 5 * s * s) * r / rn + 2 * s * pole)
        return np.concatenate([v, a])

    sol = solve_ivp(rhs, (0.0, t_eval[-1]), np.array(R0 + V0), method="DOP853", rtol=1e-12, atol=1e-9, t_eval=t_eval)
    assert sol.success
    return sol.y.T


def test_leo_j2_one_day_backward_matches_dop853():
    """duration_days = -1 with 6 h outputs: every output within 1 m of DOP853 run backward
    (the forward LEO test's tolerance, tests/integrate/test_encke_leo.py)."""
    prob, tr = _run(_deck("duration_days = -1.0", extra="[output]\nstep_days = 0.25\n"))
    t = np.asarray(tr.t)
    np.testing.assert_allclose(t, -DAY * np.array([0.0, 0.25, 0.5, 0.75, 1.0]), atol=1e-6)
    assert int(tr.status) == 0
    pole = np.asarray(prob.params.pole[prob.model.primary], dtype=float)
    ref = _dop853_backward(pole, np.asarray(prob.t_out))
    err_m = np.linalg.norm(np.asarray(tr.x[:, :3]) - ref[:, :3], axis=1) * 1e3
    assert err_m.max() < 1.0, err_m
    assert np.linalg.norm(np.asarray(tr.x[-1, 3:6]) - ref[-1, 3:]) * 1e3 < 1e-3  # m/s
    assert float(tr.x_final[6]) == 1000.0


def test_forward_then_backward_returns_to_the_initial_state():
    """Thrust arc, a velocity-frame impulse and J2: forward 1 d, then a backward deck from the
    final state (epoch one day later, arcs and impulse at the same instants) returns to the
    deck's initial state within 2 m and 2 mm/s (twice the 1 m one-way tolerance), and to the
    initial mass within 1e-9 kg.  The forward mass agrees with the rocket equation and the
    constant nuclear-power mass flow (T = 2 eta P / c, mdot = T / c)."""
    prop = """
[propulsion]
power_source = "nuclear"
power_kw = 10.0
efficiency = 0.65
exhaust_velocity_km_s = 30.0
"""
    fwd_extra = (
        prop
        + "[[thrust_arc]]\nstart_days = 0.2\nstop_days = 0.5\n"
        + "[[impulse]]\ntime_days = 0.7\ndv_km_s = [0.05, 0.01, 0.0]\nisp_s = 300.0\n"
    )
    _, fwd = _run(_deck("duration_days = 1.0", iso="2030-01-01T00:00:00", extra=fwd_extra))
    xf = np.asarray(fwd.x_final)
    mdot = 2 * 0.65 * 10.0e3 / 30.0e3**2  # kg/s: 2 eta P / c^2 in W and m/s
    m_arc = 1000.0 - mdot * 0.3 * DAY
    m_want = m_arc * math.exp(-math.hypot(0.05, 0.01) / (300.0 * 9.80665e-3))
    assert abs(xf[6] - m_want) < 1e-6, (xf[6], m_want)
    back_extra = (
        prop
        + "[[thrust_arc]]\nstart_days = -0.8\nstop_days = -0.5\n"
        + "[[impulse]]\ntime_days = -0.3\ndv_km_s = [0.05, 0.01, 0.0]\nisp_s = 300.0\n"
    )
    deck = _deck("duration_days = -1.0", r=xf[:3].tolist(), v=xf[3:6].tolist(), m=float(xf[6]), extra=back_extra)
    _, back = _run(deck)
    xb = np.asarray(back.x_final)
    assert int(back.status) == 0
    assert abs(float(back.t_final) + DAY) < 1e-6
    dr_m = np.linalg.norm(xb[:3] - R0) * 1e3
    dv_mm_s = np.linalg.norm(xb[3:6] - V0) * 1e6
    assert dr_m < 2.0 and dv_mm_s < 2.0, (dr_m, dv_mm_s)
    assert abs(xb[6] - 1000.0) < 1e-9


@pytest.mark.slow  # ~22 s of a cold make test (mostly XLA compilation; issue 22)
def test_backward_radius_stop_at_the_kepler_time():
    """Two-body ellipse (a = 10000 km, e = 0.2) from M = 90 deg backward to r = 9000 km:
    stops where Kepler's equation puts it, E = 60 deg (time within 1 ms, radius within 1 mm)."""
    a, e = 10000.0, 0.2
    text = f"""
[epoch]
iso = "2030-01-01T00:00:00"
[initial_state]
centre = "earth"
[initial_state.elements]
a_km = {a}
e = {e}
i_deg = 30.0
raan_deg = 10.0
argp_deg = 20.0
mean_anomaly_deg = 90.0
[spacecraft]
mass_kg = 1000.0
[forces.overrides.earth]
mu_km3_s2 = {MU}
[integrator]
c_nom = 0.03
[stop]
duration_days = -1.0
condition = "radius"
body = "earth"
radius_km = 9000.0
"""
    _, tr = _run(parse_deck(text, "d.toml"))
    assert int(tr.status) == 1
    n = math.sqrt(MU / a**3)
    big_e = math.radians(60.0)
    t_want = ((big_e - e * math.sin(big_e)) - math.pi / 2) / n
    assert abs(float(tr.t_final) - t_want) < 1e-3, (float(tr.t_final), t_want)
    assert abs(np.linalg.norm(np.asarray(tr.x_final[:3])) - 9000.0) < 1e-6


@pytest.mark.parametrize("days", [-0.5])
def test_backward_outputs_decrease_and_end_at_the_final_time(days):
    _, tr = _run(_deck(f"duration_days = {days}", extra="[output]\ntimes_days = [-0.1, -0.3]\n"))
    t = np.asarray(tr.t)
    np.testing.assert_allclose(t, [0.0, -0.1 * DAY, -0.3 * DAY, days * DAY], atol=1e-6)
