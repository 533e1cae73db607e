"""Spherical coordinates (FRACAS CONVRT) and frame rotations (FRACAS EULMX, PECEQ).

Part of :mod:`fracas.dynamics.elements` (which re-exports every public name here).
"""

from __future__ import annotations

import functools
from typing import TYPE_CHECKING

import jax
import jax.numpy as jnp

from fracas import (
    _jax,  # noqa: F401  (float64 + compilation cache before any array)
    constants,
)
from fracas.dynamics.elements._vectors import _dot, _norm, _safe_norm, _stack3, _wrap_2pi

if TYPE_CHECKING:
    from jax.typing import ArrayLike

# --- spherical coordinates (CONVRT) ------------------------------------------------------


def _local_basis(lat: ArrayLike, lon: ArrayLike) -> tuple[jax.Array, jax.Array, jax.Array]:
    """Up, east, north unit vectors at latitude ``lat`` and longitude ``lon``."""
    cp, sp = jnp.cos(lat), jnp.sin(lat)
    ct, st = jnp.cos(lon), jnp.sin(lon)
    up = _stack3(cp * ct, cp * st, sp)
    east = _stack3(-st, ct, jnp.zeros_like(ct))
    north = _stack3(-sp * ct, -sp * st, cp)
    return up, east, north


@jax.jit
def spherical_to_cartesian(
    r: ArrayLike, lat: ArrayLike, lon: ArrayLike, v: ArrayLike, gamma: ArrayLike, sigma: ArrayLike
) -> tuple[jax.Array, jax.Array]:
    """Cartesian position (km) and velocity (km/s) from spherical coordinates (FRACAS
    CONVRT).

    Inputs: radius r (km), latitude/declination ``lat`` (rad), longitude/right ascension
    ``lon`` (rad), speed v (km/s), flight-path angle ``gamma`` (rad, above the local
    horizontal), azimuth ``sigma`` (rad, from local north toward east).

    Rebuilt from the scan (which duplicates and garbles the B_z line and adds a spurious
    ``R_z = v sin phi`` line); with phi = lat, theta = lon:

    * R = r (cos phi cos theta, cos phi sin theta, sin phi);
    * local components B_x = v sin gamma (up), B_y = v cos gamma sin sigma (east),
      B_z = v cos gamma cos sigma (north);
    * V_x = B_x cos phi cos theta - B_y sin theta - B_z sin phi cos theta,
      V_y = B_x cos phi sin theta + B_y cos theta - B_z sin phi sin theta,
      V_z = B_x sin phi + B_z cos phi,

    i.e. V = B_x up + B_y east + B_z north.
    """
    up, east, north = _local_basis(lat, lon)
    bx = v * jnp.sin(gamma)
    by = v * jnp.cos(gamma) * jnp.sin(sigma)
    bz = v * jnp.cos(gamma) * jnp.cos(sigma)
    R = jnp.asarray(r)[..., None] * up
    V = bx[..., None] * up + by[..., None] * east + bz[..., None] * north
    return R, V


@jax.jit
def cartesian_to_spherical(r: ArrayLike, v: ArrayLike) -> tuple[jax.Array, ...]:
    """Inverse of :func:`spherical_to_cartesian` (FRACAS CONVRT inverse).

    Returns ``(r, lat, lon, v, gamma, sigma)``: r = |R|; lat = atan2(z, sqrt(x^2+y^2)) in
    [-pi/2, pi/2]; lon = atan2(y, x) in [0, 2 pi) (0 on the polar axis); v = |V|;
    gamma = atan2(V . up, |V_horizontal|) in [-pi/2, pi/2]; sigma = atan2(V . east,
    V . north) in [0, 2 pi) (0 for purely radial velocity).
    """
    r = jnp.asarray(r, dtype=jnp.float64)
    v = jnp.asarray(v, dtype=jnp.float64)
    rmag = _norm(r)
    rho = _safe_norm(r[..., :2])
    lat = jnp.arctan2(r[..., 2], rho)
    polar = rho == 0.0
    lon = jnp.where(
        polar,
        0.0,
        _wrap_2pi(jnp.arctan2(jnp.where(polar, 0.0, r[..., 1]), jnp.where(polar, 1.0, r[..., 0]))),
    )
    up, east, north = _local_basis(lat, lon)
    vu, ve, vn = _dot(v, up), _dot(v, east), _dot(v, north)
    vh = _safe_norm(jnp.stack([ve, vn], axis=-1))
    vmag = _safe_norm(v)
    gamma = jnp.arctan2(vu, vh)
    radial = vh == 0.0
    sigma = jnp.where(radial, 0.0, _wrap_2pi(jnp.arctan2(jnp.where(radial, 0.0, ve), jnp.where(radial, 1.0, vn))))
    return rmag, lat, lon, vmag, gamma, sigma


# --- rotation matrices (EULMX, PECEQ) ----------------------------------------------------


