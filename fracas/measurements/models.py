"""Measurement models and their analytic partials (FRACAS TRAKM, section 5.3.22).

Pure ``jax.numpy`` functions of arrays, no I/O.  Frame ICRF (equatorial J2000), units km,
km/s, rad.  Light time, aberration and media delays are ignored: this is covariance-analysis
geometry, where they change the partials by parts in 1e4 at most.

Notation (TRAKM Figure 1): ``sc_r, sc_v`` spacecraft and ``earth_r, earth_v`` Earth centre,
both relative to one origin O (km, km/s); ``st_r, st_v`` station geocentric ICRF state
(:func:`fracas.measurements.stations.station_state`).  The station-relative spacecraft
state is p = sc_r - earth_r - st_r, w = sc_v - earth_v - st_v, rho = |p|, u = p / rho.

Signatures are uniform per family, so callers can treat kinds alike:

* one-station Earth-based kinds (range2, doppler2, azimuth, elevation)::

      f(sc_r, sc_v, earth_r, earth_v, st_r, st_v) -> value
      f_partials(...) -> (h_sc (6,), h_st (6,))              # d/d(r, v)

* two-station kinds (range3, doppler3, diff_range, diff_doppler)::

      f(sc_r, sc_v, earth_r, earth_v, st1_r, st1_v, st2_r, st2_v) -> value
      f_partials(...) -> (h_sc (6,), h_st1 (6,), h_st2 (6,))

* spacecraft-based kinds::

      star_planet_angle(sc_r, body_r, star_unit) -> gamma
      star_planet_angle_partials(...) -> (h_sc (6,), h_body_r (3,))
      planet_diameter(sc_r, body_r, body_radius_km) -> delta
      planet_diameter_partials(...) -> (h_sc (6,), h_body_r (3,), d delta / d R_p)

The partial w.r.t. the Earth's state is always minus the spacecraft one (p depends on
sc - earth only).  Values carry no bias: every measurement bias enters additively with a
unit partial (TRAKM eq. 8 and the closing remark on angle biases), which
:mod:`fracas.measurements.trakm` handles.
"""

from __future__ import annotations

from collections.abc import Callable

import jax.numpy as jnp
from jax import Array
from jax.typing import ArrayLike

from fracas import _jax  # noqa: F401  (x64 first)
from fracas.measurements import kinds

__all__ = [
    "KINDS",
    "N_STATIONS",
    "VALUE_FUNCTIONS",
    "PARTIAL_FUNCTIONS",
    "range2",
    "range2_partials",
    "doppler2",
    "doppler2_partials",
    "range3",
    "range3_partials",
    "doppler3",
    "doppler3_partials",
    "diff_range",
    "diff_range_partials",
    "diff_doppler",
    "diff_doppler_partials",
    "azimuth",
    "azimuth_partials",
    "elevation",
    "elevation_partials",
    "star_planet_angle",
    "star_planet_angle_partials",
    "planet_diameter",
    "planet_diameter_partials",
    "ONBOARD_KINDS",
    "TRAKM_KINDS",
]

# The data types and their participating stations (0: spacecraft-based), from the catalogue.
KINDS = kinds.KINDS
N_STATIONS = kinds.N_STATIONS

#: a position or velocity argument of the station kinds: a 3-vector (km or km/s), any array-like
Vec = ArrayLike


def _f64(x: ArrayLike) -> Array:
    return jnp.asarray(x, dtype=jnp.float64)


def _zeros3() -> Array:
    return jnp.zeros(3, dtype=jnp.float64)


def _rel(sc_r: Vec, sc_v: Vec, earth_r: Vec, earth_v: Vec, st_r: Vec, st_v: Vec) -> tuple[Array, Array]:
    """Station-relative position p and velocity w (sc - earth computed first, so two
    stations share its rounding)."""
    d_r = _f64(sc_r) - _f64(earth_r)
    d_v = _f64(sc_v) - _f64(earth_v)
    return d_r - _f64(st_r), d_v - _f64(st_v)


def _range_rate_terms(p: Array, w: Array) -> tuple[Array, Array, Array]:
    rho = jnp.linalg.norm(p)
    u = p / rho
    rdot = jnp.dot(u, w)
    return rho, u, rdot


