"""Universal-variable conic propagation with f and g (Battin 1964, ch. 4; FRACAS CONIC/ENCON).

The independent variable is the universal anomaly ``x`` (km^0.5), the dependent variable
the time ``tau`` since the conic epoch (Doc. 4 sec. 4.1 names them x and tau; its Kepler
routine, GN&C Eq. Doc. No. 3, was not available and is rebuilt here, see
``shared/seeds/digests/encke-wmatrix.md`` sec. 6):

    sqrt(mu) tau(x) = sigma0 x^2 C(xi) + (1 - alpha r0) x^3 S(xi) + r0 x,    xi = alpha x^2
    r(x)            = x^2 C + sigma0 x (1 - xi S) + r0 (1 - xi C)         (= sqrt(mu) dtau/dx)

with alpha = 2/r0 - v0^2/mu (1/a, negative for hyperbolas) and sigma0 = r0.v0/sqrt(mu).
The Lagrange coefficients f, g, fdot, gdot give r = f r0 + g v0, v = fdot r0 + gdot v0.

The root is found by the Laguerre-Conway iteration (Conway 1986; robust for ellipses,
parabolas and hyperbolas, forward and backward, from a poor start) under
``stop_gradient``; one final Newton step is taken with gradients so that forward- and
reverse-mode AD give the exact implicit derivative dx/d(r0, v0, tau, mu).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax import Array

from fracas import _jax  # noqa: F401  (float64, compilation cache)
from fracas.dynamics.forces import dot3

_SERIES_XI = 0.1  # |xi| below which C, S come from their Taylor series (no cancellation)
_MAX_ITER = 60


def _stumpff_series(xi: Array, n_terms: int = 9) -> tuple[Array, Array]:
    """Taylor series C = sum (-xi)^k/(2k+2)!, S = sum (-xi)^k/(2k+3)! (remainder < 1e-20 for |xi| < 0.1)."""
    c = jnp.zeros_like(xi)
    s = jnp.zeros_like(xi)
    tc = 0.5 * jnp.ones_like(xi)
    ts = jnp.ones_like(xi) / 6.0
    for k in range(n_terms):
        c = c + tc
        s = s + ts
        tc = -tc * xi / ((2 * k + 3) * (2 * k + 4))
        ts = -ts * xi / ((2 * k + 4) * (2 * k + 5))
    return c, s


def stumpff(xi: Array) -> tuple[Array, Array]:
    """Stumpff functions C(xi) = (1 - cos sqrt xi)/xi and S(xi) = (sqrt xi - sin sqrt xi)/xi^1.5.

    Written without cancellation: 1 - cos y = 2 sin^2(y/2) (and cosh y - 1 = 2 sinh^2(y/2)),
    and a 9-term Taylor series for |xi| < 0.1 (remainder < 1e-20).  Branches are guarded
    (double ``where``) so that derivatives are finite everywhere.
    """
    small = jnp.abs(xi) < _SERIES_XI
    c_ser, s_ser = _stumpff_series(jnp.where(small, xi, 0.0))
    pos = xi > 0
    xe = jnp.where(small, 1.0, jnp.where(pos, xi, 1.0))
    xh = jnp.where(small, -1.0, jnp.where(pos, -1.0, xi))
    ye = jnp.sqrt(xe)
    yh = jnp.sqrt(-xh)
    c_ell = 2.0 * jnp.sin(0.5 * ye) ** 2 / xe
    s_ell = (ye - jnp.sin(ye)) / (xe * ye)
    c_hyp = 2.0 * jnp.sinh(0.5 * yh) ** 2 / (-xh)
    s_hyp = (jnp.sinh(yh) - yh) / ((-xh) * yh)
    c = jnp.where(small, c_ser, jnp.where(pos, c_ell, c_hyp))
    s = jnp.where(small, s_ser, jnp.where(pos, s_ell, s_hyp))
    return c, s


_REDUCTIONS = 5  # stumpff_reduced: series at xi/4^5, exact to |xi| <= 1024 (y <= 32 rad)


def stumpff_reduced(xi: Array) -> tuple[Array, Array]:
    """C(xi), S(xi) with no transcendental function: the 9-term Taylor series at xi/4^5 and five
    angle doublings (y -> 2y, xi -> 4 xi), for either sign of xi:

        c0' = 2 c0^2 - 1,  c1' = c0 c1,  c2' = c1^2 / 2,  c3' = (c2 + c0 c3) / 4

    with c0 = cos y, c1 = sin(y)/y, c2 = C, c3 = S (y = sqrt xi; cosh/sinh for xi < 0).  Exact
    to a few ulp for |xi| <= 1024, which covers every Encke half-step (|xi| ~ (n dt/2)^2).
    Polynomial only, so it vectorises where sin/sinh do not (about 8x faster on CPU).
    """
    z = xi * (0.25**_REDUCTIONS)
    c2, c3 = _stumpff_series(z)
    c0 = 1.0 - z * c2
    c1 = 1.0 - z * c3
    for _ in range(_REDUCTIONS):
        c0, c1, c2, c3 = 2.0 * c0 * c0 - 1.0, c0 * c1, 0.5 * c1 * c1, 0.25 * (c2 + c0 * c3)
    return c2, c3


def _time_of_x(
    x: Array,
    r0: Array,
    sigma0: Array,
    alpha: Array,
    sqrt_mu: Array,
    stumpff_fn: Callable[[Array], tuple[Array, Array]] = stumpff,
) -> tuple[Array, Array, Array, Array, Array]:
    """sqrt(mu)*tau(x), r(x) and dr/dx for the universal Kepler equation."""
    xi = alpha * x * x
    c, s = stumpff_fn(xi)
    x2 = x * x
    f = sigma0 * x2 * c + (1.0 - alpha * r0) * x2 * x * s + r0 * x
    r = x2 * c + sigma0 * x * (1.0 - xi * s) + r0 * (1.0 - xi * c)
    drdx = sigma0 * (1.0 - xi * c) + (1.0 - alpha * r0) * x * (1.0 - xi * s)
    return f, r, drdx, c, s


def initial_guess(r0: Array, sigma0: Array, alpha: Array, sqrt_mu: Array, tau: float | Array) -> Array:
    """Starting x: sqrt(mu) tau alpha for ellipses, Vallado's log form for hyperbolas."""
    x_ell = sqrt_mu * tau * alpha
    a = 1.0 / jnp.where(alpha < 0, alpha, -1.0)  # negative semi-major axis (guarded)
    sgn = jnp.where(tau >= 0, 1.0, -1.0)
    arg = (-2.0 * sqrt_mu**2 * alpha * tau) / (sigma0 * sqrt_mu + sgn * jnp.sqrt(sqrt_mu**2 * -a) * (1.0 - r0 * alpha))
    arg = jnp.where(arg > 1e-300, arg, 1.0)
    x_hyp = sgn * jnp.sqrt(-a) * jnp.log(arg)
    x_par = sqrt_mu * tau / r0
    # the log form is for long times; within ~|a| of the start the linear guess is better
    x_hyp = jnp.where(jnp.abs(x_par) < jnp.sqrt(-a), x_par, x_hyp)
    x0 = jnp.where(alpha > 1e-12, x_ell, jnp.where(alpha < -1e-12, x_hyp, x_par))
    return jnp.where(jnp.isfinite(x0), x0, x_par)