def elementary_rotation(psi: ArrayLike, axis: int) -> jax.Array:
    """Frame rotation f(psi, a) of FRACAS EULMX about axis ``a`` in {1, 2, 3} (static).

    a=1: [[1,0,0],[0,c,s],[0,-s,c]]; a=2: [[c,0,-s],[0,1,0],[s,0,c]];
    a=3: [[c,s,0],[-s,c,0],[0,0,1]] (components of a fixed vector in a frame rotated by
    +psi about the axis).
    """
    c, s = jnp.cos(psi), jnp.sin(psi)
    o, z = jnp.ones_like(c), jnp.zeros_like(c)
    if axis == 1:
        rows = ((o, z, z), (z, c, s), (z, -s, c))
    elif axis == 2:
        rows = ((c, z, -s), (z, o, z), (s, z, c))
    elif axis == 3:
        rows = ((c, s, z), (-s, c, z), (z, z, o))
    else:
        raise ValueError(f"rotation axis must be 1, 2 or 3, got {axis!r}")
    return jnp.stack([jnp.stack(row, axis=-1) for row in rows], axis=-2)


@functools.partial(jax.jit, static_argnames=("axes",))
def euler_matrix(angles: ArrayLike, axes: tuple[int, int, int] = (3, 1, 3)) -> jax.Array:
    """Rotation matrix P = H G F from Euler angles (FRACAS EULMX).

    ``angles`` = (alpha, beta, gamma) in rad; ``axes`` = (a1, a2, a3), a static tuple of
    ints in {1, 2, 3}.  F = f(alpha, a1), G = f(beta, a2), H = f(gamma, a3), with f the
    frame rotation of :func:`elementary_rotation` (so P maps components in the original
    frame to components in the frame reached by rotating alpha about a1, then beta about
    the new a2, then gamma about the newest a3).
    """
    axes = tuple(int(k) for k in axes)
    if len(axes) != 3:
        raise ValueError(f"axes must be 3 ints in {{1, 2, 3}}, got {axes!r}")
    ang = jnp.asarray(angles, dtype=jnp.float64)
    F = elementary_rotation(ang[..., 0], axes[0])
    G = elementary_rotation(ang[..., 1], axes[1])
    H = elementary_rotation(ang[..., 2], axes[2])
    return H @ G @ F


@jax.jit
def ecliptic_to_equatorial_matrix() -> jax.Array:
    """Constant matrix taking ecliptic-J2000 components to EME2000/ICRF components.

    r_eq = R1(-eps) r_ecl = [[1, 0, 0], [0, cos eps, -sin eps], [0, sin eps, cos eps]] r_ecl
    with eps = ``constants.OBLIQUITY_J2000_RAD`` (IAU 2006).  Its transpose maps EME2000
    to ecliptic.  (The ecliptic part of FRACAS PECEQ, whose pole line is this rotation's
    transpose applied to the RA/Dec pole vector.)
    """
    return elementary_rotation(-jnp.asarray(constants.OBLIQUITY_J2000_RAD, dtype=jnp.float64), 1)


@jax.jit
def planet_equatorial_matrix(pole_unit_vector: ArrayLike) -> jax.Array:
    """Matrix A taking ICRF components to planet-equatorial components (FRACAS PECEQ,
    generalised).

    The rows of A are X, Y, Z of the planet-equator frame in ICRF:
    Z = pole (normalised), X = (z_ICRF x Z)/|z_ICRF x Z| -- the ascending node of the planet
    equator on the ICRF equator, i.e. the IAU direction at right ascension alpha0 + 90 deg --
    and Y = Z x X.  If the pole is within 1e-12 rad of +-z_ICRF the node is undefined and
    X = x_ICRF is used (so Earth's pole gives the identity).

    The report's PECEQ instead takes X toward the node of the planet equator on the planet's
    orbit plane (its N vector, whose garbled third component should read cos i) and works
    in ecliptic coordinates; that frame differs from this one by a rotation about Z.
    """
    p = jnp.asarray(pole_unit_vector, dtype=jnp.float64)
    Z = p / _norm(p)[..., None]
    node = _stack3(-Z[..., 1], Z[..., 0], jnp.zeros_like(Z[..., 0]))  # z_hat x Z
    nn = _safe_norm(node)
    degenerate = nn < 1e-12
    nn_safe = jnp.where(degenerate, 1.0, nn)
    x_hat = jnp.broadcast_to(jnp.array([1.0, 0.0, 0.0]), node.shape)
    X = jnp.where(degenerate[..., None], x_hat, node / nn_safe[..., None])
    # make X exactly orthogonal to Z in the degenerate branch too
    X = X - _dot(X, Z)[..., None] * Z
    X = X / _norm(X)[..., None]
    Y = jnp.cross(Z, X)
    return jnp.stack([X, Y, Z], axis=-2)
