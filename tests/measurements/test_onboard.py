"""UNF onboard measurement models (fracas.measurements.onboard): analytic partials against
central differences, the Doppler count's exact STM form against re-propagation, its
Delta t_c -> 0 limit, the horizon routine's geometry and its sphere limit, the altitude
models, and the beacon visibility cone.

Central differences use a step h = eps^(1/3) * scale (scale: the geometry's distance, or
1 rad), where truncation (~h^2 q''' / 6) and rounding (~eps |q| / h) are both ~eps^(2/3)
~ 4e-11 relative; the tolerance 1e-7 (relative to the partial's norm) leaves a margin of
more than 100 for the geometry's conditioning (|q| / |q'| scale ratios of order 10).
"""

import math
from types import SimpleNamespace

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from fracas import _jax  # noqa: F401
from fracas.dynamics.kepler import kepler
from fracas.measurements import models
from fracas.measurements import onboard as _onboard
from fracas.measurements.stations import DSN_STATIONS, station_state
from fracas.measurements.visibility import beacon_passes, beacon_visible, visibility_passes

# the models, jitted once each (the finite differences call them many times)
ob = SimpleNamespace(**{name: jax.jit(getattr(_onboard, name)) for name in _onboard.__all__})
_back_jit = jax.jit(lambda x, dt: jnp.concatenate(kepler(x[:3], x[3:], -dt, MU)))
EPS = np.finfo(np.float64).eps
H_REL = EPS ** (1.0 / 3.0)
TOL = 1e-7
MU = 398600.436
A_F, B_F = 6378.137, 6378.137 * (1.0 - 1.0 / 298.257223563)
POLE = np.array([0.0, 0.0, 1.0])


def _central(f, x, h):
    """Central-difference Jacobian of a scalar function f at x (vector), step h per component."""
    x = np.asarray(x, dtype=np.float64)
    out = np.empty(x.size)
    for i in range(x.size):
        e = np.zeros_like(x)
        e[i] = h
        out[i] = (float(f(x + e)) - float(f(x - e))) / (2.0 * h)
    return out


def _close(an, fd, tol=TOL):
    an, fd = np.asarray(an), np.asarray(fd)
    assert np.linalg.norm(an - fd) <= tol * max(np.linalg.norm(an), 1e-300), (an, fd)


def _random_frame(rng):
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q.T  # rows: i_xm, i_ym, i_zm


def _rot(phi):
    """Exact rotation matrix of the rotation vector phi (Rodrigues)."""
    a = np.linalg.norm(phi)
    if a == 0.0:
        return np.eye(3)
    k = phi / a
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(a) * kx + (1 - math.cos(a)) * kx @ kx


def _leo(rng, r_km=7000.0):
    """A near-circular low orbit state (r km, v km/s) about the Earth, random orientation."""
    d = rng.normal(size=3)
    r = r_km * d / np.linalg.norm(d)
    w = np.cross(r, rng.normal(size=3))
    v = math.sqrt(MU / r_km) * w / np.linalg.norm(w) + rng.normal(size=3) * 0.05
    return r, v


# --- unified angles (UNF c = 2, 3) --------------------------------------------------------
@pytest.mark.parametrize("kind", ["beta", "theta"])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_sensor_angle_partials_match_central_differences(kind, seed):
    rng = np.random.default_rng(seed)
    axes = _random_frame(rng)
    sc_r = rng.normal(size=3) * 7000.0
    target = sc_r + rng.normal(size=3) * 3000.0
    value = ob.sensor_beta if kind == "beta" else ob.sensor_theta
    partials = ob.sensor_beta_partials if kind == "beta" else ob.sensor_theta_partials
    h_sc, h_t, h_phi = (np.asarray(x) for x in partials(sc_r, target, axes))
    h = H_REL * np.linalg.norm(target - sc_r)
    _close(h_sc[:3], _central(lambda x: value(x, target, axes), sc_r, h))
    assert np.all(h_sc[3:] == 0.0)
    _close(h_t, _central(lambda x: value(sc_r, x, axes), target, h))
    # misalignment: rotate the sensor axes by phi = sum phi_k i_k (exact rotation)
    _close(h_phi, _central(lambda p: value(sc_r, target, axes @ _rot(axes.T @ p).T), np.zeros(3), H_REL))


