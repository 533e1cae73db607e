"""Perturbing accelerations, each a small pure function (km, s, kg; FRACAS GRAVFO, EP).

Every function returns km/s^2 and is written for one position; batch with ``jax.vmap``.
"""

from __future__ import annotations

import jax.numpy as jnp
from jax import Array

from fracas import (
    _jax,  # noqa: F401
    constants,
)


def dot3(a: Array, b: Array) -> Array:
    """a . b of two 3-vectors as an elementwise product and a sum: under ``vmap`` this fuses
    with its neighbours, where ``jnp.dot`` becomes a batched dot_general that XLA CPU runs as
    a separate, unvectorised kernel (measured 2x on a DPRKN12 LEO batch)."""
    return jnp.sum(a * b, axis=-1)


def potter_f(q: Array) -> Array:
    """Potter's f(q) = (1+q)^(3/2) - 1 = q (3 + 3q + q^2) / (1 + (1+q)^(3/2)), cancellation-free.

    (Doc. 4 sec. 4.1; Battin 1964 sec. 9.3.)  Valid for every q > -1.
    """
    s = 1.0 + q
    return q * (3.0 + q * (3.0 + q)) / (1.0 + s * jnp.sqrt(s))  # s^1.5 without pow (10x faster)


def point_mass_accel(r: Array, mu: Array) -> Array:
    """Two-body acceleration -mu r/|r|^3 (km/s^2) of a body of GM ``mu`` at the origin."""
    inv_r = jnp.sqrt(1.0 / dot3(r, r))  # not 1/sqrt: XLA CPU's float64 rsqrt is scalar (perf-notes)
    return (-mu * inv_r * inv_r * inv_r) * r


def central_j2_accel(r: Array, mu: Array, j2: Array, radius: Array, pole: Array) -> Array:
    """-mu r/|r|^3 plus the J2 acceleration of :func:`j2_accel`, sharing one division and one
    square root (the step of a high-order Cowell integrator is bound by the divider: 2x fewer
    divisions than the two functions apart; equal to their sum to rounding)."""
    inv_rr = 1.0 / dot3(r, r)
    inv_r = jnp.sqrt(inv_rr)
    s = dot3(r, pole) * inv_r
    k = -1.5 * mu * j2 * radius * radius * (inv_rr * inv_rr)
    return r * (inv_r * (k * (1.0 - 5.0 * s * s) - mu * inv_rr)) + (2.0 * k * s) * pole


def third_body_accel(r: Array, rho: Array, mu: Array) -> Array:
    """Direct + indirect acceleration of a third body at ``rho`` (relative to the primary).

    a = mu [(rho - r)/|rho - r|^3 - rho/|rho|^3], written as Battin's
    a = -(mu/d^3) [r + f(q) rho] with q = r.(r - 2 rho)/rho^2 and d = |rho - r|, which does not
    cancel when |r| << |rho| (Battin 1964 eq. 8.61; FRACAS GRAVFO).
    """
    rho2 = dot3(rho, rho)
    q = dot3(r, r - 2.0 * rho) / rho2
    d = rho - r
    inv_d = jnp.sqrt(1.0 / dot3(d, d))
    return (-mu * inv_d * inv_d * inv_d) * (r + potter_f(q) * rho)


def j2_accel(r: Array, mu: Array, j2: Array, radius: Array, pole: Array) -> Array:
    """Oblateness (J2) acceleration of the primary about its pole (Doc. 4 sec. 4.1, eq. for s_pert=1).

    a = -(mu/r^2)(3/2) J2 (R/r)^2 [(1 - 5 sin^2 phi) i_r + 2 sin phi i_pole],
    sin phi = i_r . i_pole (geocentric latitude).
    """
    inv_rr = 1.0 / dot3(r, r)
    ir = r * jnp.sqrt(inv_rr)
    s = dot3(ir, pole)
    k = -1.5 * mu * j2 * radius * radius * (inv_rr * inv_rr)
    return k * ((1.0 - 5.0 * s * s) * ir + 2.0 * s * pole)


def srp_accel(r_from_sun: Array, area_m2: Array, mass_kg: float | Array, cr: Array) -> Array:
    """Solar radiation pressure, cannonball model, no shadow (km/s^2).

    a = Cr (S/c) (A/m) (1 AU/r)^2 r_hat, with S/c = 4.54e-6 N/m^2 at 1 AU; r_from_sun is the
    spacecraft position relative to the Sun (km).  N/kg = m/s^2 -> 1e-3 km/s^2.
    """
    inv_r = jnp.sqrt(1.0 / dot3(r_from_sun, r_from_sun))
    scale = cr * constants.SOLAR_PRESSURE_1AU_N_M2 * area_m2 / mass_kg * 1e-3 * constants.AU_KM**2
    return (scale * inv_r * inv_r * inv_r) * r_from_sun


def encke_deviation_accel(mu: Array, rc: Array, delta: Array, a_free: Array, force: Array, m: Array) -> Array:
    """delta'' = -(mu/r_con^3)(f(q) r + delta) + a_d (Doc. 4 eq. 4.1-3, Potter's f(q))."""
    r = rc + delta
    rc2 = dot3(rc, rc)
    q = dot3(delta, delta - 2.0 * r) / dot3(r, r)
    central = -(mu / (rc2 * jnp.sqrt(rc2))) * (potter_f(q) * r + delta)
    return central + a_free + force / m
