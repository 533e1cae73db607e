"""Encke propagation with the 4th-order Nystrom integrator (Doc. 4 secs. 4.1, 4.3; FRACAS TRAJ,
INTEG, ENCON, DETECT, GRAVFO).

The state is carried as deviations (delta, nu) from an osculating conic of the current
primary body (epoch t_rect, state r0, v0), with Potter's f(q) for the central term:

    delta'' = -(mu / r_con^3) [f(q) r + delta] + a_d(t, r, v, m),   r = r_con + delta,
    q = delta.(delta - 2 r) / r.r                                   (Doc. 4 eq. 4.1-3)

The conic is rectified when |delta| > ratio |r_con| or |nu| > ratio |v_con| (ratio 0.01).
Each Nystrom step (Doc. 4 sec. 4.3) costs two short-arc Kepler solves (conic advanced
t -> t + dt/2 -> t + dt, each from a third-order prediction of the universal anomaly) and
three acceleration evaluations, four when the acceleration depends on velocity (thrust in
the velocity frame).  Every impulse starts a new osculating conic.  Mass is integrated with
the same stages (classical RK4 weights; mdot depends only on t and r, so stages 2 and 3
share it).  Steps follow dt = +-min(|t_F - t|, c_nom r_con^(3/2)/sqrt(mu), dt_max) and
are broken exactly at thrust switches, impulses and output times (FRACAS DETECT).

Stopping conditions (sphere-of-influence entry, closest approach, a radius) and changes of
primary body are *located*: after the step in which the event function changes sign,
Newton steps dt = -g/gdot (gdot from a JVP of g along the motion) are taken until
|dt| < eps_t, so the event lands to a time tolerance, not on a step boundary.

Everything here is jit-, vmap- and jvp-able: no Python branches on traced values, and a
status code instead of exceptions.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from fracas import (
    _jax,  # noqa: F401
    constants,
)
from fracas.dynamics import forces, propulsion
from fracas.dynamics.kepler import kepler_fg, predict_universal_anomaly
from fracas.dynamics.model import (
    STOP_CLOSEST_APPROACH,
    STOP_RADIUS,
    STOP_SOI_ENTRY,
    STOP_TIME,
    ForceModel,
    Params,
)
from fracas.integrate import highorder
from fracas.params import POINTING_LAW_FIELDS
from fracas.status import RunStatus

# status codes (names kept for compatibility; the enumeration is fracas.status.RunStatus)
STATUS_OK = int(RunStatus.OK)  # reached the final time
STATUS_STOPPED = int(RunStatus.STOPPED)  # the stop condition was met (located)
STATUS_MAX_STEPS = int(RunStatus.MAX_STEPS)  # max_steps reached
STATUS_NONFINITE = int(RunStatus.NONFINITE)  # the state became NaN/inf
_INACTIVE = 1.0e30  # event-function value of an inactive event (never crosses zero)


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


# ----------------------------------------------------------------------------- bodies
def body_states(model: ForceModel, params: Params, ephem, et_s):
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


def step_controls(model: ForceModel, params: Params, t_mid) -> StepControls:
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


def arc_law(params: Params, on) -> jax.Array:
    """``StepControls.law`` of the arc selected by the 0/1 weights ``on`` (na,): its centre (s),
    2 / its duration (1/s) and its Legendre coefficients (``fracas.params.POINTING_LAW_FIELDS``); all
    zero when no arc is on (a coasting step: s = 0, no turn)."""
    width = params.arc_t_off - params.arc_t_on
    inv_half = jnp.sum(on * jnp.where(width > 0.0, 2.0 / jnp.where(width > 0.0, width, 1.0), 0.0))
    centre = jnp.sum(on * 0.5 * (params.arc_t_on + params.arc_t_off))
    coeffs = [jnp.sum(on * getattr(params, name)) for name in POINTING_LAW_FIELDS]
    return jnp.stack([centre, inv_half, *coeffs])


def steered_angles(ctl: StepControls, t):
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


def perturbation(model: ForceModel, params: Params, t, r, v, primary, bodies_pos, ctl: StepControls, with_j2=True):
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
            u = propulsion.thrust_direction(r, v, alpha, beta, ctl.inertial)
        else:
            u = propulsion.thrust_direction(r, v, ctl.alpha, ctl.beta, ctl.inertial, ctl.u_angles)
        force = force + tmag * u
        mdot = -tmag / params.exhaust_velocity_km_s
    return a, force, mdot


def total_acceleration(model, params, t, r, v, m, primary, bodies_pos, ctl):
    """Full acceleration (km/s^2) in Cowell form: -mu r/r^3 + a_d (used for events and tests)."""
    a, force, _ = perturbation(model, params, t, r, v, primary, bodies_pos, ctl)
    return forces.point_mass_accel(r, params.mu[primary]) + a + force / m


_encke_accel = forces.encke_deviation_accel  # Doc. 4 eq. 4.1-3 (kept under its old name)


# ---------------------------------------------------------------------------- events
def _n_events(model: ForceModel) -> int:
    return 1 + (len(model.bodies) if model.change_primary_at_soi else 0)


def event_functions(model: ForceModel, params: Params, r, v, primary, bodies_pos, bodies_vel, radius_sign):
    """Event functions g (ne,); an event happens when g falls through zero.

    g[0] is the stop condition: soi_entry |r_b| - R_soi(b); closest_approach -(r_b . v_b);
    radius s0(|r_b| - R) with s0 the side the propagation started on.  When primary changes
    are on, g[1 + b] is |r_b| - R_soi(b) for bodies whose parent is the primary (entry) and
    R_soi(p) - |r| for the primary itself (exit).  Inactive entries are +1e30.
    """
    stop = model.stop
    rp, vp = bodies_pos[primary], bodies_vel[primary]
    g = []
    if stop.kind == STOP_TIME:
        g.append(jnp.asarray(_INACTIVE))
    else:
        b = stop.body
        rb = r + rp - bodies_pos[b]
        vb = v + vp - bodies_vel[b]
        dist = jnp.linalg.norm(rb)
        if stop.kind == STOP_SOI_ENTRY:
            gs = jnp.where(primary == b, _INACTIVE, dist - params.soi_radius[b])
        elif stop.kind == STOP_CLOSEST_APPROACH:
            gs = -forces.dot3(rb, vb)
        elif stop.kind == STOP_RADIUS:
            gs = radius_sign * (dist - stop.radius_km)
        else:  # pragma: no cover - validated upstream
            raise ValueError(stop.kind)
        g.append(gs)
    if model.change_primary_at_soi:
        for b in range(len(model.bodies)):
            rb = r + rp - bodies_pos[b]
            dist = jnp.linalg.norm(rb)
            soi = params.soi_radius[b]
            entry = jnp.where(params.parent[b] == primary.astype(jnp.float64), dist - soi, _INACTIVE)
            exit_ = jnp.where((primary == b) & (params.parent[b] >= 0), soi - jnp.linalg.norm(r), _INACTIVE)
            g.append(jnp.where(primary == b, exit_, entry))
    return jnp.stack(g)


# ------------------------------------------------------------------------ the step
_N_NEWTON = 2  # Newton steps after the predictor: (n dt/2)^4/24 ~ 2e-5 -> 4e-10 -> 2e-19


_predict_x = predict_universal_anomaly  # third-order Taylor prediction (kepler module)


def _nystrom_step(model, params, ephem, epoch_et, c: Carry, dt, ctl: StepControls):
    """One Encke/Nystrom step of size dt (Doc. 4 sec. 4.3; FRACAS INTEG).  Returns the new
    (t, rc, vc, delta, nu, m) and the body states at t + dt.

    The conic is advanced in two half steps from the current conic point (chained f and g:
    t -> t + dt/2 -> t + dt) rather than over the whole time since rectification: each solve
    is then a short arc (|alpha x^2| ~ (n dt/2)^2), solved with polynomial Stumpff functions
    and two Newton steps from a third-order prediction.  The chained conic differs from the
    one-shot conic by roundoff only (~1e-16 relative per half step)."""
    p = c.primary
    mu = params.mu[p]
    sqrt_mu = jnp.sqrt(mu)
    t = c.t
    # stage 1 (t)
    pos1, _ = body_states(model, params, ephem, epoch_et + t)
    r1 = c.rc + c.delta
    v1 = c.vc + c.nu
    a1, f1, md1 = perturbation(model, params, t, r1, v1, p, pos1, ctl)
    k1 = _encke_accel(mu, c.rc, c.delta, a1, f1, c.m)
    # conic at t + dt/2 (Kepler solve 1, started from a 3rd-order Taylor prediction of x)
    h = 0.5 * dt
    xs = _predict_x(0.0, c.rc, c.vc, mu, sqrt_mu, h)
    half = kepler_fg(c.rc, c.vc, h, mu, xs, n_newton=_N_NEWTON, short_arc=True)
    pos2, _ = body_states(model, params, ephem, epoch_et + t + h)
    d_b = c.delta + c.nu * h + k1 * (dt * dt / 8.0)
    n_b = c.nu + k1 * h
    m_b = c.m + md1 * h
    a2, f2, md2 = perturbation(model, params, t + h, half.r + d_b, half.v + n_b, p, pos2, ctl)
    k2 = _encke_accel(mu, half.r, d_b, a2, f2, m_b)
    m_c = c.m + md2 * h
    if model.velocity_dependent:
        n_c = c.nu + k2 * h
        a3, f3, md3 = perturbation(model, params, t + h, half.r + d_b, half.v + n_c, p, pos2, ctl)
        k3 = _encke_accel(mu, half.r, d_b, a3, f3, m_c)
    else:  # k3 = k2 apart from the stage mass (Doc. 4: three evaluations per step)
        k3 = k2 + f2 * (1.0 / m_c - 1.0 / m_b)
        md3 = md2
    # conic at t + dt (Kepler solve 2, warm start from the half-step solve)
    xs2 = _predict_x(0.0, half.r, half.v, mu, sqrt_mu, h)
    end = kepler_fg(half.r, half.v, h, mu, xs2, n_newton=_N_NEWTON, short_arc=True)
    pos4, vel4 = body_states(model, params, ephem, epoch_et + t + dt)
    d_c = c.delta + c.nu * dt + k3 * (0.5 * dt * dt)
    n_c4 = c.nu + k3 * dt
    m_d = c.m + md3 * dt
    a4, f4, md4 = perturbation(model, params, t + dt, end.r + d_c, end.v + n_c4, p, pos4, ctl)
    k4 = _encke_accel(mu, end.r, d_c, a4, f4, m_d)
    delta = c.delta + c.nu * dt + (k1 + k2 + k3) * (dt * dt / 6.0)
    nu = c.nu + (k1 + 2.0 * k2 + 2.0 * k3 + k4) * (dt / 6.0)
    m = c.m + (md1 + 2.0 * md2 + 2.0 * md3 + md4) * (dt / 6.0)
    return (t + dt, end.r, end.v, delta, nu, m), (pos4, vel4)


def _break_candidates(params: Params):
    """Times (s) at which a step must end: thrust switches and impulses (FRACAS DETECT)."""
    return jnp.concatenate([params.arc_t_on, params.arc_t_off, params.impulse_t])


def _rectify(c: Carry, ratio, force=False) -> Carry:
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


def _apply_impulses(model, params, c: Carry, t_prev, direction, eps_t) -> Carry:
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
def _initial_step(model: ForceModel, params: Params, r, v, primary):
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


def init_carry(model: ForceModel, params: Params, ephem, epoch_et, t0, x0) -> tuple[Carry, jax.Array]:
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
    g = event_functions(model, params, r, v, primary, pos, vel, radius_sign)
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
    )
    if model.n_impulses:
        # impulses exactly at the start time are applied before the first step
        c = _apply_impulses(model, params, c, jnp.asarray(jnp.inf), 1.0, model.integrator.eps_t_s)
    return c, radius_sign


def _switch_primary(model, params, c: Carry, new_p, pos, vel) -> Carry:
    """Re-centre the state on body ``new_p`` and start a new conic (change of primary at an SOI)."""
    r = c.rc + c.delta + pos[c.primary] - pos[new_p]
    v = c.vc + c.nu + vel[c.primary] - vel[new_p]
    c = c._replace(primary=new_p.astype(jnp.int32), rc=r, vc=v, delta=jnp.zeros(3), nu=jnp.zeros(3))
    return _rectify(c, 0.0, force=True)


def advance(model: ForceModel, params: Params, ephem, epoch_et, c: Carry, t_end, radius_sign, var_labels=None) -> Carry:
    """Integrate from c.t to t_end (either direction), stopping early at the stop condition.

    ``var_labels`` (static tuple of parameter labels): also integrate the explicit variational
    equations into ``c.phi`` (7, 7 + np) (``highorder.variational_supported`` models only)."""
    st = model.integrator
    eps_t = st.eps_t_s
    t_end = jnp.asarray(t_end, jnp.float64)
    direction = jnp.where(t_end >= c.t, 1.0, -1.0)
    breaks = _break_candidates(params)

    def cond(c: Carry):
        arrived = (jnp.abs(t_end - c.t) < eps_t) & (c.locating < 0)
        return (~c.done) & (~arrived) & (c.n_steps < st.max_steps)

    has_events = model.stop.kind != STOP_TIME or model.change_primary_at_soi

    adaptive = st.adaptive
    faithful = st.method == "rkn4" and st.formulation == "encke"
    if var_labels is not None and not highorder.variational_supported(model, var_labels):
        raise ValueError("explicit variational equations: Cowell, no impulses, events or break-time parameters")
    if adaptive:
        expo = highorder.control_exponent(st.method)

    def rectify(c: Carry) -> Carry:
        # a Cowell carry has no deviations to rectify (impulses and primary changes still
        # restart it through _rectify(force=True), which only moves the velocity into vc)
        return c if st.formulation == "cowell" else _rectify(c, st.rect_ratio)

    def normal_step(c: Carry):
        p = c.primary
        if adaptive:
            # the controller's proposal (no derivative flows through a step-size choice)
            dt_nom = jax.lax.stop_gradient(c.h_next)
        else:
            # The nominal step is a control choice, not part of the dynamics: no derivative
            # flows through it, so sensitivities are the variational equations integrated
            # with the same steps (FRACAS INTEG integrates the STM alongside the state).
            # Breaks (thrust switches, impulses, outputs) keep theirs: d/d(switch time) is a
            # real derivative.
            r_n = jnp.linalg.norm(c.rc + c.delta) if st.formulation == "cowell" else jnp.linalg.norm(c.rc)
            rc_n = jax.lax.stop_gradient(r_n)
            dt_nom = st.c_nom * rc_n * jnp.sqrt(rc_n / jax.lax.stop_gradient(params.mu[p]))
        # next break in the direction of motion (DETECT)
        ahead = (breaks - c.t) * direction > eps_t
        # (t_end is appended so the min is never over an empty set: no inf tangents)
        t_brk = jnp.concatenate([jnp.where(ahead, breaks, t_end), t_end[None]])
        span = jnp.min(jnp.abs(t_brk - c.t))
        return direction * jnp.minimum(jnp.minimum(span, dt_nom), st.dt_max_s)

    def take_step(c: Carry, dt):
        """(state after the step and its impulses, body states at its end, error ratio)."""
        ctl = step_controls(model, params, c.t + 0.5 * dt)
        if faithful:
            (t1, rc1, vc1, d1, n1, m1), body4 = _nystrom_step(model, params, ephem, epoch_et, c, dt, ctl)
            err = jnp.zeros(())
        else:
            out, body4, err = highorder.step(
                model,
                params,
                ephem,
                epoch_et,
                c,
                dt,
                ctl,
                st.tolerance,
                perturbation=perturbation,
                body_states=body_states,
                step_controls=step_controls,
                var_labels=var_labels,
            )
            t1, rc1, vc1, d1, n1, m1 = out[:6]
            if var_labels is not None:
                c = c._replace(phi=out[6])
        new = c._replace(t=t1, rc=rc1, vc=vc1, delta=d1, nu=n1, m=m1, n_steps=c.n_steps + 1)
        return _apply_impulses(model, params, new, c.t, direction, eps_t), body4, err

    def control(c: Carry, new: Carry, dt, err, force_accept):
        """Accept or reject the trial step ``new`` (tolerance control); returns (carry, accepted).

        Accepted when err <= 1 (or ``force_accept``: Newton steps of an event location, whose
        sizes are bounded by the last accepted step); h_next = |dt| clip(0.9 err^(-1/(q+1)),
        0.2, 5), not shrunk below the previous proposal after a step that a break cut short.
        A rejected step leaves the state as it was.  A step size below eps_t (the controller
        cannot meet the tolerance: a collision, a singularity) ends the run as non-finite.
        """
        if not adaptive:
            return new, jnp.asarray(True)
        ok = (err <= 1.0) | force_accept
        fac = jnp.clip(0.9 * jnp.where(err > 0, err, 1e-300) ** (-expo), 0.2, 5.0)
        h_prop = jax.lax.stop_gradient(jnp.abs(dt) * fac)
        cut_short = jnp.abs(dt) < c.h_next * (1.0 - 1e-12)
        h_prop = jnp.where(ok & cut_short, jnp.maximum(h_prop, c.h_next), h_prop)
        h_prop = jnp.where(force_accept, c.h_next, h_prop)
        new = new._replace(h_next=h_prop)
        rej = c._replace(h_next=h_prop, n_steps=c.n_steps + 1, n_reject=c.n_reject + 1)
        collapsed = (~ok) & (h_prop < eps_t)
        rej = rej._replace(done=collapsed, status=jnp.where(collapsed, STATUS_NONFINITE, rej.status).astype(jnp.int32))
        out = jax.tree_util.tree_map(lambda a, b: jnp.where(ok, a, b), new, rej)
        return out, ok

    def check_finite(c: Carry, new: Carry, stop_now):
        finite = jnp.all(jnp.isfinite(new.delta)) & jnp.all(jnp.isfinite(new.nu)) & jnp.isfinite(new.m)
        finite = finite & jnp.all(jnp.isfinite(new.rc)) & jnp.all(jnp.isfinite(new.vc))
        status = jnp.where(stop_now, STATUS_STOPPED, jnp.where(finite, new.status, STATUS_NONFINITE))
        return new._replace(done=new.done | stop_now | (~finite), status=status.astype(jnp.int32))

    def body_plain(c: Carry):
        """Final-time stop only, no primary changes: no event functions are evaluated."""
        c = rectify(c)
        dt = normal_step(c)
        new, _, err = take_step(c, dt)
        new, _ = control(c, new, dt, err, jnp.asarray(False))
        return check_finite(c, new, jnp.asarray(False))

    def body_events(c: Carry):
        c = rectify(c)
        p = c.primary
        dt_normal = normal_step(c)
        # Newton step on the event being located: dt = -g/gdot, gdot = dg/dt along the motion.
        # Only while locating (lax.cond: a normal step pays nothing for it; the cheap test is
        # the sign change of the event functions at the end of an accepted step, below)
        locating = c.locating >= 0
        k_ev = jnp.maximum(c.locating, 0)

        def newton_step(c: Carry):
            r = c.rc + c.delta
            v = c.vc + c.nu
            pos, _ = body_states(model, params, ephem, epoch_et + c.t)
            ctl0 = step_controls(model, params, c.t)

            def g_of(tt, rr, vv):
                ps, vs = body_states(model, params, ephem, epoch_et + tt)
                return event_functions(model, params, rr, vv, p, ps, vs, radius_sign)[k_ev]

            acc = total_acceleration(model, params, c.t, r, v, c.m, p, pos, ctl0)
            g_val, g_dot = jax.jvp(g_of, (c.t, r, v), (jnp.ones(()), v, acc))
            return -g_val / jnp.where(g_dot == 0.0, 1e-30, g_dot)

        dt_newton = jax.lax.cond(locating, newton_step, lambda c: jnp.zeros_like(c.t), c)
        lim = jnp.abs(c.dt_norm)
        dt_newton = jnp.clip(dt_newton, -lim, lim)
        # never step past the segment end while locating
        dt_newton = jnp.where(direction * (c.t + dt_newton - t_end) > 0.0, t_end - c.t, dt_newton)
        located = locating & (jnp.abs(dt_newton) < eps_t)
        dt = jnp.where(locating, dt_newton, dt_normal)
        dt = jnp.where(located, 0.0, dt)
        new, (pos4, vel4), err = take_step(c, dt)
        new = new._replace(dt_norm=jnp.where(locating, c.dt_norm, dt))
        new, accepted = control(c, new, dt, err, locating)
        r1 = new.rc + new.delta
        v1 = new.vc + new.nu
        g_new = event_functions(model, params, r1, v1, p, pos4, vel4, radius_sign)
        g_new = jnp.where(accepted, g_new, c.g_prev)
        # a crossing in this (normal, accepted) step starts the location of the earliest event
        crossed = (c.g_prev > 0.0) & (g_new <= 0.0) & (~locating) & accepted
        frac = c.g_prev / jnp.where(crossed, c.g_prev - g_new, 1.0)
        frac = jnp.where(crossed, frac, jnp.inf)
        first = jnp.argmin(frac).astype(jnp.int32)
        any_cross = jnp.any(crossed)
        new = new._replace(g_prev=g_new, locating=jnp.where(any_cross, first, c.locating))
        # event located: stop (event 0) or change primary (event 1 + b)
        stop_now = located & (c.locating == 0)
        new = jax.tree_util.tree_map(lambda a, b: jnp.where(located, a, b), c, new)
        new = new._replace(n_steps=c.n_steps + 1, n_reject=jnp.where(located, c.n_reject, new.n_reject))
        if model.change_primary_at_soi:
            do_switch = located & (c.locating > 0)

            def switch(c: Carry, new: Carry) -> Carry:
                pos, vel = body_states(model, params, ephem, epoch_et + c.t)
                b = c.locating - 1
                is_exit = b == p
                parent = params.parent[jnp.maximum(b, 0)].astype(jnp.int32)
                new_p = jnp.where(is_exit, parent, b)
                switched = _switch_primary(model, params, c, new_p, pos, vel)
                g_sw = event_functions(model, params, switched.rc, switched.vc, switched.primary, pos, vel, radius_sign)
                return switched._replace(g_prev=g_sw, locating=jnp.asarray(-1, jnp.int32))

            new = jax.lax.cond(do_switch, switch, lambda c, new: new, c, new)
        new = check_finite(c, new, stop_now)
        return new._replace(locating=jnp.where(stop_now, -1, new.locating))

    body = body_events if has_events else body_plain
    c = jax.lax.while_loop(cond, body, c)
    hit_max = (~c.done) & (c.n_steps >= st.max_steps) & (jnp.abs(t_end - c.t) >= eps_t)
    return c._replace(
        status=jnp.where(hit_max, STATUS_MAX_STEPS, c.status).astype(jnp.int32),
        done=c.done | hit_max,
    )


def state_of(c: Carry):
    """(r, v, m) of a carry as one 7-vector."""
    return jnp.concatenate([c.rc + c.delta, c.vc + c.nu, c.m[None]])


def restart_from_state(model, params, c: Carry, x) -> Carry:
    """Carry whose deviations reproduce state ``x`` on the carry's conic (continuation with a
    differentiable entry point: delta = r - r_con(tau; mu), so derivatives of the next segment
    with respect to x and to mu are exact while the primal equals the continued propagation).

    At a conic epoch (tau = 0, e.g. the start) the conic itself is rebuilt from ``x``, so the
    derivative is that of exactly the map a finite-difference run computes."""
    if model.integrator.formulation == "cowell":  # no conic: the carry holds the state itself
        z3 = jnp.zeros(3)
        return c._replace(rc=x[:3], vc=x[3:6], delta=z3, nu=z3, m=x[6], t_rect=c.t, r0=x[:3], v0=x[3:6])
    mu = params.mu[c.primary]
    tau = c.t - c.t_rect
    cs = kepler_fg(c.r0, c.v0, tau, mu)
    at_epoch = tau == 0.0
    r, v = x[:3], x[3:6]
    rc = jnp.where(at_epoch, r, cs.r)
    vc = jnp.where(at_epoch, v, cs.v)
    return c._replace(
        r0=jnp.where(at_epoch, r, c.r0),
        v0=jnp.where(at_epoch, v, c.v0),
        rc=rc,
        vc=vc,
        delta=jnp.where(at_epoch, jnp.zeros(3), r - rc),
        nu=jnp.where(at_epoch, jnp.zeros(3), v - vc),
        m=x[6],
    )
