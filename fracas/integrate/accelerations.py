"""Accelerations of the propagation loop (FRACAS GRAVFO, EP, POWER, EPHEM): the body states,
the thrust settings of a step, the perturbing acceleration and the full Cowell acceleration.

Part of the Encke/Nystrom core (:mod:`fracas.integrate.encke`, which re-exports every name
here); the high-order steps (:mod:`fracas.integrate.highorder`) and the variational equations
use the same functions.  Everything is jit-, vmap- and jvp-able.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

import jax
import jax.numpy as jnp

from fracas import (
    _jax,  # noqa: F401
    constants,
)
from fracas.dynamics import forces, propulsion
from fracas.dynamics.model import ForceModel, Params
from fracas.params import POINTING_LAW_FIELDS

if TYPE_CHECKING:
    from jax.typing import ArrayLike

    from fracas.dynamics.ephemeris import EphemerisTable


# ----------------------------------------------------------------------------- bodies
def body_states(
    model: ForceModel, params: Params, ephem: EphemerisTable | None, et_s: ArrayLike
) -> tuple[jax.Array, jax.Array]:
    """Heliocentric ICRF positions (km) and velocities (km/s) of ``model.bodies`` at ``et_s``.

    DE421 Chebyshev table for ephemeris bodies; fixed conics (FRACAS EPHEM) for the
    indices in ``model.conic_bodies``; zeros when the problem has only its primary.
    """
    nb = len(model.bodies)
    if ephem is None:
        pos = jnp.zeros((nb, 3))
        vel = jnp.zeros((nb, 3))
    else:
        from fracas.dynamics.ephemeris import body_states as _table_states

        pos, vel = _table_states(ephem, et_s)
    if model.conic_bodies:
        from fracas.dynamics.elements import conic_body_state

        sun = model.bodies.index("sun") if "sun" in model.bodies else None
        for b in model.conic_bodies:
            mu = params.mu[b] + (params.mu[sun] if sun is not None else constants.BODIES["sun"].mu_km3_s2)
            rb, vb = conic_body_state(params.body_elements[b], mu, et_s - params.body_elements_et[b])
            pos = pos.at[b].set(rb)
            vel = vel.at[b].set(vb)
    return pos, vel


# ----------------------------------------------------------------------- accelerations
class StepControls(NamedTuple):
    """Thrust settings frozen over one step (steps never straddle a switch)."""

    thrust_factor: jax.Array  # throttle * per-arc scale * overall scale (0 when coasting)
    alpha: jax.Array  # rad
    beta: jax.Array  # rad
    inertial: jax.Array  # frame code (``Params.arc_frame``): 0 velocity, 1 inertial, 2 yaw switch
    # the pointing's trigonometry, done once per step (None: computed at every evaluation);
    # propulsion.angles_to_unit(alpha, beta), the unit vector in the velocity frame or, for
    # inertial pointing, in ICRF
    u_angles: jax.Array | None = None
    # the active arc's pointing law (``ForceModel.steering``; None otherwise): (8,) = arc centre
    # (s), 2 / arc duration (1/s), then the Legendre P1..P3 coefficients of alpha and of beta (rad)
    law: jax.Array | None = None
    # the sign of cos u held over the step (``ForceModel.yaw_switch``: set by the loop from
    # ``Carry.yaw_sign``; None: taken from the state at each evaluation)
    yaw_sign: jax.Array | None = None


def step_controls(model: ForceModel, params: Params, t_mid: ArrayLike) -> StepControls:
    """Active-arc controls at the step midpoint (FRACAS DETECT/EP)."""
    if not model.thrust or model.n_arcs == 0:
        z = jnp.zeros(())
        return StepControls(z, z, z, z)
    on = ((t_mid >= params.arc_t_on) & (t_mid < params.arc_t_off)).astype(jnp.float64)
    factor = params.thrust_scale * jnp.sum(on * params.arc_throttle * params.arc_thrust_scale)
    alpha = jnp.sum(on * (params.arc_alpha + params.arc_bias_in_rad)) + params.bias_in_rad
    beta = jnp.sum(on * (params.arc_beta + params.arc_bias_out_rad)) + params.bias_out_rad
    inertial = jnp.sum(on * params.arc_frame)
    if model.steering:
        return StepControls(factor, alpha, beta, inertial, None, arc_law(params, on))
    return StepControls(factor, alpha, beta, inertial, propulsion.angles_to_unit(alpha, beta))


def arc_law(params: Params, on: jax.Array) -> jax.Array:
    """``StepControls.law`` of the arc selected by the 0/1 weights ``on`` (na,): its centre (s),
    2 / its duration (1/s) and its Legendre coefficients (``fracas.params.POINTING_LAW_FIELDS``); all
    zero when no arc is on (a coasting step: s = 0, no turn)."""
    width = params.arc_t_off - params.arc_t_on
    inv_half = jnp.sum(on * jnp.where(width > 0.0, 2.0 / jnp.where(width > 0.0, width, 1.0), 0.0))
    centre = jnp.sum(on * 0.5 * (params.arc_t_on + params.arc_t_off))
    coeffs = [jnp.sum(on * getattr(params, name)) for name in POINTING_LAW_FIELDS]
    return jnp.stack([centre, inv_half, *coeffs])


def steered_angles(ctl: StepControls, t: ArrayLike) -> tuple[jax.Array, jax.Array]:
    """(alpha, beta) (rad) of the active arc's pointing law at time t (s): the mean angles plus
    the Legendre series in s = (t - centre) * 2 / duration, clipped to [-1, 1]
    (P1 = s, P2 = (3s^2 - 1)/2, P3 = (5s^3 - 3s)/2)."""
    law = ctl.law
    s = jnp.clip((t - law[0]) * law[1], -1.0, 1.0)
    p2 = 1.5 * s * s - 0.5
    p3 = s * (2.5 * s * s - 1.5)
    alpha = ctl.alpha + law[2] * s + law[3] * p2 + law[4] * p3
    beta = ctl.beta + law[5] * s + law[6] * p2 + law[7] * p3
    return alpha, beta


def acting_third_bodies(model: ForceModel) -> tuple[int, ...]:
    """``ForceModel.acting_third_bodies`` (kept as a function for existing callers)."""
    return model.acting_third_bodies()


def perturbation(
    model: ForceModel,
    params: Params,
    t: ArrayLike,
    r: jax.Array,
    v: jax.Array,
    primary: ArrayLike,
    bodies_pos: jax.Array,
    ctl: StepControls,
    with_j2: bool = True,
) -> tuple[jax.Array, jax.Array, jax.Array]:
    """Perturbing acceleration split as (a_free, force, mdot) so that a_d = a_free + force/m.

    a_free (km/s^2): J2 of the primary and third bodies; force (kg km/s^2): thrust and
    solar radiation pressure; mdot (kg/s): propellant flow (FRACAS GRAVFO, EP, POWER).
    ``with_j2=False`` leaves J2 out (a Cowell step adds it with the central term,
    ``forces.central_j2_accel``).
    """
    a = jnp.zeros(3)
    force = jnp.zeros(3)
    mdot = jnp.zeros(())
    if model.j2 and with_j2:
        a = a + forces.j2_accel(r, params.mu[primary], params.j2[primary], params.radius[primary], params.pole[primary])
    rp = bodies_pos[primary]
    for b in acting_third_bodies(model):
        rho = bodies_pos[b] - rp
        # the current primary is never its own third body (rho = 0): select a harmless rho
        is_p = primary == b
        rho_safe = jnp.where(is_p, jnp.array([1.0e12, 0.0, 0.0]), rho)
        a = a + jnp.where(is_p, 0.0, 1.0) * forces.third_body_accel(r, rho_safe, params.mu[b])
    need_sun = model.srp or (model.thrust and model.power == "solar")
    if need_sun:
        sun = model.bodies.index("sun")
        r_sun = r + rp - bodies_pos[sun]
    if model.srp:
        force = force + forces.srp_accel(r_sun, params.area_m2, 1.0, params.cr)
    if model.thrust:
        p_kw = propulsion.power_kw(
            params.power_kw,
            r_sun if model.power == "solar" else None,
            t,
            params.power_decay_s,
            solar=model.power == "solar",
        )
        tmag = ctl.thrust_factor * propulsion.thrust_magnitude(p_kw, params.efficiency, params.exhaust_velocity_km_s)
        if ctl.law is not None:
            alpha, beta = steered_angles(ctl, t)
            u = propulsion.thrust_direction(r, v, alpha, beta, ctl.inertial, yaw_sign=ctl.yaw_sign)
        else:
            u = propulsion.thrust_direction(
                r, v, ctl.alpha, ctl.beta, ctl.inertial, ctl.u_angles, yaw_sign=ctl.yaw_sign
            )
        force = force + tmag * u
        mdot = -tmag / params.exhaust_velocity_km_s
    return a, force, mdot


def total_acceleration(
    model: ForceModel,
    params: Params,
    t: ArrayLike,
    r: jax.Array,
    v: jax.Array,
    m: ArrayLike,
    primary: ArrayLike,
    bodies_pos: jax.Array,
    ctl: StepControls,
) -> jax.Array:
    """Full acceleration (km/s^2) in Cowell form: -mu r/r^3 + a_d (used for events and tests)."""
    a, force, _ = perturbation(model, params, t, r, v, primary, bodies_pos, ctl)
    return forces.point_mass_accel(r, params.mu[primary]) + a + force / m
