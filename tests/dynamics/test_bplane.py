"""Tests of fracas.dynamics.bplane (FRACAS BPLANE).

Independent references:

* a hyperbola built in its own perifocal plane from the textbook parametric form
  (x = |a| (e - cosh H), y = |a| sqrt(e^2 - 1) sinh H, focus at the origin), whose
  incoming asymptote and B vector follow from plane geometry: the asymptote is the line
  through the centre (|a| e, 0) with direction S_pf = (1, sqrt(e^2 - 1))/e (the H -> -inf
  limit of the velocity direction), so B = C - (C . S) S = |a| sqrt(e^2-1) (sqrt(e^2-1),
  -1)/e and b = |B| = -a sqrt(e^2 - 1) for a < 0.  The plane is then rotated so that S
  and B point in prescribed directions (so B.T, B.R and theta are known by construction);
* a scipy DOP853 integration (rtol 1e-13, atol 1e-12) that locates periapsis with an
  event function r . v = 0, for t_closest_approach and r_closest_approach;
* central finite differences for the AD derivatives.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp

from fracas import (
    _jax,  # noqa: F401
    constants,
)
from fracas.dynamics.bplane import b_plane

MU_MARS = constants.BODIES["mars"].mu_km3_s2
POLE = (0.0, 0.0, 1.0)


def _unit(x):
    x = np.asarray(x, dtype=float)
    return x / np.linalg.norm(x)


def _planar_hyperbola(a, e, H, mu):
    """Perifocal state at hyperbolic anomaly H (a < 0), from the parametric form."""
    A = -a
    sq = math.sqrt(e * e - 1)
    r = A * (e * math.cosh(H) - 1)
    k = math.sqrt(mu * A)
    pos = np.array([A * (e - math.cosh(H)), A * sq * math.sinh(H), 0.0])
    vel = np.array([-k * math.sinh(H) / r, k * sq * math.cosh(H) / r, 0.0])
    return pos, vel


def _oriented_flyby(a, e, H, s_dir, theta0, mu, pole=POLE):
    """State whose incoming asymptote is s_dir and whose B vector makes angle theta0
    with T (toward R), for the reference ``pole``.  Returns (r, v, S, T, R, b)."""
    sq = math.sqrt(e * e - 1)
    s_pf = np.array([1.0, sq, 0.0]) / e
    c = np.array([-a * e, 0.0, 0.0])  # centre of the hyperbola
    b_pf = c - (c @ s_pf) * s_pf
    b = np.linalg.norm(b_pf)
    bh_pf = b_pf / b
    S = _unit(s_dir)
    T = _unit(np.cross(S, pole))
    R = np.cross(S, T)
    bh = math.cos(theta0) * T + math.sin(theta0) * R
    Q = np.column_stack([S, bh, np.cross(S, bh)]) @ np.column_stack([s_pf, bh_pf, np.cross(s_pf, bh_pf)]).T
    r_pf, v_pf = _planar_hyperbola(a, e, H, mu)
    return Q @ r_pf, Q @ v_pf, S, T, R, b


def test_b_magnitude_geometry():
    """The geometric construction gives b = -a sqrt(e^2 - 1), and a state far up the
    incoming leg (H = -14) lies on the line B + s S to 1e-5 b (its distance from the
    asymptote decays like |a| exp(H), ~1e-6 |a|): checks S_pf and B_pf themselves."""
    a, e = -4000.0, 1.8
    r, v, S, T, R, b = _oriented_flyby(a, e, -1.0, [0.3, -0.5, 0.2], 0.7, MU_MARS)
    assert b == pytest.approx(-a * math.sqrt(e * e - 1), rel=1e-14)
    B = b * (math.cos(0.7) * T + math.sin(0.7) * R)
    r_far, _, _, _, _, _ = _oriented_flyby(a, e, -14.0, [0.3, -0.5, 0.2], 0.7, MU_MARS)
    perp = r_far - (r_far @ S) * S
    np.testing.assert_allclose(perp, B, atol=1e-5 * b)


@settings(max_examples=40, deadline=None, derandomize=True)
@given(
    s_ra=st.floats(0.0, 2.0 * math.pi),
    s_dec=st.floats(-1.4, 1.4),
    theta0=st.floats(-3.1, 3.1),
    e=st.floats(1.02, 8.0),
    v_inf=st.floats(0.5, 15.0),
    H=st.floats(-6.0, 3.0),
)
def test_bplane_against_construction(s_ra, s_dec, theta0, e, v_inf, H):
    """B.T = b cos(theta0), B.R = b sin(theta0), theta = theta0, v_inf, S, T, R and the
    periapsis radius |a| (e - 1) and time -(e sinh H - H)/n agree with the construction
    to round-off (1e-11 relative; the inputs themselves carry ~1e-15 relative error,
    amplified by at most the 1/(e - 1) conditioning of S near e = 1).

    S is drawn by right ascension and declination within 80.2 deg of the equator, so every
    example is checked: |S x pole| = cos(dec) >= 0.17 keeps T = S x pole / |S x pole| defined
    (the B-plane frame is singular for S along the reference pole)."""
    s_dir = [math.cos(s_dec) * math.cos(s_ra), math.cos(s_dec) * math.sin(s_ra), math.sin(s_dec)]
    a = -MU_MARS / v_inf**2
    r, v, S, T, R, b = _oriented_flyby(a, e, H, s_dir, theta0, MU_MARS)
    out = b_plane(jnp.asarray(r), jnp.asarray(v), MU_MARS, POLE)
    tol = 1e-12 / (e - 1)
    assert float(out.b_mag) == pytest.approx(b, rel=tol)
    assert float(out.b_dot_t) == pytest.approx(b * math.cos(theta0), abs=tol * b)
    assert float(out.b_dot_r) == pytest.approx(b * math.sin(theta0), abs=tol * b)
    assert float(out.theta) == pytest.approx(theta0, abs=tol)
    assert float(out.v_inf) == pytest.approx(v_inf, rel=1e-12)  # sqrt(v² − 2μ/r): cancellation ~v²/v∞²
    np.testing.assert_allclose(out.s_hat, S, atol=tol)
    np.testing.assert_allclose(out.t_hat, T, atol=tol)
    np.testing.assert_allclose(out.r_hat, R, atol=tol)
    assert float(out.r_closest_approach) == pytest.approx(-a * (e - 1), rel=1e-13)
    n = math.sqrt(MU_MARS / (-a) ** 3)
    t_ca = -(e * math.sinh(H) - H) / n
    assert float(out.t_closest_approach) == pytest.approx(t_ca, rel=1e-11, abs=1e-12 / n)


def test_custom_reference_pole():
    """With the ecliptic pole as reference (EME2000 components), T lies in the ecliptic
    and B.T, B.R follow the construction made with that pole."""
    eps = constants.OBLIQUITY_J2000_RAD
    pole = (0.0, -math.sin(eps), math.cos(eps))
    r, v, S, T, R, b = _oriented_flyby(-9000.0, 2.5, -2.0, [1.0, 2.0, -0.5], -2.0, MU_MARS, pole)
    out = b_plane(jnp.asarray(r), jnp.asarray(v), MU_MARS, pole)
    assert abs(float(jnp.dot(out.t_hat, jnp.asarray(pole)))) < 1e-15
    assert float(out.b_dot_t) == pytest.approx(b * math.cos(-2.0), rel=1e-12)
    assert float(out.b_dot_r) == pytest.approx(b * math.sin(-2.0), rel=1e-12)
    assert float(out.theta) == pytest.approx(-2.0, abs=1e-12)


def _two_body(t, y, mu):
    r = y[:3]
    return np.concatenate([y[3:], -mu * r / np.linalg.norm(r) ** 3])


def _periapsis_event(t, y, mu):
    return y[:3] @ y[3:]


_periapsis_event.terminal = True
_periapsis_event.direction = 1.0


@pytest.mark.parametrize(
    "a, e, H, mu",
    [
        (-4759.0, 1.8, -2.5, MU_MARS),  # Mars flyby, v_inf ~ 3 km/s
        (-30000.0, 1.25, -1.2, constants.BODIES["earth"].mu_km3_s2),  # Earth, slow approach
        (-1.3e6, 1.05, -3.0, constants.BODIES["jupiter"].mu_km3_s2),  # Jupiter, near-parabolic
    ],
)
def test_closest_approach_vs_dop853(a, e, H, mu):
    """Time and radius of periapsis from an integration of the two-body ODE (DOP853,
    rtol 1e-13, atol 1e-12) stopped at r.v = 0.  The event time is located on the dense
    output to ~1e-12 relative; periapsis radius is stationary at the event, so it is
    insensitive to the event-time error.  Tolerances: 1e-9 relative on t and 1e-10
    relative on r (two orders above the integration error)."""
    r, v, *_ = _oriented_flyby(a, e, H, [0.2, 0.9, -0.4], 1.0, mu)
    out = b_plane(jnp.asarray(r), jnp.asarray(v), mu, POLE)
    t_ca = float(out.t_closest_approach)
    assert t_ca > 0
    sol = solve_ivp(
        _two_body,
        (0.0, 3 * t_ca),
        np.concatenate([r, v]),
        method="DOP853",
        rtol=1e-13,
        atol=1e-12,
        events=_periapsis_event,
        args=(mu,),
    )
    t_ev = sol.t_events[0][0]
    r_ev = np.linalg.norm(sol.y_events[0][0][:3])
    assert t_ca == pytest.approx(t_ev, rel=1e-9)
    assert float(out.r_closest_approach) == pytest.approx(r_ev, rel=1e-10)
    # after periapsis the time is negative (periapsis behind)
    y_after = sol.y_events[0][0]
    sol2 = solve_ivp(_two_body, (0.0, 0.5 * t_ca), y_after, method="DOP853", rtol=1e-13, atol=1e-12, args=(mu,))
    out2 = b_plane(jnp.asarray(sol2.y[:3, -1]), jnp.asarray(sol2.y[3:, -1]), mu, POLE)
    assert float(out2.t_closest_approach) == pytest.approx(-0.5 * t_ca, rel=1e-9)
    # B.T, B.R are constants of the motion
    assert float(out2.b_dot_t) == pytest.approx(float(out.b_dot_t), rel=1e-9)
    assert float(out2.b_dot_r) == pytest.approx(float(out.b_dot_r), rel=1e-9)


def _bplane_vec(y):
    o = b_plane(y[:3], y[3:], MU_MARS, POLE)
    return jnp.stack([o.b_dot_t, o.b_dot_r, o.t_closest_approach])


def test_ad_vs_central_differences():
    """Forward- and reverse-mode Jacobians of (B.T, B.R, t_ca) w.r.t. the state vs
    central differences with steps 1e-3 km (|r| ~ 3e4 km) and 1e-7 km/s (|v| ~ 3 km/s),
    i.e. relative steps ~3e-8, near the eps^(1/3) optimum.  The FD error is ~1e-9 to
    2e-8 of each row's scale (measured), so 1e-6 of the row's largest entry is a safe
    bound that still catches any wrong derivative term."""
    r, v, *_ = _oriented_flyby(-4759.0, 1.8, -2.0, [0.3, -0.5, 0.2], 0.7, MU_MARS)
    y0 = np.concatenate([r, v])
    jacs = jax.jit(lambda y: (jax.jacfwd(_bplane_vec)(y), jax.jacrev(_bplane_vec)(y)))
    Jf, Jr = (np.asarray(j) for j in jacs(jnp.asarray(y0)))
    np.testing.assert_allclose(Jf, Jr, rtol=1e-12, atol=1e-13 * np.abs(Jf).max())
    f = _bplane_vec  # b_plane itself is jitted; no extra compilation here
    steps = [1e-3] * 3 + [1e-7] * 3
    cols = []
    for k in range(6):
        d = np.zeros(6)
        d[k] = steps[k]
        cols.append((np.asarray(f(y0 + d)) - np.asarray(f(y0 - d))) / (2 * steps[k]))
    Jfd = np.stack(cols, axis=1)
    for i in range(Jf.shape[0]):
        scale = np.abs(Jfd[i]).max()
        assert np.abs(Jf[i] - Jfd[i]).max() <= 1e-6 * scale, (i, Jf[i], Jfd[i])


def test_non_hyperbolic_and_degenerate_inputs():
    """An elliptic state gives NaN in every field (not a silent wrong answer); S parallel
    to the reference pole still gives finite, orthonormal S, T, R; vmap works."""
    r = jnp.array([7000.0, 0.0, 0.0])
    v = jnp.array([0.0, 7.5, 0.0])
    out = b_plane(r, v, constants.MU_EARTH_EGM96_KM3_S2, POLE)
    assert all(np.all(np.isnan(np.asarray(x))) for x in out)
    # incoming asymptote along +z, parallel to the default pole (T falls back to S x x)
    r, v, *_ = _oriented_flyby(-4759.0, 1.8, -2.0, [0.0, 0.0, 1.0], 0.3, MU_MARS, (1.0, 0.0, 0.0))
    out = b_plane(jnp.asarray(r), jnp.asarray(v), MU_MARS, POLE)
    M = np.stack([np.asarray(out.s_hat), np.asarray(out.t_hat), np.asarray(out.r_hat)])
    assert np.all(np.isfinite(M))
    np.testing.assert_allclose(M @ M.T, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(out.s_hat, [0.0, 0.0, 1.0], atol=1e-12)
    # batch
    r1, v1, *_ = _oriented_flyby(-4759.0, 1.8, -2.0, [0.3, -0.5, 0.2], 0.7, MU_MARS)
    r2, v2, *_ = _oriented_flyby(-9000.0, 3.0, 1.0, [-0.3, 0.5, 0.8], -1.2, MU_MARS)
    rb, vb = jnp.asarray(np.stack([r1, r2])), jnp.asarray(np.stack([v1, v2]))
    ob = jax.vmap(lambda r, v: b_plane(r, v, MU_MARS, POLE))(rb, vb)
    o2 = b_plane(jnp.asarray(r2), jnp.asarray(v2), MU_MARS, POLE)
    assert float(ob.b_dot_r[1]) == pytest.approx(float(o2.b_dot_r), rel=1e-14)