# --- 2-way range and Doppler (TRAKM eqs. 1-8) --------------------------------------
def range2(sc_r: Vec, sc_v: Vec, earth_r: Vec, earth_v: Vec, st_r: Vec, st_v: Vec) -> Array:
    """2-way range rho = |sc_r - earth_r - st_r| (km) (FRACAS TRAKM, eq. 1 model)."""
    p, _ = _rel(sc_r, sc_v, earth_r, earth_v, st_r, st_v)
    return jnp.linalg.norm(p)


def range2_partials(sc_r: Vec, sc_v: Vec, earth_r: Vec, earth_v: Vec, st_r: Vec, st_v: Vec) -> tuple[Array, Array]:
    """d rho / d(sc r, v) = (u, 0) (TRAKM eq. 1); d rho / d(st r, v) = (-u, 0) (eq. 2)."""
    p, _ = _rel(sc_r, sc_v, earth_r, earth_v, st_r, st_v)
    u = p / jnp.linalg.norm(p)
    h_sc = jnp.concatenate([u, _zeros3()])
    return h_sc, -h_sc


def doppler2(sc_r: Vec, sc_v: Vec, earth_r: Vec, earth_v: Vec, st_r: Vec, st_v: Vec) -> Array:
    """2-way Doppler as range rate rho_dot = u . (sc_v - earth_v - st_v) (km/s) (TRAKM)."""
    p, w = _rel(sc_r, sc_v, earth_r, earth_v, st_r, st_v)
    return jnp.dot(p, w) / jnp.linalg.norm(p)


def _doppler_grad_r(rho: Array, u: Array, w: Array, rdot: Array) -> Array:
    """d rho_dot / d p = w^T (I - u u^T) / rho (TRAKM eqs. 4 and 7; the scanned eq. 4 lost
    the projector: it is rho_dot_vec^T du/dp with du/dp = (I - u u^T)/rho)."""
    return (w - rdot * u) / rho


def doppler2_partials(sc_r: Vec, sc_v: Vec, earth_r: Vec, earth_v: Vec, st_r: Vec, st_v: Vec) -> tuple[Array, Array]:
    """d rho_dot / d(sc r, v) = ((w - rho_dot u)/rho, u) (TRAKM eqs. 3-5, 7); station: minus
    that (eq. 6)."""
    p, w = _rel(sc_r, sc_v, earth_r, earth_v, st_r, st_v)
    rho, u, rdot = _range_rate_terms(p, w)
    h_sc = jnp.concatenate([_doppler_grad_r(rho, u, w, rdot), u])
    return h_sc, -h_sc


# --- 3-way (QVLBI) range and Doppler (TRAKM eqs. 9-10) -----------------------------
def _summed_partials(partials: Callable[..., tuple[Array, Array]], *state: Vec) -> tuple[Array, Array, Array]:
    """The partials of a 3-way kind, the sum of a 2-way kind over both stations: the two
    stations' spacecraft partials summed, each station's own (``partials``: the 2-way one;
    ``state``: the 3-way arguments sc_r, sc_v, earth_r, earth_v, st1_r, st1_v, st2_r, st2_v)."""
    sc_r, sc_v, earth_r, earth_v, st1_r, st1_v, st2_r, st2_v = state
    h1, s1 = partials(sc_r, sc_v, earth_r, earth_v, st1_r, st1_v)
    h2, s2 = partials(sc_r, sc_v, earth_r, earth_v, st2_r, st2_v)
    return h1 + h2, s1, s2


def range3(sc_r: Vec, sc_v: Vec, earth_r: Vec, earth_v: Vec, st1_r: Vec, st1_v: Vec, st2_r: Vec, st2_v: Vec) -> Array:
    """3-way range rho_3 = rho_1 + rho_2 (km) (TRAKM eq. 9; c dt is a separate bias)."""
    return range2(sc_r, sc_v, earth_r, earth_v, st1_r, st1_v) + range2(sc_r, sc_v, earth_r, earth_v, st2_r, st2_v)


