"""Onboard measurement models of the Shuttle Unified Navigation Filter (UNF) and their partials.

E. S. Muller, *Shuttle Unified Navigation Filter*, NASA CR-134276 (1973); every equation here
is rebuilt ([R] in the digest ``unf-apollo.md``: the UNF's flow diagrams are lost) from its
nomenclature and narrative, and checked against central differences in
``tests/measurements/test_onboard.py``.  Pure ``jax.numpy`` (float64), jit- and vmap-able,
nothing raises (a geometry without a solution gives nan).  Frame ICRF, units km, km/s, rad.

Kinds (FRACAS names; UNF code c and symbol):

* ``doppler_count_1way`` (UNF c = 0.5): one-way integrated Doppler count over the count
  interval [t0, t_M], t0 = t_M - dt_c, as its range change (km)::

      q = rho(t_M) - rho(t0),     N = f q  counts,  f = m_D f_D / c  (cycles per km)

  (positive when receding).  The partial is the exact STM form
  dq/dx(t_M) = drho(t_M)/dx - drho(t0)/dx(t0) Phi(t0, t_M) (digest A.3.4); this module gives
  the two geometric rows, :mod:`fracas.measurements.trakm` chains them with Phi.
* ``sensor_beta`` / ``sensor_theta`` (UNF c = 2, beta; c = 3, theta; digest A.3.5): with
  r_rho = target - spacecraft and (x, y, z) its components on the sensor axes
  (i_xm, i_ym, i_zm), rho_a = sqrt(x^2 + z^2)::

      beta = atan2(z, x),        theta = atan2(y, rho_a)

  Misalignment: a small rotation phi of the sensor axes (i' = i + phi x i) changes q by
  (g x r_rho) . phi, g = dq/dr_rho; its components along the sensor's own axes are the
  ``sensor_misalignment_{x,y,z}_rad`` partials.
* ``horizon_angle`` (UNF c = 3 in orbit navigation, psi "angle between horizon and x_M";
  digest A.3.6, A.7.2): the theta of the line of sight from the spacecraft to the horizon
  (tangent) point of the oblate limb in the vertical scan plane; the limb is the section of
  the body's ellipsoid by the scan plane (through the centre), its semi-axes raised by the
  horizon altitude gamma_H: a_H = a_F + gamma_H, b_H = R_F(incl) + gamma_H,
  R_F(phi) = a_F b_F / sqrt(b_F^2 cos^2 phi + a_F^2 sin^2 phi), sin(incl) = i_y . i_pole.
  dq/dr = -g(rho_H) (n/rho_H: no sensitivity along the line of sight), dq/dgamma_H =
  (g . N) dn/dgamma_H (N the limb's outward normal at the tangent point; = +1/rho_H for a
  sphere, the UNF's b-vector -1/r_rho up to the sign of the angle).
* ``altitude`` (UNF c = 4; digest A.3.7): h = |r| - R_ref (spherical) or the geodetic height
  above the ellipsoid (a_F, b_F, pole i_pole); dh/dr = i_r, resp. the ellipsoid normal at
  the foot point.

The sensor frames are inputs (rows i_xm, i_ym, i_zm), held fixed in the partials: the
vehicle's attitude is known inertially (IMU), attitude errors are the misalignment
parameters.  :func:`lvlh_axes` and :func:`horizon_sensor_axes` build the frames at the
reference (numpy or JAX arrays alike).
"""

from __future__ import annotations

import jax.numpy as jnp
from jax import Array
from jax.typing import ArrayLike

from fracas import _jax  # noqa: F401  (x64 first)
from fracas.dynamics.relative_motion import hill_axes

__all__ = [
    "lvlh_axes",
    "horizon_sensor_axes",
    "unified_angles",
    "beta_gradient",
    "theta_gradient",
    "misalignment_partials",
    "doppler_count_1way",
    "doppler_count_1way_partials",
    "sensor_beta",
    "sensor_beta_partials",
    "sensor_theta",
    "sensor_theta_partials",
    "horizon_geometry",
    "horizon_angle",
    "horizon_angle_partials",
    "altitude",
    "altitude_partials",
]

