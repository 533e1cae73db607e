"""Measurement models (FRACAS TRAKM): values against independent definitions, analytic
partials against AD, and the cancellation-free differenced data types against a 50-digit
reference.  (Station-location partials through STAPRL are checked against central
differences in test_trakm.py, on the H columns the engine uses.)

Rebuilt equations checked here (the scan garbles them): TRAKM eq. 10 (3-way Doppler is the
sum of range *rates*), eq. 15 (exact differenced range dr^T (p1 + p2)/(rho1 + rho2)),
eq. 37 (d delta / d x = 2 R_p u^T / (rho sqrt(rho^2 - R_p^2))), and the topocentric azimuth
and elevation partials that replace eqs. 18-31.
"""

import math
from decimal import Decimal, getcontext

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from fracas import _jax  # noqa: F401
from fracas.measurements import models as M
from fracas.measurements.stations import DSN_STATIONS, station_state

EPS = np.finfo(np.float64).eps


def _station_rv(name, et):
    st = DSN_STATIONS[name]
    r, v = station_state(st.radius_km, st.latitude_rad, st.longitude_rad, et)
    return np.asarray(r), np.asarray(v)


def _geometry(rng, distance_km, et):
    """Heliocentric-like origin: Earth at ~1 AU, spacecraft at `distance_km` from it in a
    random direction, stations Goldstone and Canberra."""
    earth_r = np.array([1.0e8, 1.1e8, 4.7e7]) + rng.normal(size=3) * 1e6
    earth_v = rng.normal(size=3) * 20.0
    d = rng.normal(size=3)
    sc_r = earth_r + distance_km * d / np.linalg.norm(d)
    sc_v = earth_v + rng.normal(size=3) * 3.0
    s1, s1v = _station_rv("goldstone", et)
    s2, s2v = _station_rv("canberra", et)
    return sc_r, sc_v, earth_r, earth_v, s1, s1v, s2, s2v


def _args(kind, g, rng):
    sc_r, sc_v, earth_r, earth_v, s1, s1v, _, _ = g
    n = M.N_STATIONS[kind]
    if n == 1:
        return (sc_r, sc_v, earth_r, earth_v, s1, s1v)
    if n == 2:
        return g
    body_r = sc_r + rng.normal(size=3) * 5e4  # target body ~1e5 km away
    if kind == "star_planet_angle":
        d = rng.normal(size=3)
        return (sc_r, body_r, d / np.linalg.norm(d))
    return (sc_r, body_r, 3396.19)


