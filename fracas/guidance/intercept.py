"""Two-vehicle intercept maneuver (the TPI / midcourse-correction type of R-649 Fig. II-18)
and its sensitivity to both vehicles' state errors.

At t_m the chaser (r_A, v_A) needs the velocity v_1 that brings it, on a conic of the
central body (mu km^3/s^2), to the target's position r_Tf at t_f = t_m + tof::

    kepler(r_A, v_1, tof).r = r_Tf = kepler(r_T, v_T, tof).r,     dV = v_1 - v_A   (km/s)

(the Lambert problem, solved here by Newton iteration on v_1 from the linear guess of the
coast STM; onboard targeting used conics the same way).  The maneuver's sensitivity to
the states (3 x 12, columns [x_A; x_T]) is the implicit-function derivative at the
solution, with Phi = d(r, v)(t_f)/d(r, v)(t_m) of each conic arc::

    d dV/d x_A = [-Phi_rv^-1 Phi_rr, -I]          (transfer arc)
    d dV/d x_T =  Phi_rv^-1 [Phi_T,rr, Phi_T,rv]   (target arc)

so the maneuver computed from ESTIMATED states errs by M (x_hat - x): its covariance from
knowledge errors is M E M' (R-649 Fig. II-18: |dV_hat - dV_true|).  Pure JAX; no raising:
the status is 0 when the intercept converged (miss < 1e-8 km), 1 otherwise.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax import Array
from jax.typing import ArrayLike

from fracas import _jax  # noqa: F401  (float64 before any array exists)
from fracas.dynamics.kepler import kepler

__all__ = ["intercept", "intercept_sensitivity", "INTERCEPT_TOLERANCE_KM"]

INTERCEPT_TOLERANCE_KM = 1e-8
_ITER = 40


def _arc(r: Array, v: Array, tof: float | Array, mu: float | Array) -> Array:
    rf, vf = kepler(r, v, tof, mu)
    return jnp.concatenate([rf, vf])


def _jac(r: Array, v: Array, tof: float | Array, mu: float | Array) -> Array:
    return jax.jacfwd(lambda x: _arc(x[:3], x[3:], tof, mu))(jnp.concatenate([r, v]))


@jax.jit
def intercept(
    x_chaser: ArrayLike, x_target: ArrayLike, tof_s: ArrayLike, mu: ArrayLike
) -> tuple[Array, Array, Array, Array]:
    """(dV (3,) km/s, v_1 (3,) km/s, miss km, status) of the intercept from x_chaser (6,) at
    t_m to the target's position tof_s later (module docstring)."""
    x_chaser = jnp.asarray(x_chaser, dtype=jnp.float64)
    x_target = jnp.asarray(x_target, dtype=jnp.float64)
    tof_s = jnp.asarray(tof_s, dtype=jnp.float64)
    mu = jnp.asarray(mu, dtype=jnp.float64)
    r_a, v_a = x_chaser[:3], x_chaser[3:6]
    r_tf = _arc(x_target[:3], x_target[3:6], tof_s, mu)[:3]

    def body(_: int, v1: Array) -> Array:
        f = _arc(r_a, v1, tof_s, mu)[:3] - r_tf
        J = _jac(r_a, v1, tof_s, mu)[:3, 3:]
        step = jnp.linalg.solve(J, f)
        # damp steps larger than half the speed (far from the root the linear model fails)
        scale = jnp.minimum(1.0, 0.5 * jnp.linalg.norm(v1) / jnp.maximum(jnp.linalg.norm(step), 1e-300))
        v_new = v1 - scale * step
        return jnp.where(jnp.all(jnp.isfinite(v_new)), v_new, v1)

    v1 = jax.lax.fori_loop(0, _ITER, body, v_a)
    miss = jnp.linalg.norm(_arc(r_a, v1, tof_s, mu)[:3] - r_tf)
    status = jnp.where(miss < INTERCEPT_TOLERANCE_KM, 0, 1)
    return v1 - v_a, v1, miss, status


@jax.jit
def intercept_sensitivity(
    x_chaser: ArrayLike, x_target: ArrayLike, v1: ArrayLike, tof_s: float | Array, mu: float | Array
) -> Array:
    """M (3, 12): d dV / d [x_A; x_T] at the converged intercept v1 (module docstring)."""
    x_chaser = jnp.asarray(x_chaser, dtype=jnp.float64)
    x_target = jnp.asarray(x_target, dtype=jnp.float64)
    Jx = _jac(x_chaser[:3], jnp.asarray(v1, dtype=jnp.float64), tof_s, mu)
    Jt = _jac(x_target[:3], x_target[3:6], tof_s, mu)
    inv_rv = jnp.linalg.inv(Jx[:3, 3:])
    m_a = jnp.concatenate([-inv_rv @ Jx[:3, :3], -jnp.eye(3, dtype=jnp.float64)], axis=1)
    m_t = inv_rv @ Jt[:3, :]
    return jnp.concatenate([m_a, m_t], axis=1)