def range3_partials(
    sc_r: Vec, sc_v: Vec, earth_r: Vec, earth_v: Vec, st1_r: Vec, st1_v: Vec, st2_r: Vec, st2_v: Vec
) -> tuple[Array, Array, Array]:
    """Sum of the two stations' 2-way partials (TRAKM text after eq. 10)."""
    return _summed_partials(range2_partials, sc_r, sc_v, earth_r, earth_v, st1_r, st1_v, st2_r, st2_v)


def doppler3(sc_r: Vec, sc_v: Vec, earth_r: Vec, earth_v: Vec, st1_r: Vec, st1_v: Vec, st2_r: Vec, st2_v: Vec) -> Array:
    """3-way Doppler rho_dot_3 = rho_dot_1 + rho_dot_2 (km/s) (TRAKM eq. 10, rebuilt: the
    scan prints ranges on the right-hand side; c df/f is a separate bias)."""
    return doppler2(sc_r, sc_v, earth_r, earth_v, st1_r, st1_v) + doppler2(sc_r, sc_v, earth_r, earth_v, st2_r, st2_v)


def doppler3_partials(
    sc_r: Vec, sc_v: Vec, earth_r: Vec, earth_v: Vec, st1_r: Vec, st1_v: Vec, st2_r: Vec, st2_v: Vec
) -> tuple[Array, Array, Array]:
    """Sum of the two stations' 2-way Doppler partials (TRAKM text after eq. 10)."""
    return _summed_partials(doppler2_partials, sc_r, sc_v, earth_r, earth_v, st1_r, st1_v, st2_r, st2_v)


# --- differenced range and Doppler (TRAKM eqs. 11-16), cancellation-free -----------
def _diff_terms(
    sc_r: Vec, sc_v: Vec, earth_r: Vec, earth_v: Vec, st1_r: Vec, st1_v: Vec, st2_r: Vec, st2_v: Vec
) -> dict[str, Array]:
    """Common terms of the differenced kinds, free of the rho_1 - rho_2 cancellation.

    TRAKM eqs. 14-16, with eq. 15 rebuilt exactly (the scan dropped the normalisation):
        dr   = st2_r - st1_r                         (eq. 14; = p1 - p2 exactly)
        drho = dr^T (p1 + p2) / (rho1 + rho2)        (eq. 15: rho1^2 - rho2^2 = (p1-p2).(p1+p2))
        u1 - u2 = (dr - drho u2) / rho1              (eq. 16)
    """
    p1, w1 = _rel(sc_r, sc_v, earth_r, earth_v, st1_r, st1_v)
    p2, w2 = _rel(sc_r, sc_v, earth_r, earth_v, st2_r, st2_v)
    rho1, u1, rdot1 = _range_rate_terms(p1, w1)
    rho2, u2, rdot2 = _range_rate_terms(p2, w2)
    dr = _f64(st2_r) - _f64(st1_r)
    dv = _f64(st2_v) - _f64(st1_v)  # = w1 - w2 exactly
    drho = jnp.dot(dr, p1 + p2) / (rho1 + rho2)
    du = (dr - drho * u2) / rho1
    # rho_dot_1 - rho_dot_2 = u1.w1 - u2.w2 = (u1 - u2).w1 + u2.(w1 - w2)
    drdot = jnp.dot(du, w1) + jnp.dot(u2, dv)
    return {
        "rho1": rho1,
        "rho2": rho2,
        "u1": u1,
        "u2": u2,
        "w1": w1,
        "w2": w2,
        "rdot1": rdot1,
        "rdot2": rdot2,
        "dv": dv,
        "drho": drho,
        "du": du,
        "drdot": drdot,
    }


def diff_range(
    sc_r: Vec, sc_v: Vec, earth_r: Vec, earth_v: Vec, st1_r: Vec, st1_v: Vec, st2_r: Vec, st2_v: Vec
) -> Array:
    """Differenced range rho_1 - rho_2 (km) (TRAKM eq. 11; c dt is a separate bias),
    evaluated as dr^T (p1 + p2) / (rho1 + rho2) (eqs. 14-15 rebuilt): no digits are lost
    to the cancellation of two ~1e8 km ranges."""
    return _diff_terms(sc_r, sc_v, earth_r, earth_v, st1_r, st1_v, st2_r, st2_v)["drho"]


