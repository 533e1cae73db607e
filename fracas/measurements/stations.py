"""Tracking stations: geocentric ICRF state and its partials w.r.t. the station location
(FRACAS STAPRL, section 5.3.17).

A station is given by geocentric spherical coordinates (R, phi, lambda): radius (km),
geocentric latitude (rad) and east longitude (rad) in the Earth-fixed frame.  Its inertial
(ICRF, km) position is the rotation of the body-fixed vector about the ICRF z axis by the
IAU 2000 Earth rotation angle theta(UT1):

    psi = lambda + theta
    r   = R (cos phi cos psi, cos phi sin psi, sin phi)
    v   = omega x r = omega R cos phi (-sin psi, cos psi, 0)

Simplifications, all deliberate for covariance-analysis geometry:

* precession, nutation and polar motion are ignored (the Earth's pole is the ICRF z axis):
  this rotates station positions in inertial space by at most a few tenths of a degree
  over decades, which does not matter for tracking geometry in an error analysis;
* UT1 = TDB - 69.184 s (TT - UTC with 37 leap seconds, TDB - TT and UT1 - UTC < 1 s
  neglected);
* the rotation rate is d(theta)/dt of the IAU 2000 formula (:data:`ERA_RATE_RAD_S`, a local
  constant derived from the ERA coefficients, so that v is exactly dr/dt of the model; it
  equals ``constants.EARTH_ROTATION_RAD_S`` to the last bit but one).

FRACAS STAPRL works in the ecliptic frame (its partials carry cos/sin of the obliquity)
and the scan of its formulas is garbled (repeated rows, lost signs, G undefined).  The
partials here are rebuilt for the equatorial frame by differentiating the r, v above; they
are the positive partials d(r, v)/d(R, phi, lambda) (STAPRL returned their negatives, the
sensitivity of the station-relative spacecraft state).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import jax
import jax.numpy as jnp
from jax import Array
from jax.typing import ArrayLike

from fracas import _jax  # noqa: F401  (x64 first)
from fracas.constants import DAY_S

__all__ = [
    "Station",
    "DSN_STATIONS",
    "ERA_RATE_RAD_S",
    "UT1_MINUS_TDB_S",
    "earth_rotation_angle",
    "station_state",
    "station_partials",
    "station_from_itrf",
]

# IAU 2000 Earth rotation angle (IERS Conventions 2010, eq. 5.15):
#   theta = 2 pi (0.7790572732640 + 1.00273781191135448 Tu),  Tu = JD(UT1) - 2451545.0
_ERA_0 = 0.7790572732640  # revolutions at J2000 UT1
_ERA_EXCESS = 0.00273781191135448  # revolutions per UT1 day beyond one
ERA_RATE_RAD_S = 2.0 * math.pi * (1.0 + _ERA_EXCESS) / DAY_S  # rad/s, d(theta)/dt
UT1_MINUS_TDB_S = -69.184  # s, UT1 ~ UTC = TT - 69.184 s (37 leap seconds); TDB - TT ignored


@dataclass(frozen=True)
class Station:
    """A tracking station in geocentric spherical coordinates (STAPRL's R, phi, lambda).

    ``radius_km``: distance from the Earth's centre (km); ``latitude_rad``: geocentric
    latitude (rad); ``longitude_rad``: east longitude in the Earth-fixed frame (rad).
    """

    name: str
    radius_km: float
    latitude_rad: float
    longitude_rad: float


def station_from_itrf(name: str, x_m: float, y_m: float, z_m: float) -> Station:
    """Station from Earth-fixed (ITRF) cartesian coordinates in metres (plain math, no jax)."""
    x, y, z = x_m / 1000.0, y_m / 1000.0, z_m / 1000.0
    return Station(
        name=name,
        radius_km=math.sqrt(x * x + y * y + z * z),
        latitude_rad=math.atan2(z, math.hypot(x, y)),
        longitude_rad=math.atan2(y, x),
    )


# DSN 70-m antennas, ITRF93 cartesian coordinates (m) from JPL DSN Telecommunications Link
# Design Handbook 810-005, Module 301 (as reproduced in the NAIF kernel comments of
# earthstns_itrf93_201023.bsp); the station drift (cm/yr) is far below the ~10 m needed.
DSN_STATIONS: dict[str, Station] = {
    "goldstone": station_from_itrf("goldstone", -2_353_621.420, -4_641_341.472, 3_677_052.318),  # DSS-14
    "madrid": station_from_itrf("madrid", 4_849_092.518, -360_180.348, 4_115_109.251),  # DSS-63
    "canberra": station_from_itrf("canberra", -4_460_894.917, 2_682_361.507, -3_674_748.152),  # DSS-43
}


def earth_rotation_angle(et_s: ArrayLike) -> Array:
    """IAU 2000 Earth rotation angle theta (rad, in [0, 2 pi)) at TDB seconds past J2000.

    theta = 2 pi frac(0.7790572732640 + 0.00273781191135448 Tu + frac(Tu)),
    Tu = (et_s - 69.184 s) / 86400 s (UT1 ~ TDB - 69.184 s).  The whole-day part of et_s is
    split off first (exactly, in float64), so the angle keeps the full precision of et_s
    (about 1e-11 rad at et_s ~ 1e9 s) instead of losing digits to Tu ~ 1e4 days.
    """
    et = jnp.asarray(et_s, dtype=jnp.float64)
    days = jnp.floor(et / DAY_S)
    # exact: both terms are multiples of ulp(et).  The barrier stops XLA from reassociating
    # (et - days*86400) - 69.184 into (et - 69.184) - days*86400, which it did when
    # constant-folding a jitted call with a literal et (an error of ~1e-12 rad).
    sec_of_day = jax.lax.optimization_barrier(et - days * DAY_S)
    tu = (et + UT1_MINUS_TDB_S) / DAY_S
    rev = _ERA_0 + _ERA_EXCESS * tu + (sec_of_day + UT1_MINUS_TDB_S) / DAY_S
    return 2.0 * jnp.pi * jnp.mod(rev, 1.0)


def _trig(latitude_rad: ArrayLike, longitude_rad: ArrayLike, et_s: ArrayLike) -> tuple[Array, Array, Array, Array]:
    phi = jnp.asarray(latitude_rad, dtype=jnp.float64)
    psi = jnp.asarray(longitude_rad, dtype=jnp.float64) + earth_rotation_angle(et_s)
    return jnp.cos(phi), jnp.sin(phi), jnp.cos(psi), jnp.sin(psi)


def station_state(
    radius_km: ArrayLike, latitude_rad: ArrayLike, longitude_rad: ArrayLike, et_s: ArrayLike
) -> tuple[Array, Array]:
    """Geocentric ICRF position (km) and velocity (km/s) of a station at TDB ``et_s`` (s).

    r = R (cos phi cos psi, cos phi sin psi, sin phi), v = omega z x r,
    psi = lambda + theta(et_s) (module docstring; FRACAS STAPRL geometry, equatorial frame).
    Returns ``(r (3,), v (3,))``.
    """
    R = jnp.asarray(radius_km, dtype=jnp.float64)
    cphi, sphi, cpsi, spsi = _trig(latitude_rad, longitude_rad, et_s)
    r = R * jnp.stack([cphi * cpsi, cphi * spsi, sphi])
    v = (ERA_RATE_RAD_S * R * cphi) * jnp.stack([-spsi, cpsi, jnp.zeros_like(spsi)])
    return r, v


def station_partials(radius_km: ArrayLike, latitude_rad: ArrayLike, longitude_rad: ArrayLike, et_s: ArrayLike) -> Array:
    """Analytic d(r, v)/d(R, phi, lambda) of :func:`station_state`, shape (6, 3).

    Rows: r_x, r_y, r_z (km), v_x, v_y, v_z (km/s); columns: R (per km), phi, lambda (per
    rad).  FRACAS STAPRL rebuilt in the equatorial frame (the scanned ecliptic formulas are
    garbled), with psi = lambda + theta and omega = :data:`ERA_RATE_RAD_S`:

        dr/dR   = (cphi cpsi, cphi spsi, sphi)
        dr/dphi = R (-sphi cpsi, -sphi spsi, cphi)
        dr/dlam = R (-cphi spsi, cphi cpsi, 0)
        dv/dR   = omega cphi (-spsi, cpsi, 0)
        dv/dphi = -omega R sphi (-spsi, cpsi, 0)
        dv/dlam = -omega R cphi (cpsi, spsi, 0)
    """
    R = jnp.asarray(radius_km, dtype=jnp.float64)
    w = ERA_RATE_RAD_S
    cphi, sphi, cpsi, spsi = _trig(latitude_rad, longitude_rad, et_s)
    zero = jnp.zeros_like(spsi)
    dr_dR = jnp.stack([cphi * cpsi, cphi * spsi, sphi])
    dr_dphi = R * jnp.stack([-sphi * cpsi, -sphi * spsi, cphi])
    dr_dlam = R * jnp.stack([-cphi * spsi, cphi * cpsi, zero])
    east = jnp.stack([-spsi, cpsi, zero])
    dv_dR = (w * cphi) * east
    dv_dphi = (-w * R * sphi) * east
    dv_dlam = (-w * R * cphi) * jnp.stack([cpsi, spsi, zero])
    top = jnp.stack([dr_dR, dr_dphi, dr_dlam], axis=1)
    bottom = jnp.stack([dv_dR, dv_dphi, dv_dlam], axis=1)
    return jnp.concatenate([top, bottom], axis=0)