def solve_universal_x(
    r0: Array,
    sigma0: Array,
    alpha: Array,
    sqrt_mu: Array,
    tau: float | Array,
    x_start: Array,
    rtol: float = 1e-15,
) -> tuple[Array, Array]:
    """Root x of sqrt(mu) tau(x) = sqrt(mu) tau by Laguerre-Conway (n = 5), gradient-free.

    Returns (x, n_iter).  Converged when |dx| <= rtol * max(|x|, 1) or after 60 iterations.
    """
    target = sqrt_mu * tau
    n = 5.0

    def cond(c: tuple[Array, Array, Array]) -> Array:
        x, dx, k = c
        return (jnp.abs(dx) > rtol * jnp.maximum(jnp.abs(x), 1.0)) & (k < _MAX_ITER)

    def body(c: tuple[Array, Array, Array]) -> tuple[Array, Array, Array]:
        x, _, k = c
        f, r, drdx, _, _ = _time_of_x(x, r0, sigma0, alpha, sqrt_mu)
        fx = f - target
        disc = jnp.abs((n - 1.0) ** 2 * r * r - n * (n - 1.0) * fx * drdx)
        denom = r + jnp.sign(r) * jnp.sqrt(disc)
        dx = -n * fx / jnp.where(denom == 0.0, 1.0, denom)
        return x + dx, dx, k + 1

    x, _, k = jax.lax.while_loop(cond, body, (x_start, jnp.ones_like(x_start), jnp.zeros((), jnp.int32)))
    return x, k


class ConicState(NamedTuple):
    """Result of a conic propagation: r km, v km/s, the universal anomaly x and f, g coefficients."""

    r: jax.Array
    v: jax.Array
    x: jax.Array
    f: jax.Array
    g: jax.Array
    fdot: jax.Array
    gdot: jax.Array