def diff_range_partials(
    sc_r: Vec, sc_v: Vec, earth_r: Vec, earth_v: Vec, st1_r: Vec, st1_v: Vec, st2_r: Vec, st2_v: Vec
) -> tuple[Array, Array, Array]:
    """d/d sc = (u1 - u2, 0) with u1 - u2 from eq. 16 (TRAKM eq. 13); d/d st1 = (-u1, 0),
    d/d st2 = (u2, 0)."""
    t = _diff_terms(sc_r, sc_v, earth_r, earth_v, st1_r, st1_v, st2_r, st2_v)
    z = _zeros3()
    return (jnp.concatenate([t["du"], z]), jnp.concatenate([-t["u1"], z]), jnp.concatenate([t["u2"], z]))


def diff_doppler(
    sc_r: Vec, sc_v: Vec, earth_r: Vec, earth_v: Vec, st1_r: Vec, st1_v: Vec, st2_r: Vec, st2_v: Vec
) -> Array:
    """Differenced Doppler rho_dot_1 - rho_dot_2 (km/s) (TRAKM eq. 12; c df/f a separate
    bias), as (u1 - u2).w1 + u2.(st2_v - st1_v) with u1 - u2 from eq. 16."""
    return _diff_terms(sc_r, sc_v, earth_r, earth_v, st1_r, st1_v, st2_r, st2_v)["drdot"]


def diff_doppler_partials(
    sc_r: Vec, sc_v: Vec, earth_r: Vec, earth_v: Vec, st1_r: Vec, st1_v: Vec, st2_r: Vec, st2_v: Vec
) -> tuple[Array, Array, Array]:
    """Partials of :func:`diff_doppler`, the spacecraft ones cancellation-free.

    With g_i = (w_i - rho_dot_i u_i)/rho_i (d rho_dot_i / d p_i), the difference g1 - g2 is
    expanded exactly (extension of TRAKM eqs. 14-16 to the Doppler position partial):
        g1 - g2 = dv/rho1 - w2 drho/(rho1 rho2)
                  - [drdot u1 + rdot2 (u1 - u2) - rdot2 u2 drho/rho2] / rho1
    d/d sc = (g1 - g2, u1 - u2); d/d st1 = (-g1, -u1); d/d st2 = (g2, u2).
    """
    t = _diff_terms(sc_r, sc_v, earth_r, earth_v, st1_r, st1_v, st2_r, st2_v)
    rho1, rho2, u1, u2 = t["rho1"], t["rho2"], t["u1"], t["u2"]
    w1, w2, rdot1, rdot2 = t["w1"], t["w2"], t["rdot1"], t["rdot2"]
    drho, du, drdot = t["drho"], t["du"], t["drdot"]
    g1 = (w1 - rdot1 * u1) / rho1
    g2 = (w2 - rdot2 * u2) / rho2
    dg = (t["dv"] - w2 * (drho / rho2) - drdot * u1 - rdot2 * du + (rdot2 * drho / rho2) * u2) / rho1
    return (jnp.concatenate([dg, du]), jnp.concatenate([-g1, -u1]), jnp.concatenate([g2, u2]))


# --- azimuth and elevation (TRAKM eqs. 17-31, rebuilt topocentric) ------------------
def _topocentric(
    sc_r: ArrayLike, earth_r: ArrayLike, st_r: ArrayLike
) -> tuple[Array, Array, Array, Array, Array, Array, Array, Array]:
    """Spherical-Earth local frame at the station: up = st_r/|st_r|, east = unit(z x up),
    north = up x east; returns p, rho, |st_r|, up, east, north, cos/sin geocentric lat."""
    p = _f64(sc_r) - _f64(earth_r) - _f64(st_r)
    s = _f64(st_r)
    smag = jnp.linalg.norm(s)
    up = s / smag
    cphi = jnp.sqrt(up[0] * up[0] + up[1] * up[1])
    east = jnp.stack([-up[1], up[0], jnp.zeros_like(cphi)]) / cphi
    north = jnp.cross(up, east)
    return p, jnp.linalg.norm(p), smag, up, east, north, cphi, up[2]