# --- analytic partials against AD ------------------------------------------------------
@pytest.mark.parametrize("kind", M.TRAKM_KINDS)  # the onboard kinds: tests/measurements/test_onboard.py
def test_analytic_partials_match_ad(kind):
    # Analytic and AD Jacobians evaluate the same algebra in a different order: each carries
    # O(10) roundings of relative size eps = 2.2e-16, amplified by the geometry's condition
    # (1/cos(beta), 1/sin(gamma), 1/h^2: at most ~10 for these seeded random geometries), so
    # they agree to ~1e-14 relative per block; 1e-12 leaves a 100x margin.  Exact-zero blocks
    # (velocity partials of range/angles) must be exactly zero.  Distances 4e4 km (near
    # Earth), 4e5 km (lunar) and 3e8 km (interplanetary) cover both regimes of the
    # differenced kinds.
    rng = np.random.default_rng(2024)
    value_fn, partial_fn = M.VALUE_FUNCTIONS[kind], M.PARTIAL_FUNCTIONS[kind]
    cases = []
    for dist in (4e4, 4e5, 3e8):
        for _ in range(2):
            g = _geometry(rng, dist, 6.0e8 + rng.uniform(0, 86400.0))
            cases.append(_args(kind, g, rng))
    n_args = len(cases[0])
    stacked = tuple(jnp.asarray(np.array([c[i] for c in cases]), dtype=jnp.float64) for i in range(n_args))

    @jax.jit
    def both(*a):
        ad = jax.vmap(jax.jacfwd(value_fn, argnums=tuple(range(n_args))))(*a)
        an = jax.vmap(partial_fn)(*a)
        return ad, an

    ad, an = both(*stacked)
    ad = [np.asarray(x) for x in ad]
    an = [np.asarray(x) for x in an]
    n_st = M.N_STATIONS[kind]
    if n_st > 0:
        # blocks: spacecraft (r, v) = args 0, 1; station k (r, v) = args 4 + 2k, 5 + 2k
        pairs = [(np.concatenate([ad[0], ad[1]], axis=1), an[0])]
        pairs += [(np.concatenate([ad[4 + 2 * k], ad[5 + 2 * k]], axis=1), an[1 + k]) for k in range(n_st)]
        # Earth: minus the spacecraft partials
        pairs.append((np.concatenate([ad[2], ad[3]], axis=1), -an[0]))
    else:
        pairs = [(ad[0], an[0][:, :3]), (np.zeros_like(ad[0]), an[0][:, 3:]), (ad[1], an[1])]
        if kind == "planet_diameter":
            pairs.append((ad[2][:, None], np.asarray(an[2])[:, None]))
    for ad_b, an_b in pairs:
        for row_ad, row_an in zip(ad_b, an_b):
            for sl in (slice(0, 3), slice(3, None)):
                a, b = row_ad[sl], row_an[sl]
                assert np.linalg.norm(a - b) <= 1e-12 * np.linalg.norm(a), (kind, a, b)


# --- values against independent definitions --------------------------------------------
def test_doppler_is_time_derivative_of_range():
    # rho_dot must be d rho / dt along the relative motion: central difference of range2
    # over +-h of straight-line motion, geocentric (earth at the origin, so positions carry
    # no 1e8 km rounding).  With |w| ~ 5 km/s and rho ~ 4e4 km: truncation
    # h^2/6 |w|^3/rho^2 ~ 3e-11 km/s and rounding eps rho / h ~ 1e-10 km/s at h = 0.05 s;
    # tolerance 1e-9 km/s.
    rng = np.random.default_rng(5)
    sc_r, sc_v, earth_r, earth_v, s1, s1v, _, _ = _geometry(rng, 4e4, 6.0e8)
    x, w = sc_r - earth_r, sc_v - earth_v
    z = np.zeros(3)
    h = 0.05
    rp = float(M.range2(x + h * w, w, z, z, s1 + h * s1v, s1v))
    rm = float(M.range2(x - h * w, w, z, z, s1 - h * s1v, s1v))
    assert abs((rp - rm) / (2 * h) - float(M.doppler2(sc_r, sc_v, earth_r, earth_v, s1, s1v))) < 1e-9


def test_three_way_is_sum_of_two_way():
    # TRAKM eqs. 9-10 (eq. 10 rebuilt: ranges *rates* on the right): exact sums up to one
    # rounding of the sum (relative 1e-15).
    rng = np.random.default_rng(6)
    g = _geometry(rng, 4e5, 6.1e8)
    one = lambda f, k: float(f(*g[:4], g[4 + 2 * k], g[5 + 2 * k]))
    r3, d3 = float(M.range3(*g)), float(M.doppler3(*g))
    assert abs(r3 - one(M.range2, 0) - one(M.range2, 1)) <= 1e-15 * abs(r3)
    assert abs(d3 - one(M.doppler2, 0) - one(M.doppler2, 1)) <= 1e-15 * abs(d3) + 1e-16