def test_sensor_angle_definitions_and_gradient_identity():
    rng = np.random.default_rng(5)
    axes = _random_frame(rng)
    r_rho = axes.T @ np.array([3.0, 1.0, 4.0])  # x = 3, y = 1, z = 4 on the sensor axes
    beta, theta = (float(x) for x in ob.unified_angles(r_rho, axes))
    assert beta == pytest.approx(math.atan2(4.0, 3.0), rel=1e-15)
    assert theta == pytest.approx(math.atan2(1.0, 5.0), rel=1e-15)
    # d beta / d r_rho = (i_rho_a x i_ym) / rho_a (digest A.3.5)
    i_a = (3.0 * axes[0] + 4.0 * axes[2]) / 5.0
    np.testing.assert_allclose(ob.beta_gradient(r_rho, axes), np.cross(i_a, axes[1]) / 5.0, rtol=0, atol=1e-16)


# --- one-way Doppler count (UNF c = 0.5) -----------------------------------------------------
def _count_setup(dt_c, seed=0):
    rng = np.random.default_rng(seed)
    r, v = _leo(rng)
    et = 6.5e8 + 1234.5
    st = DSN_STATIONS["goldstone"]
    s1 = np.asarray(station_state(st.radius_km, st.latitude_rad, st.longitude_rad, et)[0])
    s0 = np.asarray(station_state(st.radius_km, st.latitude_rad, st.longitude_rad, et - dt_c)[0])
    return r, v, s1, s0


def _back(x, dt_c):
    return _back_jit(jnp.asarray(x), dt_c)


def _count_h_exact(x, s1, s0, dt_c):
    """H row at t_M by the exact STM form: h(t_M) + h(t0) Phi(t0, t_M), Phi by AD of the conic."""
    x0 = np.asarray(_back(x, dt_c))
    phi_back = np.asarray(jax.jacfwd(_back_jit)(jnp.asarray(x), dt_c))
    z = np.zeros(3)
    h1, _, h0, _ = (np.asarray(a) for a in ob.doppler_count_1way_partials(x[:3], z, s1, x0[:3], z, s0))
    return h1 + h0 @ phi_back


@pytest.mark.parametrize("dt_c", [6.0, 60.0, 600.0])
def test_doppler_count_exact_stm_form_matches_re_propagation(dt_c):
    r, v, s1, s0 = _count_setup(dt_c)
    x = np.concatenate([r, v])
    z = np.zeros(3)

    def count(y):
        y0 = np.asarray(_back(y, dt_c))  # re-propagate the perturbed state back to t0
        return ob.doppler_count_1way(y[:3], z, s1, y0[:3], z, s0)

    h = _count_h_exact(x, s1, s0, dt_c)
    fd_r = _central(lambda p: count(np.concatenate([p, v])), r, H_REL * 7000.0)
    fd_v = _central(lambda p: count(np.concatenate([r, p])), v, H_REL * 7.5)
    _close(h, np.concatenate([fd_r, fd_v]))


def test_doppler_count_reduces_to_range_rate_partials_as_the_interval_shrinks():
    """As dt_c -> 0 the H row / dt_c tends to the range-rate partials (digest A.3.4), the
    error shrinking like dt_c (first order)."""
    errs = []
    for dt_c in (1e-1, 1e-2):
        r, v, s1, s0 = _count_setup(dt_c)
        x = np.concatenate([r, v])
        st = DSN_STATIONS["goldstone"]
        s1v = np.asarray(station_state(st.radius_km, st.latitude_rad, st.longitude_rad, 6.5e8 + 1234.5)[1])
        z = np.zeros(3)
        rr, _ = models.doppler2_partials(r, v, z, z, s1, s1v)
        h = _count_h_exact(x, s1, s0, dt_c) / dt_c
        errs.append(np.linalg.norm(h - np.asarray(rr)) / np.linalg.norm(rr))
    assert errs[0] < 1e-3
    assert errs[1] < errs[0] / 5.0  # first-order convergence


def test_doppler_count_value_is_the_range_change():
    r, v, s1, s0 = _count_setup(60.0)
    z = np.zeros(3)
    x0 = np.asarray(_back(np.concatenate([r, v]), 60.0))
    q = float(ob.doppler_count_1way(r, z, s1, x0[:3], z, s0))
    assert q == pytest.approx(np.linalg.norm(r - s1) - np.linalg.norm(x0[:3] - s0), rel=1e-14)


