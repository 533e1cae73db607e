"""Kepler's equation and the conversions between Cartesian states and conic elements
(FRACAS CONIC and the fixed-conic branch of EPHEM).

Part of :mod:`fracas.dynamics.elements` (which re-exports every public name here); the element
vector layout and the conventions are in its docstring.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import jax
import jax.numpy as jnp

from fracas import _jax  # noqa: F401  (float64 + compilation cache before any array)
from fracas.dynamics.elements._vectors import TWO_PI, _dot, _norm, _safe_norm, _stack3, _wrap_2pi

if TYPE_CHECKING:
    from jax.typing import ArrayLike

# Below these the node / periapsis direction is treated as undefined (equatorial /
# circular orbit) and the redundant angle is set to zero.  The fallback frame is exact
# only for sin i = 0 (e = 0); otherwise it misplaces the state by about |r| sin i
# (|r| e), so the thresholds sit at round-off level.  Above them the node / periapsis
# directions may be noisy but raan, argp and the anomaly stay mutually consistent, so
# the state round trip is exact to round-off either way.
EQUATORIAL_SIN_I_TOL = 1e-15
CIRCULAR_E_TOL = 1e-15

# Fixed iteration counts for Kepler's equation (Danby's quartic correction from bounded
# starters).  On dense grids (0 <= e <= 1 - 1e-9 with |M| <= pi; 1 + 1e-8 <= e <= 1e4 with
# |M| <= 1e10) two iterations already reach a backward error below 1 ulp (elliptic) and
# 9 ulp (hyperbolic, the sinh round-off); the counts below keep a margin.
_KEPLER_ITERS_ELLIPTIC = 4
_KEPLER_ITERS_HYPERBOLIC = 5

# --- Kepler's equation ---------------------------------------------------------------


def _kepler_elliptic_iterate(M: jax.Array, e: jax.Array) -> jax.Array:
    """E with E - e sin E = M for M in [-pi, pi] (starter + Danby quartic corrections).

    By symmetry solve for |M| in [0, pi], where f(E) = E - e sin E - |M| is convex.  The
    starter is min(|M| + 0.85 e (Danby), (6|M|/e)^(1/3), pi); the last two are upper
    bounds of the root (from sin E <= E - E^3/6 + ... and f(pi) >= 0), and the cube root
    is the good one for small |M| at e near 1, where Danby's starter is poor.
    """
    Ma = jnp.abs(M)
    E0 = jnp.minimum(jnp.minimum(Ma + 0.85 * e, jnp.cbrt(6.0 * Ma / jnp.maximum(e, 1e-300))), jnp.pi)

    def body(_: int, E: jax.Array) -> jax.Array:
        s, c = e * jnp.sin(E), e * jnp.cos(E)
        f = E - s - Ma
        f1, f2, f3 = 1.0 - c, s, c
        d1 = -f / f1
        d2 = -f / (f1 + 0.5 * d1 * f2)
        d3 = -f / (f1 + 0.5 * d2 * f2 + d2 * d2 * f3 / 6.0)
        return jnp.clip(E + d3, 0.0, jnp.pi)

    E = jax.lax.fori_loop(0, _KEPLER_ITERS_ELLIPTIC, body, E0)
    return jnp.where(M < 0.0, -E, E)


def _kepler_hyperbolic_iterate(M: jax.Array, e: jax.Array) -> jax.Array:
    """H with e sinh H - H = M (upper-bound starter + quartic corrections).

    The starter is the smallest of three upper bounds of |H| (each follows from
    sinh H >= H and sinh H >= H + H^3/6 for H >= 0): asinh(|M|/(e-1)), (6|M|/e)^(1/3), and
    Danby's large-|M| estimate ln(2|M|/e + 1.8).  f(H) = e sinh H - H - |M| is convex and
    increasing for H > 0, so corrections from above converge monotonically.
    """
    Ma = jnp.abs(M)
    H0 = jnp.minimum(
        jnp.minimum(jnp.arcsinh(Ma / (e - 1.0)), jnp.cbrt(6.0 * Ma / e)),
        jnp.log(2.0 * Ma / e + 1.8),
    )

    def body(_: int, H: jax.Array) -> jax.Array:
        sh, ch = e * jnp.sinh(H), e * jnp.cosh(H)
        f = sh - H - Ma
        f1, f2, f3 = ch - 1.0, sh, ch
        d1 = -f / f1
        d2 = -f / (f1 + 0.5 * d1 * f2)
        d3 = -f / (f1 + 0.5 * d2 * f2 + d2 * d2 * f3 / 6.0)
        return jnp.maximum(H + d3, 0.0)

    H = jax.lax.fori_loop(0, _KEPLER_ITERS_HYPERBOLIC, body, H0)
    return jnp.sign(M) * H


@jax.jit
def solve_kepler(M: ArrayLike, e: ArrayLike) -> jax.Array:
    """Eccentric anomaly E (e < 1) or hyperbolic anomaly H (e > 1), rad, from M (rad).

    Elliptic: E - e sin E = M, returned in [-pi, pi] (M is first reduced modulo 2 pi).
    Hyperbolic: e sinh H - H = M.  The root is found with a fixed number of Danby quartic
    iterations under ``jax.lax.stop_gradient``; one final Newton step carries the
    gradient, so by the implicit-function theorem forward and reverse AD give the exact
    derivatives dE/dM = 1/(1 - e cos E), dE/de = sin E/(1 - e cos E) (and the hyperbolic
    analogues) at no extra cost.  Part of FRACAS CONIC/EPHEM.
    """
    M = jnp.asarray(M, dtype=jnp.float64)
    e = jnp.asarray(e, dtype=jnp.float64)
    ell = e < 1.0
    # elliptic branch on safe inputs
    e_e = jnp.where(ell, e, 0.5)
    M_e = jnp.where(ell, M, 0.0)
    M_w = M_e - TWO_PI * jnp.round(M_e / TWO_PI)
    sg = jax.lax.stop_gradient
    E_s = _kepler_elliptic_iterate(sg(M_w), sg(e_e))
    E = E_s - (E_s - e_e * jnp.sin(E_s) - M_w) / (1.0 - e_e * jnp.cos(E_s))
    # hyperbolic branch on safe inputs
    e_h = jnp.where(ell, 2.0, e)
    M_h = jnp.where(ell, 0.0, M)
    H_s = _kepler_hyperbolic_iterate(sg(M_h), sg(e_h))
    H = H_s - (e_h * jnp.sinh(H_s) - H_s - M_h) / (e_h * jnp.cosh(H_s) - 1.0)
    return jnp.where(ell, E, H)


@jax.jit
def true_to_mean_anomaly(nu: ArrayLike, e: ArrayLike) -> jax.Array:
    """Mean anomaly (rad) from true anomaly ``nu`` (rad) and eccentricity (FRACAS CONIC).

    Elliptic: E = atan2(sqrt(1 - e^2) sin nu, e + cos nu), M = E - e sin E in [0, 2 pi).
    Hyperbolic (|nu| below the asymptote angle): sinh H = sqrt(e^2 - 1) sin nu /
    (1 + e cos nu), M = e sinh H - H (negative before periapsis).
    """
    nu = jnp.asarray(nu, dtype=jnp.float64)
    e = jnp.asarray(e, dtype=jnp.float64)
    ell = e < 1.0
    e_e = jnp.where(ell, e, 0.5)
    nu_e = jnp.where(ell, nu, 0.0)
    E = jnp.arctan2(jnp.sqrt(1.0 - e_e * e_e) * jnp.sin(nu_e), e_e + jnp.cos(nu_e))
    M_e = _wrap_2pi(E - e_e * jnp.sin(E))
    e_h = jnp.where(ell, 2.0, e)
    nu_h = jnp.where(ell, 0.0, nu)
    sinh_H = jnp.sqrt(e_h * e_h - 1.0) * jnp.sin(nu_h) / (1.0 + e_h * jnp.cos(nu_h))
    M_h = e_h * sinh_H - jnp.arcsinh(sinh_H)
    return jnp.where(ell, M_e, M_h)


@jax.jit
def mean_to_true_anomaly(M: ArrayLike, e: ArrayLike) -> jax.Array:
    """True anomaly (rad, in (-pi, pi]) from mean anomaly (rad) and eccentricity.

    Solves Kepler's equation with :func:`solve_kepler`, then
    elliptic: nu = 2 atan2(sqrt(1 + e) sin(E/2), sqrt(1 - e) cos(E/2));
    hyperbolic: nu = 2 atan2(sqrt(e + 1) tanh(H/2), sqrt(e - 1)) (overflow-free for any H).
    """
    M = jnp.asarray(M, dtype=jnp.float64)
    e = jnp.asarray(e, dtype=jnp.float64)
    ell = e < 1.0
    X = solve_kepler(M, e)
    e_e = jnp.where(ell, e, 0.5)
    E = jnp.where(ell, X, 0.0)
    nu_e = 2.0 * jnp.arctan2(jnp.sqrt(1.0 + e_e) * jnp.sin(0.5 * E), jnp.sqrt(1.0 - e_e) * jnp.cos(0.5 * E))
    e_h = jnp.where(ell, 2.0, e)
    H = jnp.where(ell, 0.0, X)
    nu_h = 2.0 * jnp.arctan2(jnp.sqrt(e_h + 1.0) * jnp.tanh(0.5 * H), jnp.sqrt(e_h - 1.0))
    return jnp.where(ell, nu_e, nu_h)


# --- Cartesian <-> elements ---------------------------------------------------------


def perifocal_basis(i: ArrayLike, raan: ArrayLike, argp: ArrayLike) -> tuple[jax.Array, jax.Array]:
    """Unit vectors P (to periapsis) and Q (90 deg ahead in the orbit plane) in the
    inertial frame: the first two columns of R3(-raan) R1(-i) R3(-argp)."""
    ci, si = jnp.cos(i), jnp.sin(i)
    cO, sO = jnp.cos(raan), jnp.sin(raan)
    cw, sw = jnp.cos(argp), jnp.sin(argp)
    P = _stack3(cO * cw - sO * sw * ci, sO * cw + cO * sw * ci, sw * si)
    Q = _stack3(-cO * sw - sO * cw * ci, -sO * sw + cO * cw * ci, cw * si)
    return P, Q


@jax.jit
def cartesian_to_elements(r: ArrayLike, v: ArrayLike, mu: ArrayLike) -> jax.Array:
    """Conic elements ``[a, e, i, raan, argp, M]`` from position r (km) and velocity
    v (km/s) about a body of gravitational parameter mu (km^3/s^2) (FRACAS CONIC).

    Rebuilt equations (the scan's CONIC is garbled; its e-vector line reads
    ``c = (v x h)/mu - r`` where ``- r/|r|`` is meant, its node and periapsis arctangents
    lost their second arguments, and its anomaly lines mix E with e cos E):

    * h = r x v, w = h/|h|, a = 1/(2/|r| - |v|^2/mu) (a < 0: hyperbola);
    * eccentricity vector e_vec = (v x h)/mu - r/|r|, e = |e_vec|;
    * i = atan2(sqrt(w_x^2 + w_y^2), w_z);
    * node unit vector n = (-w_y, w_x, 0)/sin i, raan = atan2(w_x, -w_y);
      equatorial (sin i < 1e-15): n = x_hat, raan = 0;
    * m = w x n; argp = atan2(e_vec . m, e_vec . n); circular (e < 1e-15): argp = 0,
      so the anomaly is measured from the node (or from x_hat if also equatorial);
    * argument of latitude u = atan2(r . m, r . n); true anomaly nu = u - argp;
    * M from nu by :func:`true_to_mean_anomaly`.

    Angles raan, argp in [0, 2 pi); M in [0, 2 pi) for ellipses.  Gradients are finite
    everywhere in the domain (exactly circular/equatorial states give zero gradients for
    the undefined angles).
    """
    r = jnp.asarray(r, dtype=jnp.float64)
    v = jnp.asarray(v, dtype=jnp.float64)
    rmag = _norm(r)
    h = jnp.cross(r, v)
    w = h / _norm(h)[..., None]
    a = 1.0 / (2.0 / rmag - _dot(v, v) / mu)
    e_vec = jnp.cross(v, h) / mu - r / rmag[..., None]
    e = _safe_norm(e_vec)

    sin_i = _safe_norm(w[..., :2])
    inc = jnp.arctan2(sin_i, w[..., 2])
    equatorial = sin_i < EQUATORIAL_SIN_I_TOL
    sin_i_safe = jnp.where(equatorial, 1.0, sin_i)
    nx = jnp.where(equatorial, 1.0, -w[..., 1] / sin_i_safe)
    ny = jnp.where(equatorial, 0.0, w[..., 0] / sin_i_safe)
    n_hat = _stack3(nx, ny, jnp.zeros_like(nx))
    raan = _wrap_2pi(jnp.arctan2(ny, nx))
    m_hat = jnp.cross(w, n_hat)

    circular = e < CIRCULAR_E_TOL
    ec = jnp.where(circular, 1.0, _dot(e_vec, n_hat))
    es = jnp.where(circular, 0.0, _dot(e_vec, m_hat))
    argp = jnp.where(circular, 0.0, _wrap_2pi(jnp.arctan2(es, ec)))
    u = jnp.arctan2(_dot(r, m_hat), _dot(r, n_hat))
    nu = u - argp
    M = true_to_mean_anomaly(nu, e)
    return jnp.stack([a, e, inc, raan, argp, M], axis=-1)


@jax.jit
def elements_to_cartesian(elements: ArrayLike, mu: ArrayLike) -> tuple[jax.Array, jax.Array]:
    """Position (km) and velocity (km/s) from ``[a, e, i, raan, argp, M]`` (inverse of
    FRACAS CONIC; the conic-state part of FRACAS EPHEM).

    Kepler's equation is solved by :func:`solve_kepler` (exact AD derivatives).  Perifocal
    state (standard; Bate-Mueller-White 4.5 / Vallado 2.3):

    * ellipse: x = a (cos E - e), y = a sqrt(1-e^2) sin E, r = a (1 - e cos E),
      vx = -sqrt(mu a) sin E / r, vy = sqrt(mu a (1-e^2)) cos E / r;
    * hyperbola (|a| used): x = |a| (e - cosh H), y = |a| sqrt(e^2-1) sinh H,
      r = |a| (e cosh H - 1), vx = -sqrt(mu |a|) sinh H / r,
      vy = sqrt(mu |a| (e^2-1)) cosh H / r;

    rotated by P, Q of :func:`perifocal_basis`.  Working with E/H rather than the true
    anomaly avoids the cancellation in 1 + e cos nu far out on a hyperbola.
    """
    el = jnp.asarray(elements, dtype=jnp.float64)
    a, e, inc, raan, argp, M = (el[..., k] for k in range(6))
    ell = e < 1.0
    X = solve_kepler(M, e)
    aa = jnp.abs(a)
    # elliptic branch (safe inputs)
    e_e = jnp.where(ell, e, 0.5)
    E = jnp.where(ell, X, 0.0)
    cE, sE = jnp.cos(E), jnp.sin(E)
    be = jnp.sqrt(1.0 - e_e * e_e)
    x_e = aa * (cE - e_e)
    y_e = aa * be * sE
    r_e = aa * (1.0 - e_e * cE)
    # hyperbolic branch (safe inputs)
    e_h = jnp.where(ell, 2.0, e)
    H = jnp.where(ell, 0.0, X)
    cH, sH = jnp.cosh(H), jnp.sinh(H)
    bh = jnp.sqrt(e_h * e_h - 1.0)
    x_h = aa * (e_h - cH)
    y_h = aa * bh * sH
    r_h = aa * (e_h * cH - 1.0)

    k = jnp.sqrt(mu * aa)
    x = jnp.where(ell, x_e, x_h)
    y = jnp.where(ell, y_e, y_h)
    rr = jnp.where(ell, r_e, r_h)
    vx = jnp.where(ell, -k * sE, -k * sH) / rr
    vy = jnp.where(ell, k * be * cE, k * bh * cH) / rr

    P, Q = perifocal_basis(inc, raan, argp)
    r = x[..., None] * P + y[..., None] * Q
    v = vx[..., None] * P + vy[..., None] * Q
    return r, v


@jax.jit
def conic_body_state(elements: ArrayLike, mu: ArrayLike, dt_s: ArrayLike) -> tuple[jax.Array, jax.Array]:
    """State (km, km/s) of a body on a fixed conic ``dt_s`` seconds after the epoch of
    ``elements`` (FRACAS EPHEM for targets without an ephemeris).

    M(t) = M0 + n dt with n = sqrt(mu/|a|^3) (rad/s); the rest of the elements are fixed.
    Differentiable w.r.t. the elements, mu and dt_s.
    """
    el = jnp.asarray(elements, dtype=jnp.float64)
    a = el[..., 0]
    n = jnp.sqrt(mu / jnp.abs(a) ** 3)
    el = el.at[..., 5].add(n * dt_s)
    return elements_to_cartesian(el, mu)