#: a scalar input (a radius or an altitude, km; a flag): a float or a traced 0-d array
Scalar = float | Array

_N_GEODETIC_ITER = 8  # fixed-point iterations for the geodetic latitude (converged to eps near Earth)


def _f64(x: ArrayLike) -> Array:
    return jnp.asarray(x, dtype=jnp.float64)


def _unit(x: Array) -> Array:
    return x / jnp.linalg.norm(x)


def _zeros3() -> Array:
    return jnp.zeros(3, dtype=jnp.float64)


# --- frames -------------------------------------------------------------------------
def lvlh_axes(r: ArrayLike, v: ArrayLike) -> Array:
    """Local-vertical/velocity frame of a state (r km, v km/s relative to the body), rows
    (i_t forward, i_h orbit normal, i_r up): i_r = r/|r|, i_h = unit(r x v), i_t = i_h x i_r
    (right-handed: i_t x i_h = i_r).  A [[tracking]] entry's ``sensor_axes`` with
    ``sensor_frame = "lvlh"`` are components on these rows."""
    return hill_axes(_f64(r), _f64(v))[0][jnp.array([1, 2, 0])]  # Hill rows (radial, along, normal) reordered


def horizon_sensor_axes(r: ArrayLike, v: ArrayLike, azimuth_rad: ArrayLike, depression_rad: ArrayLike) -> Array:
    """Horizon-sensor axes (rows i_xm = boresight x_M, i_ym, i_zm = i_2) for a vertical scan
    plane at azimuth phi (UNF phi, counter-clockwise from the forward direction seen from
    above: i_phi = cos phi i_t + sin phi i_h) and a boresight depressed by ``depression_rad``
    below the local horizontal: x_M = cos d i_phi - sin d i_r; i_2 = i_phi x i_r (normal to the
    scan plane), i_ym = i_2 x x_M (up-ish, so the angle is positive above the boresight)."""
    t, h, up = lvlh_axes(r, v)
    i_phi = jnp.cos(azimuth_rad) * t + jnp.sin(azimuth_rad) * h
    x_m = jnp.cos(depression_rad) * i_phi - jnp.sin(depression_rad) * up
    i_2 = jnp.cross(i_phi, up)
    return jnp.stack([x_m, jnp.cross(i_2, x_m), i_2])


# --- the unified angles (UNF c = 2, 3) ------------------------------------------------
def unified_angles(r_rho: ArrayLike, axes: ArrayLike) -> tuple[Array, Array]:
    """(beta, theta) of a relative position r_rho (km) on sensor axes (rows i_xm, i_ym, i_zm):
    beta = atan2(z, x), theta = atan2(y, rho_a), rho_a = sqrt(x^2 + z^2) (rad, (-pi, pi])."""
    x, y, z = _f64(axes) @ _f64(r_rho)
    return jnp.arctan2(z, x), jnp.arctan2(y, jnp.sqrt(x * x + z * z))


def beta_gradient(r_rho: ArrayLike, axes: ArrayLike) -> Array:
    """d beta / d r_rho = (x i_zm - z i_xm) / rho_a^2 (1/km)."""
    axes = _f64(axes)
    x, _, z = axes @ _f64(r_rho)
    return (x * axes[2] - z * axes[0]) / (x * x + z * z)


def theta_gradient(r_rho: ArrayLike, axes: ArrayLike) -> Array:
    """d theta / d r_rho = (rho_a i_ym - y i_rho_a) / rho^2, i_rho_a = (x i_xm + z i_zm)/rho_a (1/km)."""
    axes = _f64(axes)
    x, y, z = axes @ _f64(r_rho)
    rho_a = jnp.sqrt(x * x + z * z)
    i_a = (x * axes[0] + z * axes[2]) / rho_a
    return (rho_a * axes[1] - y * i_a) / (rho_a * rho_a + y * y)


