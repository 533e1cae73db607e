"""Physical constants and the body catalogue, in canonical units (km, s, kg, rad).

One module holds every constant.  Gravitational parameters are the DE421 values (they
match the ephemeris the positions come from); radii, J2 and pole directions are IAU/
standard values; each entry says where it comes from.  The inertial frame of fracas is
ICRF / EME2000 (the frame of DE421); ecliptic quantities use the IAU 2006 obliquity.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

# --- units and universal constants -------------------------------------------------
AU_KM = 149_597_870.7  # km, IAU 2012 astronomical unit
DAY_S = 86_400.0  # s
SECONDS_PER_DAY = 86_400  # s, int (exact calendar arithmetic)
JULIAN_YEAR_S = 365.25 * DAY_S  # s
J2000_JD = 2_451_545.0  # Julian date (TDB) of J2000.0
G0_KM_S2 = 9.80665e-3  # km/s^2, standard gravity (Isp <-> exhaust velocity)
SPEED_OF_LIGHT_KM_S = 299_792.458  # km/s
SOLAR_FLUX_1AU_W_M2 = 1361.0  # W/m^2, total solar irradiance at 1 AU
# Solar radiation pressure on a perfect absorber at 1 AU: S/c = 4.54e-6 N/m^2.
SOLAR_PRESSURE_1AU_N_M2 = SOLAR_FLUX_1AU_W_M2 / (SPEED_OF_LIGHT_KM_S * 1e3)
OBLIQUITY_J2000_RAD = math.radians(84381.406 / 3600.0)  # IAU 2006 mean obliquity at J2000
EARTH_ROTATION_RAD_S = 7.292115146706979e-5  # rad/s, IERS mean sidereal rate

# --- the span of the DE421 ephemeris served (fracas.dynamics.ephemeris.coverage_et): the
# de421 package's data begin at JD 2414992.5 (1899-12-04; the published span starts
# 1899-07-29) and the published span ends at JD 2471184.5 (2053-10-09), TDB.  Decks whose
# propagation needs body positions must lie inside it (checked when a deck is validated).
DE421_START_JD = 2_414_992.5  # 1899-12-04T00:00:00 TDB
DE421_END_JD = 2_471_184.5  # 2053-10-09T00:00:00 TDB

# --- the LEO reference case of the trajectory-core issue (EGM96-era values) ---------
MU_EARTH_EGM96_KM3_S2 = 398_600.4418
J2_EARTH = 1.08262668e-3
R_EARTH_KM = 6378.137


@dataclass(frozen=True)
class Body:
    """One gravitating body (all fields in canonical units).

    ``parent``: the body whose sphere of influence contains this one's (Sun for planets,
    Earth for the Moon).  ``sma_km``: mean distance from the parent, used for the
    Laplace sphere-of-influence radius ``sma * (mu / mu_parent)**0.4``.
    ``pole_ra_deg``/``pole_dec_deg``: IAU 2009 pole at J2000 (rates neglected).
    """

    name: str
    mu_km3_s2: float
    radius_km: float
    j2: float
    pole_ra_deg: float
    pole_dec_deg: float
    parent: str | None
    sma_km: float


# DE421 GMs (km^3/s^2; planets are system values except Earth and Moon).
BODIES: dict[str, Body] = {
    b.name: b
    for b in (
        Body("sun", 132_712_440_040.944, 695_700.0, 2.0e-7, 286.13, 63.87, None, 0.0),
        Body("mercury", 22_032.090, 2_439.7, 5.03e-5, 281.0097, 61.4143, "sun", 0.387098 * AU_KM),
        Body("venus", 324_858.592, 6_051.8, 4.458e-6, 272.76, 67.16, "sun", 0.723332 * AU_KM),
        Body("earth", 398_600.436, 6_378.137, 1.08262668e-3, 0.0, 90.0, "sun", 1.000001 * AU_KM),
        Body("moon", 4_902.800, 1_737.4, 2.0323e-4, 269.9949, 66.5392, "earth", 384_400.0),
        Body("mars", 42_828.375, 3_396.19, 1.96045e-3, 317.68143, 52.88650, "sun", 1.523679 * AU_KM),
        Body("jupiter", 126_712_764.8, 71_492.0, 1.4736e-2, 268.056595, 64.495303, "sun", 5.2044 * AU_KM),
        Body("saturn", 37_940_585.2, 60_268.0, 1.6298e-2, 40.589, 83.537, "sun", 9.5826 * AU_KM),
        Body("uranus", 5_794_548.6, 25_559.0, 3.34343e-3, 257.311, -15.175, "sun", 19.2184 * AU_KM),
        Body("neptune", 6_836_535.0, 24_764.0, 3.411e-3, 299.36, 43.46, "sun", 30.110 * AU_KM),
        Body("pluto", 977.0, 1_188.3, 0.0, 132.993, -6.163, "sun", 39.482 * AU_KM),
    )
}


def soi_radius_km(name: str) -> float:
    """Laplace sphere-of-influence radius (km): a (mu/mu_parent)^(2/5); infinite for the Sun."""
    body = BODIES[name]
    if body.parent is None:
        return math.inf
    return body.sma_km * (body.mu_km3_s2 / BODIES[body.parent].mu_km3_s2) ** 0.4


def pole_unit_vector(name: str) -> tuple[float, float, float]:
    """Unit vector of the body's north pole in ICRF/EME2000 (from the IAU RA/Dec)."""
    body = BODIES[name]
    ra, dec = math.radians(body.pole_ra_deg), math.radians(body.pole_dec_deg)
    return (math.cos(ra) * math.cos(dec), math.sin(ra) * math.cos(dec), math.sin(dec))


def body_name_at(bodies: Sequence[str], index: Any) -> str:
    """The name of body ``index`` in a force model's body list ``bodies`` (a trajectory's
    primary index: ``bodies[i]``), or "" for an index outside it (no primary)."""
    i = int(index)
    return bodies[i] if 0 <= i < len(bodies) else ""


def body_names_at(bodies: Sequence[str], indices: Iterable[Any]) -> list[str]:
    """:func:`body_name_at` of each index: a trajectory's primary indices -> body names."""
    return [body_name_at(bodies, i) for i in indices]