# --- horizon sensor (UNF c = 3 orbit navigation) -----------------------------------------------
def _horizon_case(seed, a_f=A_F, b_f=B_F, gamma=20.0, r_km=7000.0, az=0.7, dep=None):
    rng = np.random.default_rng(seed)
    r, v = _leo(rng, r_km)
    if dep is None:
        dep = math.acos(a_f / r_km) + 0.01  # boresight about the horizon
    axes = np.asarray(ob.horizon_sensor_axes(r, v, az, dep))
    return r, v, axes, a_f, b_f, gamma


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_horizon_tangent_point_is_on_the_ellipse_and_its_polar_line(seed):
    r, v, axes, a_f, b_f, gamma = _horizon_case(seed)
    g = {k: np.asarray(x) for k, x in ob.horizon_geometry(r, axes, POLE, a_f, b_f, gamma).items()}
    xt, yt, a, b = g["x_t"], g["y_t"], g["a_h"], g["b_h"]
    assert xt**2 / a**2 + yt**2 / b**2 == pytest.approx(1.0, abs=1e-14)  # on the ellipse
    assert xt * g["x_v"] / a**2 + yt * g["y_v"] / b**2 == pytest.approx(1.0, abs=1e-13)  # polar line
    assert abs(np.dot(g["rho_h"] + r, axes[2])) < 1e-9  # the tangent point is in the scan plane
    assert np.dot(g["rho_h"], axes[0]) > 0.0  # ahead, in the azimuth direction
    assert a >= b - 1e-12 and a == pytest.approx(a_f + gamma)


@pytest.mark.parametrize("r_km,gamma", [(6700.0, 0.0), (7000.0, 20.0), (42164.0, 40.0)])
def test_horizon_angle_sphere_limit_is_the_analytic_depression(r_km, gamma):
    """Sphere of radius R raised by gamma, boresight horizontal: psi = -arccos((R + gamma)/r)."""
    r, v, axes, a_f, _, _ = _horizon_case(1, b_f=A_F, gamma=gamma, r_km=r_km, dep=0.0)
    psi = float(ob.horizon_angle(r, np.zeros(3), axes, POLE, A_F, A_F, gamma))
    assert psi == pytest.approx(-math.acos((A_F + gamma) / r_km), rel=1e-13)
    _, dgam, rho_h = (np.asarray(x) for x in ob.horizon_angle_partials(r, np.zeros(3), axes, POLE, A_F, A_F, gamma))
    assert float(rho_h) == pytest.approx(math.sqrt(r_km**2 - (A_F + gamma) ** 2), rel=1e-12)
    assert float(dgam) == pytest.approx(1.0 / float(rho_h), rel=1e-12)  # +1/rho_H (UNF: -1/r_rho, sign)


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_horizon_partials_match_central_differences_of_the_tangent_geometry(seed):
    r, v, axes, a_f, b_f, gamma = _horizon_case(seed)
    body = np.zeros(3)
    h_sc, dgam, rho_h = (np.asarray(x) for x in ob.horizon_angle_partials(r, body, axes, POLE, a_f, b_f, gamma))
    fd = _central(lambda x: ob.horizon_angle(x, body, axes, POLE, a_f, b_f, gamma), r, H_REL * 7000.0)
    _close(h_sc[:3], fd)
    assert np.all(h_sc[3:] == 0.0)
    # n / rho_H: perpendicular to the line of sight, magnitude 1/rho_H
    assert (
        abs(np.dot(h_sc[:3], axes @ axes.T @ np.asarray(ob.horizon_geometry(r, axes, POLE, a_f, b_f, gamma)["rho_h"])))
        < 1e-12
    )
    assert np.linalg.norm(h_sc[:3]) == pytest.approx(1.0 / float(rho_h), rel=1e-9)
    fd_g = _central(lambda g: ob.horizon_angle(r, body, axes, POLE, a_f, b_f, g[0]), [gamma], H_REL * 100.0)
    _close([dgam], fd_g)
    assert abs(float(dgam) * float(rho_h) - 1.0) < 5e-3  # within the flattening of +1/rho_H