def elevation(sc_r: Vec, sc_v: Vec, earth_r: Vec, earth_v: Vec, st_r: Vec, st_v: Vec) -> Array:
    """Elevation beta (rad) above the station's horizon plane (normal to the geocentric
    station radius, spherical Earth): sin beta = u . up (TRAKM eq. 17/18), evaluated as
    atan2(p.up, |p - (p.up) up|) for full accuracy near the zenith."""
    p, _, _, up, _, _, _, _ = _topocentric(sc_r, earth_r, st_r)
    e = jnp.dot(p, up)
    return jnp.arctan2(e, jnp.linalg.norm(p - e * up))


def elevation_partials(sc_r: Vec, sc_v: Vec, earth_r: Vec, earth_v: Vec, st_r: Vec, st_v: Vec) -> tuple[Array, Array]:
    """Analytic partials of :func:`elevation` (TRAKM eqs. 19-20, rebuilt):

        d beta / d sc_r = (up - sin b u) / (rho cos b)
        d beta / d st_r = -d beta / d sc_r + (u - sin b up) / (|st_r| cos b)
    (the second term is the tilt of the horizon with the station, du_s/dx_s of eq. 20);
    no velocity dependence.
    """
    p, rho, smag, up, _, _, _, _ = _topocentric(sc_r, earth_r, st_r)
    u = p / rho
    sb = jnp.dot(u, up)
    cb = jnp.linalg.norm(u - sb * up)
    g = (up - sb * u) / (rho * cb)
    z = _zeros3()
    h_sc = jnp.concatenate([g, z])
    h_st = jnp.concatenate([-g + (u - sb * up) / (smag * cb), z])
    return h_sc, h_st


def azimuth(sc_r: Vec, sc_v: Vec, earth_r: Vec, earth_v: Vec, st_r: Vec, st_v: Vec) -> Array:
    """Azimuth alpha (rad, in [0, 2 pi)), from local north toward east:
    alpha = atan2(p.east, p.north) (standard topocentric definition; replaces the
    geocentric-ecliptic construction of TRAKM eqs. 21-23)."""
    p, _, _, _, east, north, _, _ = _topocentric(sc_r, earth_r, st_r)
    return jnp.mod(jnp.arctan2(jnp.dot(p, east), jnp.dot(p, north)), 2.0 * jnp.pi)


def azimuth_partials(sc_r: Vec, sc_v: Vec, earth_r: Vec, earth_v: Vec, st_r: Vec, st_v: Vec) -> tuple[Array, Array]:
    """Analytic partials of :func:`azimuth` (replacing TRAKM eqs. 24-30).

    With n = p.north, E = p.east, e = p.up, h^2 = n^2 + E^2 and geocentric latitude phi:
        d alpha / d sc_r = (n east - E north) / h^2
        d alpha / d st_r = -d alpha / d sc_r
                           + [(tan phi - e n / h^2) east + (E e / h^2) north] / |st_r|
    The second line is the rotation of the local frame as the station moves: from
    d up = north d phi + cos phi east d lam, d east = (sin phi north - cos phi up) d lam,
    d north = -up d phi - sin phi east d lam.  No velocity dependence.
    """
    p, _, smag, up, east, north, cphi, sphi = _topocentric(sc_r, earth_r, st_r)
    n = jnp.dot(p, north)
    E = jnp.dot(p, east)
    e = jnp.dot(p, up)
    h2 = n * n + E * E
    g = (n * east - E * north) / h2
    frame = ((sphi / cphi - e * n / h2) * east + (E * e / h2) * north) / smag
    z = _zeros3()
    return jnp.concatenate([g, z]), jnp.concatenate([-g + frame, z])


# --- spacecraft-based optical data (TRAKM eqs. 32-39) ------------------------------
def star_planet_angle(sc_r: ArrayLike, body_r: ArrayLike, star_unit: ArrayLike) -> Array:
    """Star-planet angle gamma (rad): cos gamma = d . u_p, u_p = unit(body_r - sc_r), d the
    star unit vector (TRAKM eq. 32); evaluated as atan2(|d x u_p|, d . u_p)."""
    q = _f64(body_r) - _f64(sc_r)
    u = q / jnp.linalg.norm(q)
    d = _f64(star_unit)
    return jnp.arctan2(jnp.linalg.norm(jnp.cross(d, u)), jnp.dot(d, u))