def misalignment_partials(g: ArrayLike, r_rho: ArrayLike, axes: ArrayLike) -> Array:
    """dq/dphi on the sensor's own axes: ((g x r_rho) . i_xm, . i_ym, . i_zm) (rad/rad), for a
    small rotation phi = sum phi_k i_k of the sensor axes (i' = i + phi x i; digest A.3.5)."""
    return _f64(axes) @ jnp.cross(_f64(g), _f64(r_rho))


def sensor_beta(sc_r: ArrayLike, target_r: ArrayLike, axes: ArrayLike) -> Array:
    """UNF c = 2, beta: atan2(z, x) of r_rho = target_r - sc_r on the sensor axes (rad)."""
    return unified_angles(_f64(target_r) - _f64(sc_r), axes)[0]


def sensor_beta_partials(sc_r: ArrayLike, target_r: ArrayLike, axes: ArrayLike) -> tuple[Array, Array, Array]:
    """(d beta/d sc (r, v) (6,), d beta/d target_r (3,), d beta/d phi (3,)): the spacecraft
    row is -g (relative measurement, b = -b_T), the target's +g."""
    r_rho = _f64(target_r) - _f64(sc_r)
    g = beta_gradient(r_rho, axes)
    return jnp.concatenate([-g, _zeros3()]), g, misalignment_partials(g, r_rho, axes)


def sensor_theta(sc_r: ArrayLike, target_r: ArrayLike, axes: ArrayLike) -> Array:
    """UNF c = 3, theta: atan2(y, rho_a) of r_rho = target_r - sc_r on the sensor axes (rad)."""
    return unified_angles(_f64(target_r) - _f64(sc_r), axes)[1]


def sensor_theta_partials(sc_r: ArrayLike, target_r: ArrayLike, axes: ArrayLike) -> tuple[Array, Array, Array]:
    """(d theta/d sc (r, v) (6,), d theta/d target_r (3,), d theta/d phi (3,))."""
    r_rho = _f64(target_r) - _f64(sc_r)
    g = theta_gradient(r_rho, axes)
    return jnp.concatenate([-g, _zeros3()]), g, misalignment_partials(g, r_rho, axes)


# --- one-way integrated Doppler count (UNF c = 0.5) ------------------------------------
def doppler_count_1way(
    sc_r: ArrayLike, earth_r: ArrayLike, st_r: ArrayLike, sc_r0: ArrayLike, earth_r0: ArrayLike, st_r0: ArrayLike
) -> Array:
    """UNF c = 0.5: range change rho(t_M) - rho(t0) over the count interval (km); the count is
    N = f (this) + bias, f = m_D f_D / c cycles per km.  ``*_r``: at t_M, ``*_r0``: at
    t0 = t_M - dt_c (spacecraft and Earth relative to one origin, station geocentric)."""
    p1 = _f64(sc_r) - _f64(earth_r) - _f64(st_r)
    p0 = _f64(sc_r0) - _f64(earth_r0) - _f64(st_r0)
    return jnp.linalg.norm(p1) - jnp.linalg.norm(p0)


def doppler_count_1way_partials(
    sc_r: ArrayLike, earth_r: ArrayLike, st_r: ArrayLike, sc_r0: ArrayLike, earth_r0: ArrayLike, st_r0: ArrayLike
) -> tuple[Array, Array, Array, Array]:
    """(d q/d sc(t_M) (6,), d q/d st_r(t_M) (3,), d q/d sc(t0) (6,), d q/d st_r(t0) (3,)):
    (i_rho(t_M), 0), -i_rho(t_M), (-i_rho(t0), 0), +i_rho(t0) (i_rho station -> spacecraft).
    The Earth's rows are minus the spacecraft's.  The H row at t_M is the exact STM form
    h(t_M) + h(t0) Phi(t0, t_M) (the sign of h(t0) is in it)."""
    p1 = _f64(sc_r) - _f64(earth_r) - _f64(st_r)
    p0 = _f64(sc_r0) - _f64(earth_r0) - _f64(st_r0)
    u1, u0 = _unit(p1), _unit(p0)
    z = _zeros3()
    return jnp.concatenate([u1, z]), -u1, jnp.concatenate([-u0, z]), u0