def test_horizon_partials_in_an_equatorial_scan_plane():
    """Scan plane normal along the pole: the limb is a circle (the routine's special case)."""
    r = np.array([7000.0, 0.0, 0.0])
    v = np.array([0.0, 7.5, 0.0])
    axes = np.asarray(ob.horizon_sensor_axes(r, v, 0.0, 0.3))
    assert abs(abs(axes[2] @ POLE) - 1.0) < 1e-15
    psi = float(ob.horizon_angle(r, np.zeros(3), axes, POLE, A_F, B_F, 0.0))
    assert psi == pytest.approx(0.3 - math.acos(A_F / 7000.0), rel=1e-12)
    h_sc = np.asarray(ob.horizon_angle_partials(r, np.zeros(3), axes, POLE, A_F, B_F, 0.0)[0])
    _close(h_sc[:3], _central(lambda x: ob.horizon_angle(x, np.zeros(3), axes, POLE, A_F, B_F, 0.0), r, 0.05))


# --- altitude (UNF c = 4) ---------------------------------------------------------------------
@pytest.mark.parametrize("geodetic", [0.0, 1.0])
@pytest.mark.parametrize("seed", [0, 1])
def test_altitude_partials_match_central_differences(geodetic, seed):
    rng = np.random.default_rng(seed)
    r, _ = _leo(rng, 6700.0)
    body = rng.normal(size=3) * 10.0
    sc = body + r
    args = (POLE, A_F, B_F, A_F, geodetic)
    h = np.asarray(ob.altitude_partials(sc, body, *args))
    _close(h[:3], _central(lambda x: ob.altitude(x, body, *args), sc, H_REL * 6700.0))
    assert np.all(h[3:] == 0.0)


@pytest.mark.parametrize("lat_deg,h_km", [(0.0, 300.0), (28.5, 400.0), (-63.0, 1200.0), (89.9, 500.0)])
def test_geodetic_altitude_against_the_closed_form_inverse(lat_deg, h_km):
    lat, lon = math.radians(lat_deg), 0.4
    e2 = 1.0 - (B_F / A_F) ** 2
    n = A_F / math.sqrt(1.0 - e2 * math.sin(lat) ** 2)
    r = np.array(
        [
            (n + h_km) * math.cos(lat) * math.cos(lon),
            (n + h_km) * math.cos(lat) * math.sin(lon),
            (n * (1 - e2) + h_km) * math.sin(lat),
        ]
    )
    got = float(ob.altitude(r, np.zeros(3), POLE, A_F, B_F, A_F, 1.0))
    assert got == pytest.approx(h_km, abs=1e-9)
    sph = float(ob.altitude(r, np.zeros(3), POLE, A_F, B_F, A_F, 0.0))
    assert sph == pytest.approx(np.linalg.norm(r) - A_F, rel=1e-15)


# --- beacon visibility cone (digest A.7.4) -----------------------------------------------------
def test_beacon_visibility_cone_and_passes():
    r_b = np.array([6378.0, 0.0, 0.0])
    up = np.array([7000.0, 0.0, 0.0])
    low = np.array([6378.0 + 10.0, 200.0, 0.0])  # ~3 deg above the horizon
    far = np.array([6378.0 + 100.0, 5000.0, 0.0])
    vis = beacon_visible(np.stack([up, low, far]), r_b, math.radians(5.0), 3000.0)
    assert vis.tolist() == [True, False, False]  # overhead; below 5 deg; beyond 3000 km
    assert beacon_visible(low, r_b, math.radians(1.0), 3000.0)
    t = np.arange(10.0)
    mask = np.array([0, 1, 1, 0, 0, 1, 1, 1, 0, 1], dtype=bool)
    passes = visibility_passes(t, mask)
    assert passes == [(1.0, 2.0), (5.0, 7.0), (9.0, 9.0)]
    # a circular equatorial orbit over a beacon on the equator: one pass centred on t = 0
    t = np.linspace(-1500.0, 1500.0, 61)
    ang = 2 * math.pi * t / 5828.5
    r_p = 6778.0 * np.stack([np.cos(ang), np.sin(ang), np.zeros_like(ang)], axis=1)
    ((a, b),) = beacon_passes(t, r_p, r_b, math.radians(10.0))
    assert a == -b and 0.0 < b < 1500.0