def star_planet_angle_partials(sc_r: ArrayLike, body_r: ArrayLike, star_unit: ArrayLike) -> tuple[Array, Array]:
    """d gamma / d sc_r = (d - cos g u_p) / (rho sin g) (TRAKM eq. 33), d/d sc_v = 0 (eq. 34),
    d gamma / d body_r = minus that (eq. 35, before chaining with d body_r / d params)."""
    q = _f64(body_r) - _f64(sc_r)
    rho = jnp.linalg.norm(q)
    u = q / rho
    d = _f64(star_unit)
    c = jnp.dot(d, u)
    t = d - c * u
    s = jnp.linalg.norm(jnp.cross(d, u))
    g = t / (rho * s)
    return jnp.concatenate([g, _zeros3()]), -g


def planet_diameter(sc_r: ArrayLike, body_r: ArrayLike, body_radius_km: ArrayLike) -> Array:
    """Apparent planet diameter delta (rad): sin(delta/2) = R_p / rho, rho = |body_r - sc_r|
    (TRAKM eq. 36)."""
    rho = jnp.linalg.norm(_f64(body_r) - _f64(sc_r))
    return 2.0 * jnp.arcsin(_f64(body_radius_km) / rho)


def planet_diameter_partials(
    sc_r: ArrayLike, body_r: ArrayLike, body_radius_km: ArrayLike
) -> tuple[Array, Array, Array]:
    """Partials of :func:`planet_diameter` (TRAKM eqs. 37-39; eq. 37 rebuilt, the scan is
    garbled):

        d delta / d sc_r   = 2 R_p u_p^T / (rho sqrt(rho^2 - R_p^2))     (eq. 37)
        d delta / d sc_v   = 0                                           (eq. 38)
        d delta / d body_r = -d delta / d sc_r                           (eq. 39)
        d delta / d R_p    = 2 / sqrt(rho^2 - R_p^2)
    """
    q = _f64(body_r) - _f64(sc_r)
    rho = jnp.linalg.norm(q)
    u = q / rho
    Rp = _f64(body_radius_km)
    root = jnp.sqrt((rho - Rp) * (rho + Rp))
    g = (2.0 * Rp / (rho * root)) * u
    return jnp.concatenate([g, _zeros3()]), -g, 2.0 / root


VALUE_FUNCTIONS = {
    "range2": range2,
    "doppler2": doppler2,
    "range3": range3,
    "doppler3": doppler3,
    "diff_range": diff_range,
    "diff_doppler": diff_doppler,
    "azimuth": azimuth,
    "elevation": elevation,
    "star_planet_angle": star_planet_angle,
    "planet_diameter": planet_diameter,
}

PARTIAL_FUNCTIONS = {
    "range2": range2_partials,
    "doppler2": doppler2_partials,
    "range3": range3_partials,
    "doppler3": doppler3_partials,
    "diff_range": diff_range_partials,
    "diff_doppler": diff_doppler_partials,
    "azimuth": azimuth_partials,
    "elevation": elevation_partials,
    "star_planet_angle": star_planet_angle_partials,
    "planet_diameter": planet_diameter_partials,
}

# The Shuttle UNF onboard kinds (their own signatures and TRAKM kernel; fracas.measurements.onboard).
from fracas.measurements import onboard as _onboard  # noqa: E402

ONBOARD_KINDS = kinds.ONBOARD_KINDS
#: the kinds with the uniform signatures of this module's docstring
TRAKM_KINDS = tuple(k for k in KINDS if k not in ONBOARD_KINDS)
VALUE_FUNCTIONS.update(
    {
        "doppler_count_1way": _onboard.doppler_count_1way,
        "sensor_beta": _onboard.sensor_beta,
        "sensor_theta": _onboard.sensor_theta,
        "horizon_angle": _onboard.horizon_angle,
        "altitude": _onboard.altitude,
    }
)
PARTIAL_FUNCTIONS.update(
    {
        "doppler_count_1way": _onboard.doppler_count_1way_partials,
        "sensor_beta": _onboard.sensor_beta_partials,
        "sensor_theta": _onboard.sensor_theta_partials,
        "horizon_angle": _onboard.horizon_angle_partials,
        "altitude": _onboard.altitude_partials,
    }
)