# --- horizon sensor (UNF c = 3, orbit navigation; digest A.7.2) -------------------------
def horizon_geometry(
    r: ArrayLike, axes: ArrayLike, pole: ArrayLike, a_f: Scalar, b_f: Scalar, gamma_h: Scalar
) -> dict[str, Scalar]:
    """The horizon routine (UNF, digest A.7.2): tangent point of the line of sight in the
    scan plane (normal i_2 = axes[2], through the body centre) on the limb ellipse.

    ``r`` (km): spacecraft relative to the body centre; ``pole``: the body's unit pole (ICRF);
    a_f, b_f: equatorial and polar radii (km); gamma_h: horizon altitude (km).  Returns a dict:
    rho_h (3,) spacecraft -> tangent point (km), a_h, b_h (km), i_x, i_y (3,) the ellipse's
    major and minor axes, x_t, y_t (km) the tangent point and x_v, y_v the spacecraft in the
    ellipse's axes.  Of the two tangent points the one ahead along the boresight is taken.
    """
    r, axes, pole = _f64(r), _f64(axes), _f64(pole)
    i_2 = axes[2]
    c = jnp.cross(pole, i_2)
    nc = jnp.linalg.norm(c)
    # equatorial scan plane (i_2 along the pole): the limb is a circle, any axis will do
    alt = jnp.cross(jnp.where(jnp.abs(i_2[0]) < 0.9, jnp.array([1.0, 0.0, 0.0]), jnp.array([0.0, 1.0, 0.0])), i_2)
    i_x = jnp.where(nc > 1e-12, c / jnp.where(nc > 1e-12, nc, 1.0), alt / jnp.linalg.norm(alt))
    i_y = jnp.cross(i_2, i_x)
    s = jnp.dot(i_y, pole)
    c2 = 1.0 - s * s
    r_f = a_f * b_f / jnp.sqrt(b_f * b_f * c2 + a_f * a_f * s * s)
    a_h, b_h = a_f + gamma_h, r_f + gamma_h
    x_v, y_v = jnp.dot(r, i_x), jnp.dot(r, i_y)
    p, q = x_v / a_h, y_v / b_h
    s2 = p * p + q * q
    k = jnp.sqrt(s2 - 1.0)
    x1, y1 = a_h * (p + q * k) / s2, b_h * (q - p * k) / s2
    x2, y2 = a_h * (p - q * k) / s2, b_h * (q + p * k) / s2
    t1 = x1 * i_x + y1 * i_y
    t2 = x2 * i_x + y2 * i_y
    first = jnp.dot(t1 - r, axes[0]) >= jnp.dot(t2 - r, axes[0])
    x_t, y_t = jnp.where(first, x1, x2), jnp.where(first, y1, y2)
    return {
        "rho_h": jnp.where(first, t1, t2) - r,
        "a_h": a_h,
        "b_h": b_h,
        "i_x": i_x,
        "i_y": i_y,
        "x_t": x_t,
        "y_t": y_t,
        "x_v": x_v,
        "y_v": y_v,
    }


def horizon_angle(
    sc_r: ArrayLike, body_r: ArrayLike, axes: ArrayLike, pole: ArrayLike, a_f: Scalar, b_f: Scalar, gamma_h: Scalar
) -> Array:
    """UNF horizon measurement psi (c = 3): theta of the spacecraft -> horizon line of sight on
    the horizon-sensor axes (rad; positive above the boresight i_xm toward i_ym)."""
    geo = horizon_geometry(_f64(sc_r) - _f64(body_r), axes, pole, a_f, b_f, gamma_h)
    return unified_angles(geo["rho_h"], axes)[1]


