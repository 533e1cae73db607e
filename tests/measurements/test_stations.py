"""Stations: DSN coordinates, Earth rotation angle, station state and STAPRL partials.

References are independent of the code under test: published geodetic coordinates (WGS84),
exact rational arithmetic for the IAU 2000 rotation angle, AD of the state for the
velocity, and central finite differences for the STAPRL partials (which FRACAS gives in an
ecliptic frame, garbled by the scan; they were rebuilt for the equatorial frame).
"""

import math
from fractions import Fraction

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from fracas import _jax  # noqa: F401
from fracas.measurements.stations import (
    DSN_STATIONS,
    ERA_RATE_RAD_S,
    earth_rotation_angle,
    station_partials,
    station_state,
)

EPS = np.finfo(np.float64).eps
_state = jax.jit(station_state)
_partials = jax.jit(station_partials)
_era = jax.jit(earth_rotation_angle)

# WGS84 ellipsoid, for the geodetic -> cartesian reference only.
_A_KM, _F = 6378.137, 1.0 / 298.257223563
_E2 = _F * (2.0 - _F)


def _geodetic_to_xyz(lat_deg, lon_deg, h_km):
    lat, lon = math.radians(lat_deg), math.radians(lon_deg)
    n = _A_KM / math.sqrt(1.0 - _E2 * math.sin(lat) ** 2)
    return np.array(
        [
            (n + h_km) * math.cos(lat) * math.cos(lon),
            (n + h_km) * math.cos(lat) * math.sin(lon),
            (n * (1.0 - _E2) + h_km) * math.sin(lat),
        ]
    )


def _fixed_xyz(st):
    c = math.cos(st.latitude_rad)
    return st.radius_km * np.array(
        [c * math.cos(st.longitude_rad), c * math.sin(st.longitude_rad), math.sin(st.latitude_rad)]
    )


def test_goldstone_matches_published_geodetic_coordinates():
    # DSS-14 geodetic coordinates from the same JPL 810-005 table: 35d25'33.24312" N,
    # 243d06'37.66244" E, h = 1001.390 m.  Angles are quoted to 1e-5" (0.3 mm) and h to
    # 1 mm, so the geocentric (R, phi, lambda) must reproduce the point to ~1 mm: 1 cm tol.
    ref = _geodetic_to_xyz(35 + 25 / 60 + 33.24312 / 3600, 243 + 6 / 60 + 37.66244 / 3600, 1.001390)
    got = _fixed_xyz(DSN_STATIONS["goldstone"])
    assert np.max(np.abs(got - ref)) < 1e-5


@pytest.mark.parametrize(
    "name, lat_geodetic_deg, lon_deg",
    [("madrid", 40.4314, -4.2480), ("canberra", -35.4024, 148.9813)],
)
def test_other_dsn_stations_roughly_where_published(name, lat_geodetic_deg, lon_deg):
    # Coarse published geodetic positions of DSS-63 and DSS-43 (to 1e-4 deg): a 0.01 deg
    # (~1 km) tolerance catches a wrong digit in the table without needing the ellipsoid
    # height.  Geocentric latitude from geodetic: tan(phi_c) = (1 - e^2) tan(phi_g) at h = 0
    # (h ~ 1 km shifts it by < 1e-4 deg).
    st = DSN_STATIONS[name]
    lat_c = math.degrees(math.atan((1.0 - _E2) * math.tan(math.radians(lat_geodetic_deg))))
    assert abs(math.degrees(st.latitude_rad) - lat_c) < 0.01
    assert abs(math.degrees(st.longitude_rad) - lon_deg) < 0.01
    assert 6356.0 < st.radius_km < 6380.0


def _era_exact(et_s: float) -> float:
    """IAU 2000 ERA in exact rational arithmetic (UT1 = TDB - 69.184 s), reduced to [0, 1)
    revolutions before the one rounding to float."""
    tu = (Fraction(et_s) - Fraction(69184, 1000)) / 86400
    rev = Fraction("0.7790572732640") + Fraction("1.00273781191135448") * tu
    return float(rev - math.floor(rev)) * 2.0 * math.pi


@pytest.mark.parametrize("et_s", [69.184, 8.0e8 + 0.25, -3.2e8 + 1234.5678, 1.5e9])
def test_earth_rotation_angle_exact_reference(et_s):
    # The day split keeps the float64 evaluation at ~1e-15 rad (roundings of O(1) revolutions,
    # the only large term being frac(Tu) computed exactly); 1e-13 rad is 100x that margin
    # and 100x below what a naive 2 pi (0.779 + 1.0027 Tu) would give at Tu ~ 1e4 days.
    ref = _era_exact(et_s)
    # runtime argument, and a literal et that XLA constant-folds (it once reassociated the
    # day split there, a 1e-12 rad error; the optimization barrier prevents it)
    for got in (float(_era(et_s)), float(jax.jit(lambda: earth_rotation_angle(et_s))())):
        diff = (got - ref + math.pi) % (2.0 * math.pi) - math.pi
        assert abs(diff) < 1e-13
    if et_s == 69.184:  # UT1 = J2000.0: theta = 2 pi 0.7790572732640 (IERS 2010, eq. 5.15)
        assert abs(got - 2.0 * math.pi * 0.7790572732640) < 1e-14