def kepler_fg(
    r0_vec: Array,
    v0_vec: Array,
    tau: float | Array,
    mu: float | Array,
    x_start: Array | None = None,
    n_newton: int | None = None,
    short_arc: bool = False,
) -> ConicState:
    """Propagate (r0, v0) on its conic by ``tau`` seconds (any sign; any conic) (FRACAS CONIC).

    ``x_start`` warm-starts the iteration (for example a Taylor prediction from the previous
    solve, as the Encke integrator does).  ``n_newton`` (static): take exactly that many
    Newton steps from ``x_start`` instead of iterating Laguerre-Conway to convergence; only
    for starts already close to the root (the integrator's predictor is O(dt^3) accurate,
    so three Newton steps reach roundoff).  Differentiable in every argument
    (implicit-function derivative of x).  ``short_arc`` (static) uses :func:`stumpff_reduced`
    (valid while |alpha x^2| <= 1024, i.e. arcs of up to ~5 revolutions; the integrator's
    half steps are ~0.15 rad).
    """
    sf = stumpff_reduced if short_arc else stumpff
    r0 = jnp.linalg.norm(r0_vec)
    sqrt_mu = jnp.sqrt(mu)
    sigma0 = dot3(r0_vec, v0_vec) / sqrt_mu
    alpha = 2.0 / r0 - dot3(v0_vec, v0_vec) / mu
    if x_start is None:
        x_start = initial_guess(r0, sigma0, alpha, sqrt_mu, tau)
    sg = jax.lax.stop_gradient
    if n_newton is None:
        x_star, _ = solve_universal_x(sg(r0), sg(sigma0), sg(alpha), sg(sqrt_mu), sg(tau), sg(x_start))
    else:
        x_star = sg(x_start)
        a_r0, a_s0, a_al, a_sm, a_tau = sg(r0), sg(sigma0), sg(alpha), sg(sqrt_mu), sg(tau)
        for _ in range(n_newton):
            f, r, _, _, _ = _time_of_x(x_star, a_r0, a_s0, a_al, a_sm, sf)
            x_star = x_star + (a_sm * a_tau - f) / r
    x_star = sg(x_star)
    # one Newton step with gradients: exact implicit derivative, value unchanged at the root
    f, r, _, _, _ = _time_of_x(x_star, r0, sigma0, alpha, sqrt_mu, sf)
    x = x_star + (sqrt_mu * tau - f) / r
    xi = alpha * x * x
    c, s = sf(xi)
    x2 = x * x
    r = x2 * c + sigma0 * x * (1.0 - xi * s) + r0 * (1.0 - xi * c)
    f_l = 1.0 - x2 * c / r0
    g_l = tau - x2 * x * s / sqrt_mu
    fdot = sqrt_mu * x * (xi * s - 1.0) / (r0 * r)
    gdot = 1.0 - x2 * c / r
    r_vec = f_l * r0_vec + g_l * v0_vec
    v_vec = fdot * r0_vec + gdot * v0_vec
    return ConicState(r_vec, v_vec, x, f_l, g_l, fdot, gdot)


def kepler(r0_vec: Array, v0_vec: Array, tau: float | Array, mu: float | Array) -> tuple[Array, Array]:
    """Conic state (r km, v km/s) after ``tau`` seconds (convenience wrapper of kepler_fg)."""
    out = kepler_fg(r0_vec, v0_vec, tau, mu)
    return out.r, out.v


def predict_universal_anomaly(x: Array, r_vec: Array, v_vec: Array, mu: Array, sqrt_mu: Array, dtau: Array) -> Array:
    """Universal anomaly dtau seconds after the conic point (r, v) with anomaly x, to third
    order: dx/dt = sqrt(mu)/r, d2x/dt2 = -sqrt(mu) rdot/r^2,
    d3x/dt3 = -sqrt(mu)(rddot/r^2 - 2 rdot^2/r^3), rddot = (v^2 - rdot^2)/r - mu/r^2."""
    r = jnp.linalg.norm(r_vec)
    rdot = dot3(r_vec, v_vec) / r
    rddot = (dot3(v_vec, v_vec) - rdot * rdot) / r - mu / (r * r)
    d1 = sqrt_mu / r
    d2 = -sqrt_mu * rdot / (r * r)
    d3 = -sqrt_mu * (rddot / (r * r) - 2.0 * rdot * rdot / (r * r * r))
    return x + dtau * (d1 + dtau * (0.5 * d2 + dtau * d3 / 6.0))