def horizon_angle_partials(
    sc_r: ArrayLike, body_r: ArrayLike, axes: ArrayLike, pole: ArrayLike, a_f: Scalar, b_f: Scalar, gamma_h: Scalar
) -> tuple[Array, Array, Array]:
    """(d psi/d sc (r, v) (6,), d psi/d gamma_H (1/km), rho_H (km)).

    d psi/d r = -g, g = d theta/d r_rho at r_rho = rho_H (= n/rho_H in the scan plane, n the
    unit normal to the line of sight; digest A.3.6); the body centre's row is +g.  Horizon
    altitude: the tangent line moves by dn = dgamma (x_t^2/a_H^3 + y_t^2/b_H^3) /
    sqrt(x_t^2/a_H^4 + y_t^2/b_H^4) along the limb's outward normal N, so d psi/d gamma_H =
    (g . N) dn/dgamma (+1/rho_H for a sphere; the UNF's b-vector -1/r_rho up to the sign of
    the angle).  rho_H converts a horizon-threshold (altitude) noise alpha_H into angle:
    alpha^2 = alpha_H^2 / rho_H^2 (UNF s_psi)."""
    geo = horizon_geometry(_f64(sc_r) - _f64(body_r), axes, pole, a_f, b_f, gamma_h)
    rho_h = geo["rho_h"]
    g = theta_gradient(rho_h, axes)
    a, b, xt, yt = geo["a_h"], geo["b_h"], geo["x_t"], geo["y_t"]
    nx, ny = xt / (a * a), yt / (b * b)
    nn = jnp.sqrt(nx * nx + ny * ny)
    normal = (nx * geo["i_x"] + ny * geo["i_y"]) / nn
    dn = (xt * xt / (a * a * a) + yt * yt / (b * b * b)) / nn
    return jnp.concatenate([-g, _zeros3()]), jnp.dot(g, normal) * dn, jnp.linalg.norm(rho_h)


# --- altitude (UNF c = 4) --------------------------------------------------------------
def _geodetic(r: Array, pole: Array, a_f: Scalar, b_f: Scalar) -> tuple[Array, Array]:
    """(height h km, unit ellipsoid normal n (3,)) of r (relative to the body centre)."""
    z = jnp.dot(r, pole)
    w = r - z * pole
    rho = jnp.linalg.norm(w)
    e2 = 1.0 - (b_f * b_f) / (a_f * a_f)
    phi = jnp.arctan2(z, rho * (1.0 - e2))
    for _ in range(_N_GEODETIC_ITER):
        sp = jnp.sin(phi)
        n_rad = a_f / jnp.sqrt(1.0 - e2 * sp * sp)
        phi = jnp.arctan2(z + e2 * n_rad * sp, rho)
    sp, cp = jnp.sin(phi), jnp.cos(phi)
    h = rho * cp + z * sp - a_f * jnp.sqrt(1.0 - e2 * sp * sp)
    return h, cp * (w / rho) + sp * pole


def _body_geodetic(
    sc_r: ArrayLike, body_r: ArrayLike, pole: ArrayLike, a_f: Scalar, b_f: Scalar
) -> tuple[Array, Array, Array]:
    """(r = sc_r - body_r (3,), its geodetic height h km, the unit ellipsoid normal n (3,))."""
    r = _f64(sc_r) - _f64(body_r)
    h, n = _geodetic(r, _f64(pole), a_f, b_f)
    return r, h, n


def altitude(
    sc_r: ArrayLike, body_r: ArrayLike, pole: ArrayLike, a_f: Scalar, b_f: Scalar, r_ref: Scalar, geodetic: Scalar
) -> Array:
    """UNF c = 4: altitude (km).  ``geodetic`` false (0.0): spherical h = |r| - r_ref (UNF
    r_ET); true (1.0): geodetic height above the ellipsoid (a_f, b_f, pole; r_ref unused)."""
    r, h_geo, _ = _body_geodetic(sc_r, body_r, pole, a_f, b_f)
    return jnp.where(geodetic > 0.5, h_geo, jnp.linalg.norm(r) - r_ref)


def altitude_partials(
    sc_r: ArrayLike, body_r: ArrayLike, pole: ArrayLike, a_f: Scalar, b_f: Scalar, r_ref: Scalar, geodetic: Scalar
) -> Array:
    """(d h/d sc (r, v) (6,)): (i_r, 0) spherical, (n, 0) geodetic (the foot point's normal)."""
    r, _, n = _body_geodetic(sc_r, body_r, pole, a_f, b_f)
    g = jnp.where(geodetic > 0.5, n, _unit(r))
    return jnp.concatenate([g, _zeros3()])
