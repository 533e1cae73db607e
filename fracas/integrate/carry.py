"""The loop state of a propagation and its restarts (FRACAS TRAJ continuation set, Doc. 4
sec. 4.1): the carry, rectification to a new osculating conic, impulses, changes of primary body
and the initial carry.

Part of the Encke/Nystrom core (:mod:`fracas.integrate.encke`, which re-exports every name
here).  Everything is jit-, vmap- and jvp-able.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

import jax
import jax.numpy as jnp

from fracas import (
    _jax,  # noqa: F401
    constants,
)
from fracas.dynamics import propulsion
from fracas.dynamics.model import STOP_RADIUS, ForceModel, Params
from fracas.integrate import highorder
from fracas.integrate.accelerations import body_states
from fracas.integrate.events import event_functions

if TYPE_CHECKING:
    from jax.typing import ArrayLike

    from fracas.dynamics.ephemeris import EphemerisTable


class Carry(NamedTuple):
    """Loop state of one propagation (the continuation set of Doc. 4 plus mass and events)."""

    t: jax.Array  # s since the propagation epoch
    t_rect: jax.Array  # s, epoch of the current conic
    r0: jax.Array  # (3,) km, conic state at t_rect
    v0: jax.Array  # (3,) km/s
    rc: jax.Array  # (3,) conic position at t
    vc: jax.Array  # (3,) conic velocity at t
    delta: jax.Array  # (3,) km, position deviation
    nu: jax.Array  # (3,) km/s, velocity deviation
    m: jax.Array  # kg
    primary: jax.Array  # int32 index of the primary body
    g_prev: jax.Array  # (ne,) event functions at t
    locating: jax.Array  # int32: -1, or the event being located
    dt_norm: jax.Array  # s, last normal step (bounds Newton steps while locating)
    done: jax.Array  # bool: stop condition met or failure
    status: jax.Array  # int32
    n_steps: jax.Array  # int32: loop iterations (steps attempted, Newton steps included)
    n_rect: jax.Array  # int32
    h_next: jax.Array  # s, step size the controller proposes next (magnitude; tolerance control)
    n_reject: jax.Array  # int32: steps rejected by the error control
    phi: jax.Array  # (7, 7 + np) explicit variational sensitivities, or (0,) when not integrated
    # the yaw switch (``ForceModel.yaw_switch``; +1.0, 0, nan otherwise): the sign of cos u the
    # thrust uses, held over steps and flipped at each located antinode; flips located so
    # far; the time (s) of the last one
    yaw_sign: jax.Array = 1.0  # type: ignore[assignment]
    n_flips: jax.Array = 0  # type: ignore[assignment]
    t_flip: jax.Array = float("nan")  # type: ignore[assignment]


def _break_candidates(params: Params) -> jax.Array:
    """Times (s) at which a step must end: thrust switches and impulses (FRACAS DETECT)."""
    return jnp.concatenate([params.arc_t_on, params.arc_t_off, params.impulse_t])


def _rectify(c: Carry, ratio: ArrayLike, force: ArrayLike = False) -> Carry:
    """New osculating conic when the deviations exceed ``ratio`` of the conic (Doc. 4 sec. 4.1)."""
    dn = jnp.linalg.norm(c.delta)
    nn = jnp.linalg.norm(c.nu)
    rect = (dn > ratio * jnp.linalg.norm(c.rc)) | (nn > ratio * jnp.linalg.norm(c.vc)) | force
    r = c.rc + c.delta
    v = c.vc + c.nu
    z3 = jnp.zeros(3)
    w = lambda new, old: jnp.where(rect, new, old)  # noqa: E731
    return c._replace(
        t_rect=w(c.t, c.t_rect),
        r0=w(r, c.r0),
        v0=w(v, c.v0),
        rc=w(r, c.rc),
        vc=w(v, c.vc),
        delta=w(z3, c.delta),
        nu=w(z3, c.nu),
        n_rect=c.n_rect + rect.astype(jnp.int32),
    )


def _apply_impulses(
    model: ForceModel, params: Params, c: Carry, t_prev: ArrayLike, direction: ArrayLike, eps_t: ArrayLike
) -> Carry:
    """Add the impulsive dV of every impulse whose time the step just reached (FRACAS events)."""
    if model.n_impulses == 0:
        return c
    hit = (jnp.abs(params.impulse_t - c.t) < eps_t) & (jnp.abs(params.impulse_t - t_prev) >= eps_t)
    r = c.rc + c.delta
    v = c.vc + c.nu
    hitf = hit.astype(jnp.float64)

    def total_dv(v_pre):
        # velocity-frame impulses are defined on the pre-impulse velocity (FRACAS EP frame)
        frame = propulsion.velocity_frame(r, v_pre)
        dv_vel = jnp.einsum("ij,kj->ki", frame, params.impulse_dv)
        dv = jnp.where(params.impulse_frame[:, None] > 0.5, params.impulse_dv, dv_vel)
        return jnp.sum(hitf[:, None] * dv, axis=0)

    # forward: v+ = v- + dV(v-); backward: solve v- = v+ - dV(v-) by fixed-point iteration
    # (contraction rate ~|dV|/|v|; 8 passes reach roundoff for |dV| < 0.1 |v|)
    v_pre = v
    for _ in range(8):
        v_pre = jnp.where(direction > 0, v, v - total_dv(v_pre))
    dv_tot = direction * total_dv(v_pre)
    ve = params.impulse_isp_s * constants.G0_KM_S2
    dlnm = -direction * jnp.sum(hitf * jnp.linalg.norm(params.impulse_dv, axis=1)) / ve
    c = c._replace(nu=c.nu + dv_tot, m=c.m * jnp.exp(dlnm))
    # a new osculating conic after an impulse (Apollo practice), so the deviation equations
    # do not carry the dV as a large deviation
    return _rectify(c, jnp.inf, force=jnp.any(hit))


# ---------------------------------------------------------------------- propagation
def _initial_step(model: ForceModel, params: Params, r: jax.Array, v: jax.Array, primary: jax.Array) -> jax.Array:
    """First trial step (s) of tolerance control: a fraction of the osculating time scale
    r^(3/2)/sqrt(mu), scaled by tol^(1/(q+1)); the controller corrects it within a few steps
    (it may grow 5x per step), so the guess only needs the right order of magnitude."""
    st = model.integrator
    if not st.adaptive:
        return jnp.zeros(())
    rn = jnp.linalg.norm(r)
    scale = rn * jnp.sqrt(rn / params.mu[primary])
    guess = 0.05 * scale * (jnp.asarray(st.tolerance) / 1e-12) ** highorder.control_exponent(st.method)
    return jax.lax.stop_gradient(jnp.minimum(guess, st.dt_max_s))


def init_carry(
    model: ForceModel, params: Params, ephem: EphemerisTable | None, epoch_et: ArrayLike, t0: ArrayLike, x0: jax.Array
) -> tuple[Carry, jax.Array]:
    """Carry at t0 for state x0 = (r km, v km/s, m kg) relative to ``model.primary``.

    Returns the carry and the sign s0 used by a 'radius' stop condition.
    """
    r, v, m = x0[:3], x0[3:6], x0[6]
    primary = jnp.asarray(model.primary, jnp.int32)
    pos, vel = body_states(model, params, ephem, epoch_et + t0)
    radius_sign = jnp.asarray(1.0)
    if model.stop.kind == STOP_RADIUS:
        rb = r + pos[model.primary] - pos[model.stop.body]
        radius_sign = jnp.where(jnp.linalg.norm(rb) >= model.stop.radius_km, 1.0, -1.0)
    yaw_sign = propulsion.yaw_sign_of(r, v) if model.yaw_switch else jnp.ones(())
    g = event_functions(model, params, r, v, primary, pos, vel, radius_sign, yaw_sign)
    z3 = jnp.zeros(3)
    zi = jnp.zeros((), jnp.int32)
    c = Carry(
        t=jnp.asarray(t0, jnp.float64),
        t_rect=jnp.asarray(t0, jnp.float64),
        r0=r,
        v0=v,
        rc=r,
        vc=v,
        delta=z3,
        nu=z3,
        m=jnp.asarray(m, jnp.float64),
        primary=primary,
        g_prev=g,
        locating=jnp.asarray(-1, jnp.int32),
        dt_norm=jnp.zeros(()),
        done=jnp.asarray(False),
        status=zi,
        n_steps=zi,
        n_rect=zi,
        h_next=_initial_step(model, params, r, v, primary),
        n_reject=zi,
        phi=jnp.zeros((0,)),
        yaw_sign=jax.lax.stop_gradient(yaw_sign),
        n_flips=zi,
        t_flip=jnp.asarray(jnp.nan),
    )
    if model.n_impulses:
        # impulses exactly at the start time are applied before the first step
        c = _apply_impulses(model, params, c, jnp.asarray(jnp.inf), 1.0, model.integrator.eps_t_s)
    return c, radius_sign


def _switch_primary(
    model: ForceModel, params: Params, c: Carry, new_p: jax.Array, pos: jax.Array, vel: jax.Array
) -> Carry:
    """Re-centre the state on body ``new_p`` and start a new conic (change of primary at an SOI)."""
    r = c.rc + c.delta + pos[c.primary] - pos[new_p]
    v = c.vc + c.nu + vel[c.primary] - vel[new_p]
    c = c._replace(primary=new_p.astype(jnp.int32), rc=r, vc=v, delta=jnp.zeros(3), nu=jnp.zeros(3))
    return _rectify(c, 0.0, force=True)


def state_of(c: Carry) -> jax.Array:
    """(r, v, m) of a carry as one 7-vector."""
    return jnp.concatenate([c.rc + c.delta, c.vc + c.nu, c.m[None]])
