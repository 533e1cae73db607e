"""Tests of fracas.dynamics.elements (FRACAS CONIC, CONVRT, EULMX, PECEQ, conic EPHEM).

Independent references used here:

* Kepler's equation itself (backward error of the computed root, in ulps);
* round trips elements <-> Cartesian (each direction checks the other; they share no
  code except the perifocal rotation);
* a scipy DOP853 integration of the two-body equations (rtol 1e-13, atol 1e-12) for
  ``conic_body_state``;
* central finite differences for the Jacobians;
* hand-computed matrices and catalogue pole / obliquity values for the rotations.
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
from fracas.dynamics import elements as el

MU = constants.MU_EARTH_EGM96_KM3_S2
EPS = np.finfo(float).eps
HYP = settings(max_examples=60, deadline=None, derandomize=True)

c2e = jax.jit(el.cartesian_to_elements)
e2c = jax.jit(el.elements_to_cartesian)
kepler = jax.jit(jax.vmap(el.solve_kepler))
# forward and reverse derivatives of Kepler's equation in one compiled program
kepler_derivs = jax.jit(
    lambda M, e: (
        el.solve_kepler(M, e),
        jax.grad(el.solve_kepler, argnums=(0, 1))(M, e),
        jax.jacfwd(el.solve_kepler, argnums=(0, 1))(M, e),
    )
)


def _e2c_flat(x):
    return jnp.concatenate(el.elements_to_cartesian(x, MU))


def _c2e_flat(y):
    return el.cartesian_to_elements(y[:3], y[3:], MU)


def _conic_flat(x, t):
    return jnp.concatenate(el.conic_body_state(x, MU, t))


# Compiled once and shared by the tests (XLA compilation dominates the runtime, so each
# derivative program is built once: forward mode of elements_to_cartesian, reverse mode of
# cartesian_to_elements, a forward JVP of cartesian_to_elements and reverse mode of
# conic_body_state, which at dt = 0 is reverse mode of elements_to_cartesian).
e2c_jf = jax.jit(jax.jacfwd(_e2c_flat))
c2e_jr = jax.jit(jax.jacrev(_c2e_flat))
c2e_jvp = jax.jit(lambda y, w: jax.jvp(_c2e_flat, (y,), (w,))[1])
conic_jr = jax.jit(jax.jacrev(_conic_flat, argnums=(0, 1)))


def e2c_flat(x):
    """elements -> 6-state via the already-compiled e2c (no extra compilation)."""
    return np.concatenate(_state(x))


def c2e_flat(y):
    y = np.asarray(y)
    return np.asarray(c2e(y[:3], y[3:], MU))


def _angle_diff(x, y):
    d = np.remainder(np.asarray(x) - np.asarray(y) + np.pi, 2 * np.pi) - np.pi
    return np.abs(d)


def _state(elements):
    r, v = e2c(jnp.asarray(elements, dtype=float), MU)
    return np.asarray(r), np.asarray(v)


def _assert_state_close(r1, v1, r2, v2, rel):
    """Position/velocity agreement relative to |r| and |v|."""
    np.testing.assert_allclose(r1, r2, rtol=0, atol=rel * np.linalg.norm(r2))
    np.testing.assert_allclose(v1, v2, rtol=0, atol=rel * np.linalg.norm(v2))


# --- Kepler's equation --------------------------------------------------------------


def test_kepler_root_backward_error():
    """The computed E/H satisfy Kepler's equation to within a few ulps of its terms
    (the best a float64 root can do: the residual cannot be smaller than the round-off in
    evaluating E - e sin E - M), over e in [0, 0.9999], |M| <= pi and e in
    [1.0001, 1000], |M| <= 1e8 (which includes the near-parabolic cube-root regime)."""
    e = np.concatenate([np.linspace(0.0, 0.999, 60), 1 - np.logspace(-4, -1, 10)])
    M = np.concatenate([np.linspace(-np.pi, np.pi, 121), np.logspace(-14, 0, 15)])
    Ee, Me = (x.ravel() for x in np.meshgrid(e, M))
    e = np.concatenate([np.linspace(1.001, 10.0, 40), 1 + np.logspace(-4, -3, 5), [1e2, 1e3]])
    M = np.concatenate([np.linspace(-30, 30, 61), np.logspace(-14, 8, 23), -np.logspace(-14, 8, 23)])
    Eh, Mh = (x.ravel() for x in np.meshgrid(e, M))
    X = np.asarray(kepler(jnp.asarray(np.concatenate([Me, Mh])), jnp.asarray(np.concatenate([Ee, Eh]))))
    E, H = X[: Me.size], X[Me.size :]

    res = np.abs(E - Ee * np.sin(E) - Me)
    scale = np.abs(E) + Ee * np.abs(np.sin(E)) + np.abs(Me) + 1e-300
    assert np.max(res / scale) < 4 * EPS

    res = np.abs(Eh * np.sinh(H) - H - Mh)
    scale = Eh * np.abs(np.sinh(H)) + np.abs(H) + np.abs(Mh) + 1e-300
    assert np.max(res / scale) < 16 * EPS  # sinh itself is good to ~1-2 ulp of a large term


def test_kepler_exact_derivative():
    """Implicit-function AD: dE/dM = 1/(1 - e cos E), dE/de = sin E/(1 - e cos E);
    dH/dM = 1/(e cosh H - 1), dH/de = -sinh H/(e cosh H - 1) -- to round-off, since the
    final Newton step reproduces the exact implicit derivative."""
    for M, e in [(0.3, 0.95), (2.5, 0.2), (-1.0, 0.7)]:
        E, *derivs = kepler_derivs(M, e)
        E = float(E)
        for gM, ge in derivs:  # reverse, forward
            assert gM == pytest.approx(1 / (1 - e * math.cos(E)), rel=1e-13)
            assert ge == pytest.approx(math.sin(E) / (1 - e * math.cos(E)), rel=1e-13)
    for M, e in [(-40.0, 1.5), (0.01, 1.01), (3.0, 8.0)]:
        H, *derivs = kepler_derivs(M, e)
        H = float(H)
        for gM, ge in derivs:
            assert gM == pytest.approx(1 / (e * math.cosh(H) - 1), rel=1e-13)
            assert ge == pytest.approx(-math.sinh(H) / (e * math.cosh(H) - 1), rel=1e-13)


@HYP
@given(nu=st.floats(-3.1, 3.1), e=st.floats(0.0, 0.99))
def test_true_mean_anomaly_round_trip_elliptic(nu, e):
    """mean_to_true(true_to_mean(nu)) = nu; the conditioning is (1 - e)^-1.5 at worst."""
    M = el.true_to_mean_anomaly(nu, e)
    assert 0.0 <= float(M) < 2 * np.pi
    assert _angle_diff(el.mean_to_true_anomaly(M, e), nu) < 1e-13 / (1 - e) ** 1.5


@HYP
@given(frac=st.floats(-0.98, 0.98), e=st.floats(1.01, 10.0))
def test_true_mean_anomaly_round_trip_hyperbolic(frac, e):
    """Same round trip on a hyperbola, nu a fraction of the asymptote angle."""
    nu = frac * math.acos(-1 / e)
    M = el.true_to_mean_anomaly(nu, e)
    assert float(el.mean_to_true_anomaly(M, e)) == pytest.approx(nu, abs=1e-12)


# --- element round trips -------------------------------------------------------------

angles = st.floats(0.05, 2 * np.pi - 0.05)


@HYP
@given(
    a=st.floats(6600.0, 50000.0),
    e=st.floats(1e-4, 0.95),
    i=st.floats(0.02, np.pi - 0.02),
    raan=angles,
    argp=angles,
    M=angles,
)
def test_elliptic_round_trip(a, e, i, raan, argp, M):
    """elements -> state -> elements for well-defined elliptic elements (prograde and
    retrograde).  The element errors are round-off amplified by the conditioning of the
    element definitions (1/e for argp and M, 1/sin i for raan), hence the scaled bounds."""
    el0 = np.array([a, e, i, raan, argp, M])
    el1 = np.asarray(c2e(*_state(el0), MU))
    assert el1[0] == pytest.approx(a, rel=1e-12)
    assert el1[1] == pytest.approx(e, abs=1e-13)
    assert el1[2] == pytest.approx(i, abs=1e-13)
    assert _angle_diff(el1[3], raan) < 1e-13 / math.sin(i)
    assert _angle_diff(el1[4], argp) < 1e-13 / e + 1e-13 / math.sin(i)
    assert _angle_diff(el1[5], M) < 1e-13 / e / (1 - e) ** 2


@HYP
@given(
    a=st.floats(-200000.0, -2000.0),
    e=st.floats(1.05, 10.0),
    i=st.floats(0.02, np.pi - 0.02),
    raan=angles,
    argp=angles,
    M=st.floats(-50.0, 50.0),
)
def test_hyperbolic_round_trip(a, e, i, raan, argp, M):
    """elements -> state -> elements on hyperbolas (a < 0), before and after periapsis."""
    el0 = np.array([a, e, i, raan, argp, M])
    el1 = np.asarray(c2e(*_state(el0), MU))
    assert el1[0] == pytest.approx(a, rel=1e-11)
    assert el1[1] == pytest.approx(e, rel=1e-12)
    assert el1[2] == pytest.approx(i, abs=1e-12)
    assert _angle_diff(el1[3], raan) < 1e-12 / math.sin(i)
    assert _angle_diff(el1[4], argp) < 1e-12 / math.sin(i)
    assert el1[5] == pytest.approx(M, abs=1e-11 * (1 + abs(M)))


@HYP
@given(
    a=st.floats(6600.0, 50000.0),
    log_e=st.floats(-16.0, -3.0),
    log_i=st.floats(-16.0, -3.0),
    retro=st.booleans(),
    raan=angles,
    argp=angles,
    M=angles,
)
def test_degenerate_round_trip_states(a, log_e, log_i, retro, raan, argp, M):
    """Near-circular and near-equatorial (pro- and retrograde) orbits: the element angles
    are ill-defined there, so the check is state -> elements -> state, which must hold to
    round-off (1e-13 relative) whichever fallback branch is taken."""
    i = 10**log_i
    if retro:
        i = np.pi - i
    r0, v0 = _state([a, 10**log_e, i, raan, argp, M])
    el1 = c2e(r0, v0, MU)
    assert np.all(np.isfinite(np.asarray(el1)))
    r1, v1 = _state(el1)
    _assert_state_close(r1, v1, r0, v0, 1e-13)


@HYP
@given(
    rv=st.lists(st.floats(-1.0, 1.0), min_size=6, max_size=6),
    rscale=st.floats(6600.0, 1e6),
    vfac=st.floats(0.3, 2.5),
)
def test_random_state_round_trip(rv, rscale, vfac):
    """Arbitrary states (bound and unbound) survive state -> elements -> state."""
    r = np.array(rv[:3])
    v = np.array(rv[3:])
    if np.linalg.norm(r) < 0.1 or np.linalg.norm(v) < 0.1:
        return
    r = r / np.linalg.norm(r) * rscale
    v = v / np.linalg.norm(v) * vfac * math.sqrt(MU / rscale)
    if np.linalg.norm(np.cross(r, v)) < 1e-3 * rscale * np.linalg.norm(v):
        return  # (near-)rectilinear: outside the domain
    elems = np.asarray(c2e(r, v, MU))
    if abs(elems[1] - 1.0) < 1e-3:
        return  # near-parabolic: a is ill-conditioned
    r1, v1 = _state(elems)
    # conditioning grows like 1/|1 - e| near the parabola
    _assert_state_close(r1, v1, r, v, 1e-12 / abs(elems[1] - 1.0))


def test_special_cases_exact():
    """Circular equatorial prograde/retrograde orbits: e = 0, i = 0 or pi, raan = argp = 0
    and M equal to the true longitude (measured from x_hat); zero-inclination elliptic
    orbit gives raan = 0 and argp = longitude of periapsis."""
    r = np.array([7000.0 / math.sqrt(2), 7000.0 / math.sqrt(2), 0.0])
    vc = math.sqrt(MU / 7000.0)
    v = np.array([-vc / math.sqrt(2), vc / math.sqrt(2), 0.0])
    a, e, i, raan, argp, M = np.asarray(c2e(r, v, MU))
    assert a == pytest.approx(7000.0, rel=1e-13)
    assert e < 1e-15 and i == 0.0 and raan == 0.0 and argp == 0.0
    assert M == pytest.approx(np.pi / 4, abs=1e-14)
    a, e, i, raan, argp, M = np.asarray(c2e(r, -v, MU))
    assert i == pytest.approx(np.pi, abs=1e-15) and raan == 0.0 and argp == 0.0
    # retrograde: angles measured in the orbit's own sense, x_hat -> -y_hat
    assert M == pytest.approx(2 * np.pi - np.pi / 4, abs=1e-14)
    # equatorial ellipse, periapsis at longitude 1.2 rad
    r0, v0 = _state([9000.0, 0.3, 0.0, 0.0, 1.2, 0.4])
    el1 = np.asarray(c2e(r0, v0, MU))
    assert el1[3] == 0.0 and el1[4] == pytest.approx(1.2, abs=1e-13)


def test_gradients_finite_at_degenerate_states():
    """Exactly circular equatorial (pro- and retrograde) and equatorial hyperbolic states:
    forward and reverse derivatives of both conversions contain no NaN (double-where
    guards)."""
    for elems in (
        [7000.0, 0.0, 0.0, 0.0, 0.0, 1.0],
        [7000.0, 0.0, np.pi, 0.0, 0.0, 1.0],
        [-9000.0, 1.7, 0.0, 0.0, 0.3, -2.0],
    ):
        x = jnp.asarray(elems)
        y = e2c_flat(x)
        # a NaN anywhere in a Jacobian column would poison the all-ones JVP
        for jac in (e2c_jf(x), conic_jr(x, 0.0)[0], c2e_jr(y), c2e_jvp(y, jnp.ones(6))):
            assert np.all(np.isfinite(np.asarray(jac)))


def test_vmap_batch():
    """vmap over a batch mixing ellipses and hyperbolas equals the per-item results."""
    batch = jnp.array([[7000.0, 0.1, 0.5, 1.0, 2.0, 3.0], [-9000.0, 1.7, 2.0, 0.3, 0.2, -2.0]])
    both = jax.jit(jax.vmap(lambda x: (_e2c_flat(x), _c2e_flat(_e2c_flat(x)))))
    yb, eb = both(batch)
    for k in range(2):
        y = e2c_flat(batch[k])
        np.testing.assert_allclose(yb[k], y, rtol=1e-15)
        np.testing.assert_allclose(eb[k], c2e_flat(y), rtol=1e-15)


# --- conic_body_state vs numerical integration ----------------------------------------


def _two_body(t, y, mu):
    r = y[:3]
    return np.concatenate([y[3:], -mu * r / np.linalg.norm(r) ** 3])


@pytest.mark.parametrize(
    "elems, dt",
    [
        ([26560.0, 0.7, 1.1, 0.4, 2.2, 5.9], 1.3),  # fraction of periods, through periapsis
        ([7000.0, 0.001, 0.9, 3.0, 1.0, 0.1], 3.25),
        ([-30000.0, 1.4, 2.6, 5.0, 4.0, -1.5], 30000.0),  # hyperbola, seconds
    ],
)
def test_conic_body_state_vs_dop853(elems, dt):
    """Analytic conic propagation against scipy DOP853 (rtol 1e-13, atol 1e-12) of the
    two-body ODE.  Global integration error over these arcs is ~1e-11 relative, so 1e-9
    relative on position and velocity checks Kepler + rotation with a 100x margin.
    Ellipse dt is given in periods."""
    elems = np.array(elems)
    if elems[0] > 0:
        dt = dt * 2 * np.pi * math.sqrt(elems[0] ** 3 / MU)
    r0, v0 = _state(elems)
    sol = solve_ivp(_two_body, (0.0, dt), np.concatenate([r0, v0]), method="DOP853", rtol=1e-13, atol=1e-12, args=(MU,))
    r1, v1 = el.conic_body_state(jnp.asarray(elems), MU, dt)
    _assert_state_close(np.asarray(r1), np.asarray(v1), sol.y[:3, -1], sol.y[3:, -1], 1e-9)


def test_conic_body_state_gradient_vs_fd():
    """d(state)/d(elements, dt) of conic_body_state against central differences."""
    elems = np.array([26560.0, 0.7, 1.1, 0.4, 2.2, 5.9])
    dt = 20000.0
    f = jax.jit(_conic_flat)
    J, Jt = (np.asarray(j) for j in conic_jr(jnp.asarray(elems), dt))
    steps = np.array([1e-3, 1e-7, 1e-7, 1e-7, 1e-7, 1e-7])
    Jfd = _fd_jacobian(lambda x: f(x, dt), elems, steps)
    _assert_columns_close(J, Jfd, 1e-6)
    fd = (np.asarray(f(elems, dt + 1e-2)) - np.asarray(f(elems, dt - 1e-2))) / 2e-2
    _assert_columns_close(Jt[:, None], fd[:, None], 1e-7)


# --- Jacobians vs finite differences -------------------------------------------------


def _assert_columns_close(J, Jfd, frac):
    """|J - Jfd| <= frac * (largest |entry| of the same column of Jfd), per column."""
    scale = np.abs(Jfd).max(axis=0)
    err = np.abs(J - Jfd).max(axis=0)
    assert np.all(err <= frac * scale), err / scale


def _fd_jacobian(f, x, steps):
    cols = []
    for k in range(len(x)):
        d = np.zeros(len(x))
        d[k] = steps[k]
        cols.append((np.asarray(f(x + d)) - np.asarray(f(x - d))) / (2 * steps[k]))
    return np.stack(cols, axis=1)


@pytest.mark.parametrize(
    "elems",
    [
        [9000.0, 0.3, 0.7, 1.0, 2.0, 2.5],
        [42164.0, 0.9, 2.5, 4.0, 0.5, 0.2],
        [-15000.0, 2.2, 1.3, 0.7, 5.0, -3.0],
    ],
)
def test_jacobians_vs_central_differences(elems):
    """Jacobians of both conversions vs central differences (forward mode for
    elements -> state, reverse mode for state -> elements), and the other AD mode of each
    against the first.

    Steps: 1e-7 of the scale in a, 1e-7 in e and the angles (rad); 1e-4 km in position
    and 1e-7 km/s in velocity (relative steps ~1e-8 to 1e-7 of the state, near the
    eps^(1/3) optimum).  Truncation (~h^2) and round-off (~eps/h) errors of the
    differences are then 1e-9 to 2e-7 of the column scale (measured; the largest for the
    hyperbola's state -> elements map), so AD must agree to 2e-6 of each column's
    largest entry.
    """
    x0 = np.array(elems)
    Jf = np.asarray(e2c_jf(jnp.asarray(x0)))
    steps = np.array([1e-7 * abs(x0[0]), 1e-7, 1e-7, 1e-7, 1e-7, 1e-7])
    Jfd = _fd_jacobian(e2c_flat, x0, steps)
    _assert_columns_close(Jf, Jfd, 2e-6)
    # reverse mode of the same map (conic_body_state with dt = 0)
    Jr = np.asarray(conic_jr(jnp.asarray(x0), 0.0)[0])
    np.testing.assert_allclose(Jr, Jf, rtol=0, atol=1e-12 * np.abs(Jf).max())

    y0 = np.asarray(e2c_flat(x0))
    Ji = np.asarray(c2e_jr(jnp.asarray(y0)))
    Jfd = _fd_jacobian(c2e_flat, y0, np.array([1e-4] * 3 + [1e-7] * 3))
    _assert_columns_close(Ji, Jfd, 2e-6)
    # forward mode of the same map, along a generic direction
    w = np.array([0.3, -1.2, 0.7, 1e-3, 2e-3, -1.5e-3])
    np.testing.assert_allclose(
        c2e_jvp(jnp.asarray(y0), jnp.asarray(w)), Ji @ w, rtol=1e-11, atol=1e-12 * np.abs(Ji @ w).max()
    )
    # the two Jacobians are inverses of each other (exact AD identity)
    np.testing.assert_allclose(Ji @ Jf, np.eye(6), atol=1e-9)


# --- spherical coordinates (CONVRT) ----------------------------------------------------


def test_spherical_hand_cases():
    """Hand cases: on the x axis heading due east horizontally -> v along +y; at
    (lat 0, lon 90 deg) heading north, climbing 30 deg -> v = (0, v/2, v sqrt3/2)...
    i.e. up = +y, north = +z."""
    R, V = el.spherical_to_cartesian(7000.0, 0.0, 0.0, 7.5, 0.0, np.pi / 2)
    np.testing.assert_allclose(R, [7000.0, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(V, [0.0, 7.5, 0.0], atol=1e-15)
    R, V = el.spherical_to_cartesian(7000.0, 0.0, np.pi / 2, 2.0, np.pi / 6, 0.0)
    np.testing.assert_allclose(R, [0.0, 7000.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(V, [0.0, 1.0, math.sqrt(3.0)], atol=1e-15)


@HYP
@given(
    r=st.floats(100.0, 1e9),
    lat=st.floats(-1.55, 1.55),
    lon=st.floats(0.0, 6.28),
    v=st.floats(0.01, 100.0),
    gamma=st.floats(-1.55, 1.55),
    sigma=st.floats(0.0, 6.28),
)
def test_spherical_round_trip(r, lat, lon, v, gamma, sigma):
    """spherical -> Cartesian -> spherical, plus the independent identities
    sin(gamma) = r.v/(|r||v|) and |R| = r, |V| = v."""
    R, V = el.spherical_to_cartesian(r, lat, lon, v, gamma, sigma)
    R, V = np.asarray(R), np.asarray(V)
    assert np.linalg.norm(R) == pytest.approx(r, rel=1e-14)
    assert np.linalg.norm(V) == pytest.approx(v, rel=1e-14)
    assert R @ V / (r * v) == pytest.approx(math.sin(gamma), abs=1e-14)
    out = [float(x) for x in el.cartesian_to_spherical(R, V)]
    assert out[0] == pytest.approx(r, rel=1e-14)
    assert out[1] == pytest.approx(lat, abs=1e-13)
    assert _angle_diff(out[2], lon) < 1e-13
    assert out[3] == pytest.approx(v, rel=1e-14)
    assert out[4] == pytest.approx(gamma, abs=1e-13)
    assert _angle_diff(out[5], sigma) < 1e-12


def test_spherical_polar_and_radial_finite_gradients():
    """On the polar axis (lon undefined) and for radial velocity (sigma undefined) the
    inverse returns 0 for the undefined angle and finite gradients."""

    def f(y):
        return jnp.stack(el.cartesian_to_spherical(y[:3], y[3:]))

    all_three = jax.jit(lambda y: (f(y), jax.jacfwd(f)(y), jax.jacrev(f)(y)))
    for y in ([0.0, 0.0, 7000.0, 1.0, 0.0, 0.0], [7000.0, 0.0, 0.0, 3.0, 0.0, 0.0]):
        for out in all_three(jnp.asarray(y)):
            assert np.all(np.isfinite(np.asarray(out)))


# --- rotation matrices (EULMX, PECEQ) -------------------------------------------------


@HYP
@given(
    ang=st.lists(st.floats(-7.0, 7.0), min_size=3, max_size=3),
    axes=st.sampled_from([(3, 1, 3), (1, 2, 3), (3, 2, 1), (2, 2, 1)]),
)
def test_euler_orthonormal(ang, axes):
    """Any EULMX matrix is a proper rotation: P P^T = I and det P = +1."""
    P = np.asarray(el.euler_matrix(jnp.asarray(ang), axes))
    np.testing.assert_allclose(P @ P.T, np.eye(3), atol=1e-15)
    assert np.linalg.det(P) == pytest.approx(1.0, abs=1e-14)


def test_euler_hand_cases():
    """Hand-computed: axes 3-1-3 with (90 deg, 90 deg, 0): F = R3(90), G = R1(90),
    P = G F = [[0,1,0],[0,0,1],[1,0,0]] (old x is the final z axis).  And the 3-1-3
    sequence (raan, i, argp) transposed has the perifocal P, Q vectors as its first
    two columns (classical orbit-to-inertial matrix)."""
    P = np.asarray(el.euler_matrix(jnp.array([np.pi / 2, np.pi / 2, 0.0]), (3, 1, 3)))
    np.testing.assert_allclose(P, [[0, 1, 0], [0, 0, 1], [1, 0, 0]], atol=1e-15)
    c, s = math.cos(0.3), math.sin(0.3)
    np.testing.assert_allclose(
        el.euler_matrix(jnp.array([0.3, 0.0, 0.0]), (2, 1, 1)), [[c, 0, -s], [0, 1, 0], [s, 0, c]], atol=1e-16
    )
    raan, i, argp = 0.4, 1.1, 2.3
    A = np.asarray(el.euler_matrix(jnp.array([raan, i, argp]), (3, 1, 3))).T
    Pv, Qv = el.perifocal_basis(i, raan, argp)
    np.testing.assert_allclose(A[:, 0], Pv, atol=1e-15)
    np.testing.assert_allclose(A[:, 1], Qv, atol=1e-15)
    with pytest.raises(ValueError):
        el.euler_matrix(jnp.zeros(3), (3, 4, 3))


def test_ecliptic_matrix():
    """The ecliptic north pole (0, 0, 1)_ecl maps to RA 270 deg, Dec 90 deg - eps in
    EME2000 (the J2000 ecliptic pole, eps = 23.4392794 deg); the equinox x is shared."""
    A = np.asarray(el.ecliptic_to_equatorial_matrix())
    eps = math.radians(23.4392794444)
    ra, dec = math.radians(270.0), math.pi / 2 - eps
    np.testing.assert_allclose(
        A @ [0, 0, 1], [math.cos(ra) * math.cos(dec), math.sin(ra) * math.cos(dec), math.sin(dec)], atol=1e-15
    )
    np.testing.assert_allclose(A @ [1, 0, 0], [1, 0, 0], atol=0)
    np.testing.assert_allclose(A @ A.T, np.eye(3), atol=1e-15)


def test_peceq_report_pole_formula_matches():
    """The report's PECEQ pole vector in ecliptic coordinates, (cos a cos d,
    cos eps sin a cos d + sin eps sin d, -sin eps sin a cos d + cos eps sin d), equals
    ecliptic_to_equatorial_matrix()^T applied to the equatorial pole (Mars)."""
    body = constants.BODIES["mars"]
    a, d = math.radians(body.pole_ra_deg), math.radians(body.pole_dec_deg)
    eps = constants.OBLIQUITY_J2000_RAD
    report = [
        math.cos(a) * math.cos(d),
        math.cos(eps) * math.sin(a) * math.cos(d) + math.sin(eps) * math.sin(d),
        -math.sin(eps) * math.sin(a) * math.cos(d) + math.cos(eps) * math.sin(d),
    ]
    pole = np.array(constants.pole_unit_vector("mars"))
    np.testing.assert_allclose(np.asarray(el.ecliptic_to_equatorial_matrix()).T @ pole, report, atol=1e-15)


def test_planet_equatorial_matrix():
    """Earth's pole gives the identity; for Mars, Z is the IAU pole, X is the node of the
    Mars equator on the ICRF equator at RA alpha0 + 90 deg, Y completes a right-handed
    orthonormal triad."""
    A = np.asarray(el.planet_equatorial_matrix(jnp.asarray(constants.pole_unit_vector("earth"))))
    np.testing.assert_allclose(A, np.eye(3), atol=1e-15)
    pole = np.array(constants.pole_unit_vector("mars"))
    A = np.asarray(el.planet_equatorial_matrix(jnp.asarray(pole)))
    a0 = math.radians(constants.BODIES["mars"].pole_ra_deg)
    np.testing.assert_allclose(A[2], pole, atol=1e-15)
    np.testing.assert_allclose(A[0], [-math.sin(a0), math.cos(a0), 0.0], atol=1e-15)
    np.testing.assert_allclose(A @ A.T, np.eye(3), atol=1e-15)
    assert np.linalg.det(A) == pytest.approx(1.0, abs=1e-14)
    # a south-pointing pole is handled too (X = x_hat, right-handed)
    A = np.asarray(el.planet_equatorial_matrix(jnp.array([0.0, 0.0, -2.0])))
    np.testing.assert_allclose(A, np.diag([1.0, -1.0, -1.0]), atol=1e-15)
