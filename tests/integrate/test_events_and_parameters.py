"""Impulses, radius stops, leaving a sphere of influence, nuclear power, and the sensitivities
that need an ephemeris (Cr, GMs of third bodies, conic elements of an EPHEM body), each
against an independent reference: DOP853 on the plain equations (tests/reference.py) or
central finite differences (FRACAS PTRAN)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from fracas import constants as C
from fracas.dynamics.ephemeris import build_ephemeris, calendar_to_et
from fracas.dynamics.model import ForceModel, StopCondition, default_params
from fracas.integrate.propagate import finite_difference_sensitivities, propagate, propagate_with_sensitivities
from tests.integrate.methods import KINDS, KINDS_NO_ENCKE, integrator
from tests.reference import cowell_rhs_factory, helio_position, helio_velocity, integrate_piecewise

MU = 398600.4418
X0 = np.array([7000.0, 0.0, 0.0, 0.0, 7.5, 1.0, 1000.0])
DAY = 86400.0
ET0 = calendar_to_et("2031-03-01T00:00:00")


@pytest.mark.parametrize("kind", KINDS)
def test_impulses_in_both_frames(kind):
    """Two impulses (velocity frame at 2000 s, inertial at 4000 s, Isp 320 s): the state after
    6000 s matches DOP853 restarted with v += dV at the same times to 1 mm (with no
    perturbation Encke reproduces the conic exactly, so only roundoff and the reference's own
    ~1e-8 km error remain), backward through the impulses returns to the start to 1 mm, and the
    mass follows the rocket equation to 1e-12 relative.  For every kind (tests/integrate/methods.py);
    dprkn12 at tol 1e-12 stays far inside 1 mm for Cowell too."""
    m = ForceModel(bodies=("earth",), n_impulses=2, integrator=integrator(kind, c_nom=0.02))
    dv_vel = np.array([0.05, 0.01, -0.02])
    dv_in = np.array([-0.01, 0.03, 0.02])
    p = default_params(
        m,
        mu=[MU],
        impulse_t=[2000.0, 4000.0],
        impulse_dv=[dv_vel, dv_in],
        impulse_frame=[0.0, 1.0],
        impulse_isp_s=320.0,
    )
    tr = propagate(m, p, None, 0.0, X0, np.array([0.0, 6000.0]))
    rhs = cowell_rhs_factory(MU, primary="earth")
    y = integrate_piecewise(rhs, X0, [0.0, 2000.0])
    r, v = y[:3], y[3:6]
    h = np.cross(r, v)
    x_ = v / np.linalg.norm(v)
    z_ = h / np.linalg.norm(h)
    frame = np.stack([x_, np.cross(z_, x_), z_], axis=1)
    y[3:6] += frame @ dv_vel
    y = integrate_piecewise(rhs, y, [2000.0, 4000.0])
    y[3:6] += dv_in
    y = integrate_piecewise(rhs, y, [4000.0, 6000.0])
    assert np.linalg.norm(np.asarray(tr.x_final[:3]) - y[:3]) < 1e-6
    ve = 320.0 * C.G0_KM_S2
    m_ref = 1000.0 * np.exp(-(np.linalg.norm(dv_vel) + np.linalg.norm(dv_in)) / ve)
    assert abs(float(tr.x_final[6]) - m_ref) / m_ref < 1e-12
    # backward through the same impulses returns to the start (mass too)
    back = propagate(m, p, None, 0.0, np.asarray(tr.x_final), np.array([6000.0, 0.0]))
    assert np.linalg.norm(np.asarray(back.x_final[:3]) - X0[:3]) < 1e-6
    assert abs(float(back.x_final[6]) - 1000.0) < 1e-9


@pytest.mark.parametrize("kind", KINDS_NO_ENCKE)
def test_radius_stop_during_a_thrust_arc(kind):
    """Tangential nuclear-electric thrust raises the orbit until r = 7400 km: the stop lands on
    the radius (1e-6 km) at the DOP853 event time (0.01 s: the event tolerance is 1e-6 s and
    the integration error ~1e-4 km at 7 km/s).  For every kind (the high-order kinds use our
    dop853, since the thrust makes the acceleration velocity- and mass-dependent)."""
    m = ForceModel(
        bodies=("earth",),
        thrust=True,
        velocity_dependent=True,
        power="nuclear",
        n_arcs=1,
        stop=StopCondition(kind="radius", body=0, radius_km=7400.0),
        integrator=integrator(kind, thrust=True, c_nom=0.02),
    )
    p = default_params(
        m,
        mu=[MU],
        power_kw=200.0,
        power_decay_s=1.0e6,
        efficiency=0.7,
        exhaust_velocity_km_s=20.0,
        arc_t_on=[0.0],
        arc_t_off=[10 * DAY],
    )
    tr = propagate(m, p, None, 0.0, X0, np.array([0.0, 10 * DAY]))
    assert int(tr.status) == 1
    assert abs(np.linalg.norm(np.asarray(tr.x_final[:3])) - 7400.0) < 1e-6

    def rhs(t, y):
        r, v, mass = y[:3], y[3:6], y[6]
        tm = 2e-3 * 0.7 * 200.0 * np.exp(-t / 1.0e6) / 20.0
        a = -MU * r / np.linalg.norm(r) ** 3 + tm / mass * v / np.linalg.norm(v)
        return np.concatenate([v, a, [-tm / 20.0]])

    ev = lambda t, y: np.linalg.norm(y[:3]) - 7400.0  # noqa: E731
    ev.terminal = True
    sol = solve_ivp(rhs, (0.0, 10 * DAY), X0, method="DOP853", rtol=1e-13, atol=1e-12, events=ev)
    assert abs(float(tr.t_final) - sol.t_events[0][0]) < 0.01
    assert abs(float(tr.x_final[6]) - sol.y_events[0][0][6]) < 1e-6


@pytest.mark.slow  # ~36 s of a cold make test (mostly XLA compilation; issue 22)
@pytest.mark.parametrize("kind", KINDS_NO_ENCKE)
def test_leaving_earth_sphere_of_influence(kind):
    """Departure at 4 km/s above escape from 7000 km: the primary becomes the Sun where
    |r| = R_SOI(Earth), located to 1e-5 km; the heliocentric state at 10 days matches DOP853
    of the same model (geocentric to the SOI event, then heliocentric with Earth as third
    body) to 0.01 km.  For every kind (change of primary with Cowell and Encke dprkn12 too)."""
    bodies = ("sun", "earth")
    m = ForceModel(
        bodies=bodies,
        primary=1,
        third_bodies=(0,),
        change_primary_at_soi=True,
        integrator=integrator(kind, c_nom=0.02, dt_max_s=3600.0),
    )
    p = default_params(m)
    eph = build_ephemeris(bodies, ET0, ET0 + 12 * DAY)
    vesc = np.sqrt(2 * C.BODIES["earth"].mu_km3_s2 / 7000.0)
    x0 = np.array([7000.0, 0.0, 0.0, 0.0, vesc + 4.0, 0.5, 800.0])
    tr = propagate(m, p, eph, ET0, x0, np.array([0.0, 10 * DAY]))
    assert int(tr.status) == 0 and int(tr.primary_final) == 0
    soi = C.soi_radius_km("earth")
    mus = {b: C.BODIES[b].mu_km3_s2 for b in bodies}
    geo = cowell_rhs_factory(mus["earth"], "earth", ("sun",), mus, epoch_et=ET0)
    ev = lambda t, y: np.linalg.norm(y[:3]) - soi  # noqa: E731
    ev.terminal = True
    sol = solve_ivp(geo, (0.0, 10 * DAY), x0, method="DOP853", rtol=1e-13, atol=1e-9, events=ev)
    t_soi, y_soi = sol.t_events[0][0], sol.y_events[0][0].copy()
    et = ET0 + t_soi
    y_soi[:3] += helio_position("earth", et)
    y_soi[3:6] += helio_velocity("earth", et)
    helio = cowell_rhs_factory(mus["sun"], "sun", ("earth",), mus, epoch_et=ET0)
    y = integrate_piecewise(helio, y_soi, [t_soi, 10 * DAY], atol=1e-9)
    assert np.linalg.norm(np.asarray(tr.x_final[:3]) - y[:3]) < 0.01


def _helio_model(kind="fracas"):
    """Heliocentric coast near 1.3 AU with SRP, Jupiter from DE421 and Mars as an EPHEM body
    (fixed conic elements), 60 days."""
    bodies = ("sun", "mars", "jupiter")
    m = ForceModel(
        bodies=bodies,
        primary=0,
        third_bodies=(1, 2),
        srp=True,
        conic_bodies=(1,),
        integrator=integrator(kind, c_nom=0.05, dt_max_s=DAY, rect_ratio=10.0),
    )
    el_mars = np.array([2.2794e8, 0.0934, np.radians(24.7), np.radians(3.4), np.radians(332.0), np.radians(20.0)])
    p = default_params(
        m,
        area_m2=40.0,
        cr=1.4,
        body_elements=np.stack([np.zeros(6), el_mars, np.zeros(6)]),
        body_elements_et=[0.0, ET0, 0.0],
    )
    eph = build_ephemeris(bodies, ET0, ET0 + 61 * DAY)
    rm = np.asarray(
        __import__("fracas.dynamics.elements", fromlist=["x"]).conic_body_state(
            el_mars, C.BODIES["sun"].mu_km3_s2 + C.BODIES["mars"].mu_km3_s2, 30 * DAY
        )[0]
    )
    r0 = rm * (1 - 3.0e6 / np.linalg.norm(rm))  # 3e6 km sunward of where Mars will be in 30 days
    v0 = np.cross([0.0, 0.0, 1.0], r0)
    v0 = v0 / np.linalg.norm(v0) * np.sqrt(C.BODIES["sun"].mu_km3_s2 / np.linalg.norm(r0))
    x0 = np.concatenate([r0, v0, [600.0]])
    return m, p, eph, x0


@pytest.mark.slow  # heliocentric AD programs: ~35-60 s of compilation per kind on a cold cache
@pytest.mark.parametrize("kind", KINDS_NO_ENCKE)
def test_ephemeris_and_element_parameters_match_finite_differences(kind):
    """d x(60 d) / d(Cr, mu_sun, mu_mars, mu_jupiter, Mars a, e, M) and the STM by AD vs central
    differences, agreeing to 1e-6 of each column's size.  Heliocentric positions (~2e8 km)
    carry ~3e-8 km of roundoff, so each parameter step is sized to move the final position by
    ~10 km (roundoff/response ~3e-9; the central-difference truncation, relative (step/scale)^2,
    stays below 1e-8 for these nearly linear responses), except Mars's elements, whose effect
    is nonlinear on the 3e6 km miss-distance scale: their steps move Mars ~1e3 km and the
    spacecraft ~0.05 km (truncation ~(1e3/3e6)^2 ~ 1e-7, roundoff ~6e-7).  Rectification is off so the FD
    quotient has no step-sequence jumps.  For the fracas and cowell kinds (tests/integrate/methods.py,
    encke left out for time; AD through the steps at fixed step sizes, FD runs choosing their own)."""
    m, p, eph, x0 = _helio_model(kind)
    labels = (
        "cr",
        "mu[sun]",
        "mu[mars]",
        "mu[jupiter]",
        "body_elements[mars,a]",
        "body_elements[mars,e]",
        "body_elements[mars,M]",
    )
    t_out = np.array([0.0, 60 * DAY])
    _, s = propagate_with_sensitivities(m, p, eph, ET0, x0, t_out, labels)
    par = np.asarray(s.par[-1])
    response_km = np.array([10.0, 10.0, 10.0, 10.0, 0.05, 0.05, 0.05])
    steps = response_km / np.abs(par[:3]).max(axis=0)
    stm_fd, par_fd = finite_difference_sensitivities(
        m, p, eph, ET0, x0, t_out, labels, state_steps=(1.0,) * 3 + (1e-6,) * 3 + (1e-3,), param_steps=steps
    )
    err = np.abs(par - par_fd).max(axis=0) / np.abs(par_fd).max(axis=0)
    assert err.max() < 1e-6, dict(zip(labels, err))
    stm = np.asarray(s.stm[-1])[:6, :6]
    err_stm = np.abs(stm - stm_fd[:6, :6]).max(axis=0) / np.abs(stm_fd[:6, :6]).max(axis=0)
    assert err_stm.max() < 1e-6, err_stm
    assert np.all(np.abs(par_fd).max(axis=0) > 0)


@pytest.mark.parametrize("kind", KINDS_NO_ENCKE)
def test_inertial_thrust_three_evaluation_step_matches_dop853(kind):
    """Inertially fixed thrust (RA 30 deg, Dec 10 deg; nuclear power) does not depend on v, so the
    step uses three evaluations with k3 = k2 + F (1/m_C - 1/m_B) (only the stage mass differs).
    Against DOP853 after 3 orbits: position within 1 m, mass within 1e-6 kg (the c_nom 0.02
    LEO truncation level); the 4-evaluation step gives the same answer to 1 m.  For the fracas and cowell
    kinds (cowell uses our dop853, which evaluates the full acceleration at every stage
    either way, so the velocity_dependent flag must not change its answer beyond 1 m either)."""
    ra, dec = np.radians(30.0), np.radians(10.0)
    u = np.array([np.cos(dec) * np.cos(ra), np.cos(dec) * np.sin(ra), np.sin(dec)])
    common = {
        "bodies": ("earth",),
        "thrust": True,
        "power": "nuclear",
        "n_arcs": 1,
        "integrator": integrator(kind, thrust=True, c_nom=0.02),
    }  # noqa: E501
    pars = {
        "mu": [MU],
        "power_kw": 100.0,
        "power_decay_s": 1.0e6,
        "efficiency": 0.7,
        "exhaust_velocity_km_s": 15.0,
        "arc_t_on": [600.0],
        "arc_t_off": [15000.0],
        "arc_alpha": [ra],
        "arc_beta": [dec],
        "arc_frame": [1.0],
    }
    t_f = 18000.0
    finals = []
    for vdep in (False, True):
        m = ForceModel(velocity_dependent=vdep, **common)
        tr = propagate(m, default_params(m, **pars), None, 0.0, X0, np.array([0.0, t_f]))
        finals.append(np.asarray(tr.x_final))

    def rhs(t, y):
        on = 600.0 <= t < 15000.0
        tm = 2e-3 * 0.7 * 100.0 * np.exp(-t / 1.0e6) / 15.0 if on else 0.0
        a = -MU * y[:3] / np.linalg.norm(y[:3]) ** 3 + tm / y[6] * u
        return np.concatenate([y[3:6], a, [-tm / 15.0]])

    ref = integrate_piecewise(rhs, X0, [0.0, 600.0, 15000.0, t_f])
    assert 1.0 < X0[6] - ref[6]  # the arc burned propellant
    for x in finals:
        assert np.linalg.norm(x[:3] - ref[:3]) * 1e3 < 1.0
        assert abs(x[6] - ref[6]) < 1e-6
    assert np.linalg.norm(finals[0][:3] - finals[1][:3]) * 1e3 < 1.0