@pytest.mark.parametrize(
    "offset, az, el",
    [
        ((0.0, 0.0, 1000.0), 0.0, 0.0),  # due north on the horizon
        ((0.0, 1000.0, 0.0), math.pi / 2, 0.0),  # due east
        ((0.0, -1000.0, 0.0), 3 * math.pi / 2, 0.0),  # due west
        ((0.0, 0.0, -1000.0), math.pi, 0.0),  # due south
        ((1000.0, 1000.0, 0.0), math.pi / 2, math.pi / 4),  # east, 45 deg up
        ((-1000.0, 0.0, 1000.0), 0.0, -math.pi / 4),
    ],  # north, 45 deg below horizon
)
def test_azimuth_elevation_conventions(offset, az, el):
    # Station on the equator at the ICRF x axis: up = x, east = y, north = z.  Azimuth from
    # north toward east in [0, 2 pi) (TRAKM Fig. 2), elevation above the local horizontal.
    # Exact geometry: agreement to a few ulps (1e-14 rad).
    st_r = np.array([6378.0, 0.0, 0.0])
    z = np.zeros(3)
    sc_r = st_r + np.array(offset)
    a = float(M.azimuth(sc_r, z, z, z, st_r, z))
    e = float(M.elevation(sc_r, z, z, z, st_r, z))
    assert abs((a - az + math.pi) % (2 * math.pi) - math.pi) < 1e-14
    assert abs(e - el) < 1e-14


def test_elevation_matches_trakm_eq17_and_rotated_frame():
    # Independent formulas at a generic station: TRAKM eq. 17, beta = asin(u . r1/|r1|), and
    # the azimuth from an explicitly built ENU rotation matrix (phi, lambda from st_r).
    # Both are well conditioned here (|beta| < 60 deg): 1e-13 rad.
    rng = np.random.default_rng(8)
    sc_r, _, earth_r, _, s1, _, _, _ = _geometry(rng, 4e4, 6.2e8)
    z = np.zeros(3)
    p = sc_r - earth_r - s1
    beta = math.asin(p @ s1 / (np.linalg.norm(p) * np.linalg.norm(s1)))
    assert abs(beta) < math.radians(60)
    assert abs(float(M.elevation(sc_r, z, earth_r, z, s1, z)) - beta) < 1e-13
    lam = math.atan2(s1[1], s1[0])
    phi = math.atan2(s1[2], math.hypot(s1[0], s1[1]))
    enu = np.array(
        [
            [-math.sin(lam), math.cos(lam), 0.0],
            [-math.sin(phi) * math.cos(lam), -math.sin(phi) * math.sin(lam), math.cos(phi)],
            [math.cos(phi) * math.cos(lam), math.cos(phi) * math.sin(lam), math.sin(phi)],
        ]
    )
    e_, n_, _ = enu @ p
    alpha = math.atan2(e_, n_) % (2 * math.pi)
    assert abs(float(M.azimuth(sc_r, z, earth_r, z, s1, z)) - alpha) < 1e-13


def test_star_planet_angle_and_diameter_definitions():
    # gamma against arccos (well conditioned at gamma ~ 1 rad): 1e-14 rad.  delta against
    # the tangent-cone half angle tan(delta/2) = R_p / sqrt(rho^2 - R_p^2) (an independent
    # formula for the same angle, eq. 36): 1e-15 rad at delta ~ 0.07 rad.
    sc_r = np.array([1.0e8, 2.0e7, -3.0e6])
    body_r = sc_r + np.array([3.0e4, 4.0e4, 0.0])
    d = np.array([math.cos(0.9), 0.0, math.sin(0.9)])
    u = (body_r - sc_r) / 5.0e4
    assert abs(float(M.star_planet_angle(sc_r, body_r, d)) - math.acos(d @ u)) < 1e-14
    rp = 1737.4
    delta = 2.0 * math.atan(rp / math.sqrt(5.0e4**2 - rp**2))
    assert abs(float(M.planet_diameter(sc_r, body_r, rp)) - delta) < 1e-15