def test_station_state_is_rotated_published_itrf_vector():
    # The published ITRF cartesian coordinates (m), rotated by the ERA about z, must equal
    # station_state built from (R, phi, lambda): catches any slip in the spherical
    # conversion or the rotation sense.  Agreement is limited by float64 rounding of a
    # 6400 km vector (~1e-12 km): 1e-9 km tolerance.
    itrf_m = {
        "goldstone": (-2_353_621.420, -4_641_341.472, 3_677_052.318),
        "madrid": (4_849_092.518, -360_180.348, 4_115_109.251),
        "canberra": (-4_460_894.917, 2_682_361.507, -3_674_748.152),
    }
    et = 6.5e8 + 321.0
    th = float(_era(et))
    rot = np.array([[math.cos(th), -math.sin(th), 0.0], [math.sin(th), math.cos(th), 0.0], [0.0, 0.0, 1.0]])
    for name, xyz in itrf_m.items():
        st = DSN_STATIONS[name]
        r, v = _state(st.radius_km, st.latitude_rad, st.longitude_rad, et)
        assert np.max(np.abs(np.asarray(r) - rot @ (np.array(xyz) / 1000.0))) < 1e-9
        # v = omega z x r: |v| = omega R cos(phi) ~ 0.38 km/s, checked to rounding (1e-15 km/s)
        omega_cross_r = ERA_RATE_RAD_S * np.array([-float(r[1]), float(r[0]), 0.0])
        assert np.max(np.abs(np.asarray(v) - omega_cross_r)) < 1e-15


def test_station_velocity_is_time_derivative_of_position():
    # v must be d r / d et of the same model (rate = d theta / dt of the ERA formula): AD
    # differentiates the identical expression, so they agree to rounding, 1e-15 km/s on
    # |v| ~ 0.4 km/s.
    st = DSN_STATIONS["canberra"]
    drdt = jax.jit(jax.jacfwd(lambda t: station_state(st.radius_km, st.latitude_rad, st.longitude_rad, t)[0]))(4.4e8)
    _, v = _state(st.radius_km, st.latitude_rad, st.longitude_rad, 4.4e8)
    assert np.max(np.abs(np.asarray(drdt) - np.asarray(v))) < 1e-15


@pytest.mark.parametrize("name", sorted(DSN_STATIONS))
def test_station_partials_central_differences(name):
    # Central differences of station_state w.r.t. (R, phi, lambda).
    # R: r, v are linear in R, so only rounding counts: eps |r| / h = 1e-16 * 6400 / 1 km
    #    ~ 1e-12 relative to |dr/dR| = 1 -> tolerance 1e-9 relative.
    # phi, lambda: h = 1e-5 rad balances truncation h^2 R / 6 ~ 1e-7 km against rounding
    #    eps R / h ~ 7e-8 km, i.e. ~3e-11 of |dr/dangle| ~ R -> tolerance 1e-8 relative.
    # Velocity rows are the same functions times omega: same relative bounds.
    st = DSN_STATIONS[name]
    et = 5.0e8 + 77.0
    p0 = np.array([st.radius_km, st.latitude_rad, st.longitude_rad])
    an = np.asarray(_partials(*p0, et))
    steps = (1.0, 1e-5, 1e-5)
    for k, h in enumerate(steps):
        plus, minus = p0.copy(), p0.copy()
        plus[k] += h
        minus[k] -= h
        fp = np.concatenate([np.asarray(a) for a in _state(*plus, et)])
        fm = np.concatenate([np.asarray(a) for a in _state(*minus, et)])
        fd = (fp - fm) / (2.0 * h)
        tol = 1e-9 if k == 0 else 1e-8
        for rows in (slice(0, 3), slice(3, 6)):
            scale = np.linalg.norm(an[rows, k])
            assert np.linalg.norm(fd[rows] - an[rows, k]) <= tol * scale, (name, k, rows)


def test_station_partials_match_ad():
    # The rebuilt STAPRL formulas against AD of station_state: same algebra, different
    # evaluation order, so agreement to a few ulps of R (6400 km): 1e-12 relative.
    st = DSN_STATIONS["madrid"]
    et = -1.0e8

    def f(p):
        r, v = station_state(p[0], p[1], p[2], et)
        return jnp.concatenate([r, v])

    p0 = jnp.asarray([st.radius_km, st.latitude_rad, st.longitude_rad], dtype=jnp.float64)
    ad = np.asarray(jax.jit(jax.jacfwd(f))(p0))
    an = np.asarray(_partials(st.radius_km, st.latitude_rad, st.longitude_rad, et))
    for k in range(3):
        for rows in (slice(0, 3), slice(3, 6)):
            assert np.linalg.norm(ad[rows, k] - an[rows, k]) <= 1e-12 * np.linalg.norm(ad[rows, k])