# --- differenced data types: cancellation ---------------------------------------------
def _decimal_reference(sc_r, sc_v, earth_r, earth_v, s1, s1v, s2, s2v):
    """rho1 - rho2, rho_dot1 - rho_dot2, u1 - u2 and g1 - g2 (d rho_dot / d r) in 50-digit
    decimal arithmetic from the exact binary values of the float64 inputs."""
    getcontext().prec = 50
    dec = lambda v: [Decimal(float(x)) for x in v]
    p1 = [a - b - c for a, b, c in zip(dec(sc_r), dec(earth_r), dec(s1))]
    p2 = [a - b - c for a, b, c in zip(dec(sc_r), dec(earth_r), dec(s2))]
    w1 = [a - b - c for a, b, c in zip(dec(sc_v), dec(earth_v), dec(s1v))]
    w2 = [a - b - c for a, b, c in zip(dec(sc_v), dec(earth_v), dec(s2v))]
    r1, r2 = sum(x * x for x in p1).sqrt(), sum(x * x for x in p2).sqrt()
    u1, u2 = [x / r1 for x in p1], [x / r2 for x in p2]
    rd1 = sum(a * b for a, b in zip(u1, w1))
    rd2 = sum(a * b for a, b in zip(u2, w2))
    g1 = [(w - rd1 * u) / r1 for w, u in zip(w1, u1)]
    g2 = [(w - rd2 * u) / r2 for w, u in zip(w2, u2)]
    vec = lambda a, b: np.array([float(x - y) for x, y in zip(a, b)])
    return float(r1 - r2), float(rd1 - rd2), vec(u1, u2), vec(g1, g2)


def test_differenced_types_keep_full_precision_at_interplanetary_distance():
    # Spacecraft 2e8..1e9 km from Earth, Goldstone - Canberra baseline ~1e4 km: the two
    # ranges agree to ~5 digits, so the naive float64 difference rho1 - rho2 keeps only
    # ~11 significant digits (each range carries ~ulp(3e8 km) ~ 6e-8 km of rounding).  The
    # cancellation-free forms (TRAKM eqs. 14-16, eq. 15 rebuilt) must match the 50-digit
    # reference to a few ulps: 2e-15 relative (observed <= 4e-16) for the values and for
    # the spacecraft partials u1 - u2 and g1 - g2.  The naive range difference is shown to
    # be worse by > 1e-12 relative in at least one of the 8 seeded cases (observed up to
    # 4e-10), i.e. the test would fail if diff_range were computed naively.
    rng = np.random.default_rng(7)
    f_dr, f_dd = jax.jit(M.diff_range), jax.jit(M.diff_doppler)
    f_r2, f_p = jax.jit(M.range2), jax.jit(M.diff_doppler_partials)
    naive_worst = 0.0
    for i in range(8):
        et = 7.0e8 + 5000.0 * i
        s1, s1v = _station_rv("goldstone", et)
        s2, s2v = _station_rv("canberra", et)
        earth_r = np.array([1.0e8, 1.1e8, 4.7e7]) + rng.normal(size=3) * 1e6
        earth_v = rng.normal(size=3) * 20.0
        d = rng.normal(size=3)
        sc_r = earth_r + rng.uniform(2e8, 1e9) * d / np.linalg.norm(d)
        sc_v = earth_v + rng.normal(size=3) * 20.0
        args = (sc_r, sc_v, earth_r, earth_v, s1, s1v, s2, s2v)
        ref_dr, ref_dd, ref_du, ref_dg = _decimal_reference(*args)
        assert abs(float(f_dr(*args)) - ref_dr) <= 2e-15 * abs(ref_dr)
        assert abs(float(f_dd(*args)) - ref_dd) <= 2e-15 * abs(ref_dd)
        h_sc = np.asarray(f_p(*args)[0])
        assert np.linalg.norm(h_sc[3:] - ref_du) <= 2e-15 * np.linalg.norm(ref_du)
        assert np.linalg.norm(h_sc[:3] - ref_dg) <= 2e-15 * np.linalg.norm(ref_dg)
        naive = float(f_r2(sc_r, sc_v, earth_r, earth_v, s1, s1v)) - float(f_r2(sc_r, sc_v, earth_r, earth_v, s2, s2v))
        naive_worst = max(naive_worst, abs(naive - ref_dr) / abs(ref_dr))
    assert naive_worst > 1e-12
