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

Here: the Nystrom step and the loop (:func:`advance`).  The body states, step controls and
accelerations live in :mod:`fracas.integrate.accelerations`, the event functions in
:mod:`fracas.integrate.events`, the carry and its restarts (rectification, impulses, changes of
primary, :func:`init_carry`) in :mod:`fracas.integrate.carry`; their names are re-exported here.
"""

from __future__ import annotations

import functools
from typing import TYPE_CHECKING, NamedTuple

import jax
import jax.numpy as jnp

from fracas import _jax  # noqa: F401
from fracas.dynamics import forces, propulsion
from fracas.dynamics.kepler import kepler_fg, predict_universal_anomaly
from fracas.dynamics.model import STOP_TIME, ForceModel, Params
from fracas.integrate import highorder
from fracas.integrate.accelerations import (
    StepControls,
    acting_third_bodies,
    arc_law,
    body_states,
    perturbation,
    steered_angles,
    step_controls,
    total_acceleration,
)
from fracas.integrate.carry import (
    Carry,
    _apply_impulses,
    _break_candidates,
    _initial_step,
    _rectify,
    _switch_primary,
    init_carry,
    state_of,
)
from fracas.integrate.events import _INACTIVE, _n_events, event_functions, yaw_event_function, yaw_event_index
from fracas.status import RunStatus

if TYPE_CHECKING:
    from jax.typing import ArrayLike

    from fracas.dynamics.ephemeris import EphemerisTable

__all__ = [
    "STATUS_OK",
    "STATUS_STOPPED",
    "STATUS_MAX_STEPS",
    "STATUS_NONFINITE",
    "Carry",
    "StepControls",
    "acting_third_bodies",
    "arc_law",
    "body_states",
    "event_functions",
    "perturbation",
    "step_controls",
    "steered_angles",
    "total_acceleration",
    "init_carry",
    "advance",
    "state_of",
    "restart_from_state",
    "saltation_matrix",
]
# private names that callers and benchmarks read through this module
_REEXPORTED = (_INACTIVE, _n_events, _initial_step)

STATUS_OK = int(RunStatus.OK)  # reached the final time
STATUS_STOPPED = int(RunStatus.STOPPED)  # the stop condition was met (located)
STATUS_MAX_STEPS = int(RunStatus.MAX_STEPS)  # max_steps reached
STATUS_NONFINITE = int(RunStatus.NONFINITE)  # the state became NaN/inf


def _held(model: ForceModel, ctl: StepControls, c: Carry) -> StepControls:
    """``ctl`` with the carry's held yaw sign (``ForceModel.yaw_switch``; unchanged otherwise)."""
    return ctl._replace(yaw_sign=c.yaw_sign) if model.yaw_switch else ctl


_encke_accel = forces.encke_deviation_accel  # Doc. 4 eq. 4.1-3 (kept under its old name)


# ------------------------------------------------------------------------ the step
_N_NEWTON = 2  # Newton steps after the predictor: (n dt/2)^4/24 ~ 2e-5 -> 4e-10 -> 2e-19


_predict_x = predict_universal_anomaly  # third-order Taylor prediction (kepler module)


def _nystrom_step(
    model: ForceModel,
    params: Params,
    ephem: EphemerisTable | None,
    epoch_et: ArrayLike,
    c: Carry,
    dt: jax.Array,
    ctl: StepControls,
) -> tuple[tuple[jax.Array, ...], tuple[jax.Array, jax.Array]]:
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


class _Segment(NamedTuple):
    """What one call of :func:`advance` fixes for its whole loop (static settings and the
    traced values the loop body closes over)."""

    model: ForceModel
    params: Params
    ephem: EphemerisTable | None
    epoch_et: ArrayLike
    t_end: jax.Array  # s, end of the segment
    radius_sign: ArrayLike  # side of a 'radius' stop the propagation started on
    var_labels: tuple[str, ...] | None  # explicit variational equations' parameter labels
    direction: jax.Array  # +1 forward, -1 backward
    breaks: jax.Array  # times a step must end at (thrust switches, impulses)
    faithful: bool  # FRACAS's own step: rkn4 on Encke deviations
    expo: float | None  # 1/(q+1) of the step-size controller (tolerance control only)


def _rectify_if_encke(seg: _Segment, c: Carry) -> Carry:
    # a Cowell carry has no deviations to rectify (impulses and primary changes still
    # restart it through _rectify(force=True), which only moves the velocity into vc)
    st = seg.model.integrator
    return c if st.formulation == "cowell" else _rectify(c, st.rect_ratio)


def _normal_step(seg: _Segment, c: Carry) -> jax.Array:
    """The step (s, signed) of a normal (not event-locating) iteration: the controller's
    proposal or the c_nom rule, cut at the next break and at dt_max (FRACAS DETECT)."""
    st = seg.model.integrator
    params = seg.params
    eps_t = st.eps_t_s
    p = c.primary
    if st.adaptive:
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
    ahead = (seg.breaks - c.t) * seg.direction > eps_t
    # (t_end is appended so the min is never over an empty set: no inf tangents)
    t_brk = jnp.concatenate([jnp.where(ahead, seg.breaks, seg.t_end), seg.t_end[None]])
    span = jnp.min(jnp.abs(t_brk - c.t))
    return seg.direction * jnp.minimum(jnp.minimum(span, dt_nom), st.dt_max_s)


def _take_step(seg: _Segment, c: Carry, dt: jax.Array) -> tuple[Carry, tuple[jax.Array, jax.Array], jax.Array]:
    """(state after the step and its impulses, body states at its end, error ratio)."""
    model, params = seg.model, seg.params
    st = model.integrator
    ctl = _held(model, step_controls(model, params, c.t + 0.5 * dt), c)
    if seg.faithful:
        (t1, rc1, vc1, d1, n1, m1), body4 = _nystrom_step(model, params, seg.ephem, seg.epoch_et, c, dt, ctl)
        err = jnp.zeros(())
    else:
        out, body4, err = highorder.step(
            model,
            params,
            seg.ephem,
            seg.epoch_et,
            c,
            dt,
            ctl,
            st.tolerance,
            perturbation=perturbation,
            body_states=body_states,
            step_controls=step_controls,
            var_labels=seg.var_labels,
        )
        t1, rc1, vc1, d1, n1, m1 = out[:6]
        if seg.var_labels is not None:
            c = c._replace(phi=out[6])
    new = c._replace(t=t1, rc=rc1, vc=vc1, delta=d1, nu=n1, m=m1, n_steps=c.n_steps + 1)
    return _apply_impulses(model, params, new, c.t, seg.direction, st.eps_t_s), body4, err


def _control(
    seg: _Segment, c: Carry, new: Carry, dt: jax.Array, err: jax.Array, force_accept: jax.Array
) -> tuple[Carry, jax.Array]:
    """Accept or reject the trial step ``new`` (tolerance control); returns (carry, accepted).

    Accepted when err <= 1 (or ``force_accept``: Newton steps of an event location, whose
    sizes are bounded by the last accepted step); h_next = |dt| clip(0.9 err^(-1/(q+1)),
    0.2, 5), not shrunk below the previous proposal after a step that a break cut short.
    A rejected step leaves the state as it was.  A step size below eps_t (the controller
    cannot meet the tolerance: a collision, a singularity) ends the run as non-finite.
    """
    if not seg.model.integrator.adaptive:
        return new, jnp.asarray(True)
    ok = (err <= 1.0) | force_accept
    fac = jnp.clip(0.9 * jnp.where(err > 0, err, 1e-300) ** (-seg.expo), 0.2, 5.0)
    h_prop = jax.lax.stop_gradient(jnp.abs(dt) * fac)
    cut_short = jnp.abs(dt) < c.h_next * (1.0 - 1e-12)
    h_prop = jnp.where(ok & cut_short, jnp.maximum(h_prop, c.h_next), h_prop)
    h_prop = jnp.where(force_accept, c.h_next, h_prop)
    new = new._replace(h_next=h_prop)
    rej = c._replace(h_next=h_prop, n_steps=c.n_steps + 1, n_reject=c.n_reject + 1)
    collapsed = (~ok) & (h_prop < seg.model.integrator.eps_t_s)
    rej = rej._replace(done=collapsed, status=jnp.where(collapsed, STATUS_NONFINITE, rej.status).astype(jnp.int32))
    out = jax.tree_util.tree_map(lambda a, b: jnp.where(ok, a, b), new, rej)
    return out, ok


def _check_finite(c: Carry, new: Carry, stop_now: jax.Array) -> Carry:
    """``new`` marked done (non-finite, or stopped when ``stop_now``) with its status."""
    finite = jnp.all(jnp.isfinite(new.delta)) & jnp.all(jnp.isfinite(new.nu)) & jnp.isfinite(new.m)
    finite = finite & jnp.all(jnp.isfinite(new.rc)) & jnp.all(jnp.isfinite(new.vc))
    status = jnp.where(stop_now, STATUS_STOPPED, jnp.where(finite, new.status, STATUS_NONFINITE))
    return new._replace(done=new.done | stop_now | (~finite), status=status.astype(jnp.int32))


def _body_plain(seg: _Segment, c: Carry) -> Carry:
    """Final-time stop only, no primary changes: no event functions are evaluated."""
    c = _rectify_if_encke(seg, c)
    dt = _normal_step(seg, c)
    new, _, err = _take_step(seg, c, dt)
    new, _ = _control(seg, c, new, dt, err, jnp.asarray(False))
    return _check_finite(c, new, jnp.asarray(False))


def _newton_dt(seg: _Segment, p: jax.Array, k_ev: jax.Array, c: Carry) -> jax.Array:
    """Newton step dt = -g/gdot on event ``k_ev``, gdot = dg/dt along the motion (a JVP)."""
    model, params, ephem, epoch_et = seg.model, seg.params, seg.ephem, seg.epoch_et
    r = c.rc + c.delta
    v = c.vc + c.nu
    pos, _ = body_states(model, params, ephem, epoch_et + c.t)
    ctl0 = _held(model, step_controls(model, params, c.t), c)

    def g_of(tt, rr, vv):
        ps, vs = body_states(model, params, ephem, epoch_et + tt)
        return event_functions(model, params, rr, vv, p, ps, vs, seg.radius_sign, c.yaw_sign)[k_ev]

    acc = total_acceleration(model, params, c.t, r, v, c.m, p, pos, ctl0)
    g_val, g_dot = jax.jvp(g_of, (c.t, r, v), (jnp.ones(()), v, acc))
    return -g_val / jnp.where(g_dot == 0.0, 1e-30, g_dot)


def _event_step_size(
    seg: _Segment, c: Carry, p: jax.Array, dt_normal: jax.Array
) -> tuple[jax.Array, jax.Array, jax.Array]:
    """(dt, locating, located): the Newton step on the event being located, bounded by the
    last normal step and the segment end, or ``dt_normal``; located when the Newton step is
    below eps_t (then dt = 0)."""
    eps_t = seg.model.integrator.eps_t_s
    # Newton step on the event being located: dt = -g/gdot, gdot = dg/dt along the motion.
    # Only while locating (lax.cond: a normal step pays nothing for it; the cheap test is
    # the sign change of the event functions at the end of an accepted step, below)
    locating = c.locating >= 0
    k_ev = jnp.maximum(c.locating, 0)
    dt_newton = jax.lax.cond(locating, lambda c: _newton_dt(seg, p, k_ev, c), lambda c: jnp.zeros_like(c.t), c)
    lim = jnp.abs(c.dt_norm)
    dt_newton = jnp.clip(dt_newton, -lim, lim)
    # never step past the segment end while locating
    dt_newton = jnp.where(seg.direction * (c.t + dt_newton - seg.t_end) > 0.0, seg.t_end - c.t, dt_newton)
    located = locating & (jnp.abs(dt_newton) < eps_t)
    dt = jnp.where(locating, dt_newton, dt_normal)
    dt = jnp.where(located, 0.0, dt)
    return dt, locating, located


def _note_crossings(
    seg: _Segment,
    c: Carry,
    new: Carry,
    p: jax.Array,
    body4: tuple[jax.Array, jax.Array],
    accepted: jax.Array,
    locating: jax.Array,
) -> Carry:
    """``new`` with the event functions at its end; a crossing in this (normal, accepted)
    step starts the location of the earliest event."""
    pos4, vel4 = body4
    r1 = new.rc + new.delta
    v1 = new.vc + new.nu
    g_new = event_functions(seg.model, seg.params, r1, v1, p, pos4, vel4, seg.radius_sign, c.yaw_sign)
    g_new = jnp.where(accepted, g_new, c.g_prev)
    # a crossing in this (normal, accepted) step starts the location of the earliest event
    crossed = (c.g_prev > 0.0) & (g_new <= 0.0) & (~locating) & accepted
    frac = c.g_prev / jnp.where(crossed, c.g_prev - g_new, 1.0)
    frac = jnp.where(crossed, frac, jnp.inf)
    first = jnp.argmin(frac).astype(jnp.int32)
    any_cross = jnp.any(crossed)
    return new._replace(g_prev=g_new, locating=jnp.where(any_cross, first, c.locating))


def _switch_at_event(seg: _Segment, p: jax.Array, c: Carry, new: Carry) -> Carry:
    """The carry re-centred on the body whose sphere of influence the located event
    ``c.locating - 1`` enters (or on the primary's parent when it leaves the primary's)."""
    model, params = seg.model, seg.params
    pos, vel = body_states(model, params, seg.ephem, seg.epoch_et + c.t)
    b = c.locating - 1
    is_exit = b == p
    parent = params.parent[jnp.maximum(b, 0)].astype(jnp.int32)
    new_p = jnp.where(is_exit, parent, b)
    switched = _switch_primary(model, params, c, new_p, pos, vel)
    if model.yaw_switch:  # cos u about the new primary
        switched = switched._replace(yaw_sign=propulsion.yaw_sign_of(switched.rc, switched.vc))
    g_sw = event_functions(
        model, params, switched.rc, switched.vc, switched.primary, pos, vel, seg.radius_sign, switched.yaw_sign
    )
    return switched._replace(g_prev=g_sw, locating=jnp.asarray(-1, jnp.int32))


def _flip_yaw(seg: _Segment, c: Carry, k_yaw: int) -> Carry:
    """The carry at a located yaw flip: the held sign reversed, the flip counted, its event
    function restarted on the new side, and (explicit variational equations) the STM and
    parameter matrix multiplied by the saltation matrix :func:`_saltation`."""
    r, v = c.rc + c.delta, c.vc + c.nu
    new_sign = -c.yaw_sign
    if seg.var_labels is not None:
        c = c._replace(phi=_saltation(seg, c, new_sign) @ c.phi)
    g = c.g_prev.at[k_yaw].set(yaw_event_function(r, v, new_sign))
    return c._replace(
        yaw_sign=new_sign, n_flips=c.n_flips + 1, t_flip=c.t, g_prev=g, locating=jnp.asarray(-1, jnp.int32)
    )


def _saltation(seg: _Segment, c: Carry, new_sign: jax.Array) -> jax.Array:
    """:func:`saltation_matrix` at the carry's state (a located flip to ``new_sign``)."""
    x = jnp.concatenate([c.rc + c.delta, c.vc + c.nu, c.m[None]])
    return saltation_matrix(seg.model, seg.params, seg.ephem, seg.epoch_et, c.t, x, c.primary, -new_sign)


def saltation_matrix(
    model: ForceModel,
    params: Params,
    ephem: EphemerisTable | None,
    epoch_et: ArrayLike,
    t: ArrayLike,
    x: jax.Array,
    primary: ArrayLike,
    old_sign: ArrayLike,
) -> jax.Array:
    """The saltation matrix (7, 7) of a yaw flip at state x = (r km, v km/s, m kg) (t s from
    the epoch, about body index ``primary``), from the held sign ``old_sign`` to its opposite:

        S = I + (f+ - f-) g_x^T / (g_x . f-)

    f-, f+ = xdot with the old and the new sign of the out-of-plane thrust, g the flip's event
    function (:func:`fracas.integrate.events.yaw_event_function`; no explicit time
    dependence).  A perturbation dx moves the flip by dt = -g_x . dx / (g_x . f-), and over
    dt the state follows f- instead of f+; so Phi(t+) = S Phi(t-), and every column of the
    parameter matrix alike (the flip's surface does not depend on the parameters)
    (Aizerman & Gantmacher, Q. J. Mech. Appl. Math. 11, 1958; Mueller, Chaos Solitons
    Fractals 5, 1995).  Zero jump (S = I) when no switching arc is on."""
    r, v, m = x[:3], x[3:6], x[6]
    pos, _ = body_states(model, params, ephem, epoch_et + t)
    ctl = step_controls(model, params, t)

    def xdot(sign):
        cc = ctl._replace(yaw_sign=sign)
        a_free, force, mdot = perturbation(model, params, t, r, v, primary, pos, cc)
        acc = forces.point_mass_accel(r, params.mu[primary]) + a_free + force / m
        return jnp.concatenate([v, acc, jnp.reshape(mdot, (1,))])

    old_sign = jnp.asarray(old_sign, jnp.float64)
    f_minus, f_plus = xdot(old_sign), xdot(-old_sign)
    g_r, g_v = jax.grad(lambda rr, vv: yaw_event_function(rr, vv, old_sign), argnums=(0, 1))(r, v)
    g_x = jnp.concatenate([g_r, g_v, jnp.zeros(1)])
    g_dot = jnp.sum(g_x * f_minus)
    g_dot = jnp.where(g_dot == 0.0, 1e-300, g_dot)
    return jnp.eye(7) + (f_plus - f_minus)[:, None] * (g_x / g_dot)[None, :]


def _body_events(seg: _Segment, c: Carry) -> Carry:
    """One iteration with events: a normal step, or a Newton step of an event location;
    a located event stops the run (event 0) or changes the primary (event 1 + b)."""
    c = _rectify_if_encke(seg, c)
    p = c.primary
    dt_normal = _normal_step(seg, c)
    dt, locating, located = _event_step_size(seg, c, p, dt_normal)
    new, body4, err = _take_step(seg, c, dt)
    new = new._replace(dt_norm=jnp.where(locating, c.dt_norm, dt))
    new, accepted = _control(seg, c, new, dt, err, locating)
    new = _note_crossings(seg, c, new, p, body4, accepted, locating)
    # event located: stop (event 0) or change primary (event 1 + b)
    stop_now = located & (c.locating == 0)
    new = jax.tree_util.tree_map(lambda a, b: jnp.where(located, a, b), c, new)
    new = new._replace(n_steps=c.n_steps + 1, n_reject=jnp.where(located, c.n_reject, new.n_reject))
    k_yaw = yaw_event_index(seg.model)
    if seg.model.change_primary_at_soi:
        do_switch = located & (c.locating > 0) & (c.locating != k_yaw)
        new = jax.lax.cond(do_switch, lambda c, new: _switch_at_event(seg, p, c, new), lambda c, new: new, c, new)
    if seg.model.yaw_switch:
        do_flip = located & (c.locating == k_yaw)
        new = jax.lax.cond(do_flip, lambda new: _flip_yaw(seg, new, k_yaw), lambda new: new, new)
    new = _check_finite(c, new, stop_now)
    return new._replace(locating=jnp.where(stop_now, -1, new.locating))


def advance(
    model: ForceModel,
    params: Params,
    ephem: EphemerisTable | None,
    epoch_et: ArrayLike,
    c: Carry,
    t_end: ArrayLike,
    radius_sign: ArrayLike,
    var_labels: tuple[str, ...] | None = None,
) -> Carry:
    """Integrate from c.t to t_end (either direction), stopping early at the stop condition.

    ``var_labels`` (static tuple of parameter labels): also integrate the explicit variational
    equations into ``c.phi`` (7, 7 + np) (``highorder.variational_supported`` models only)."""
    st = model.integrator
    eps_t = st.eps_t_s
    t_end = jnp.asarray(t_end, jnp.float64)
    direction = jnp.where(t_end >= c.t, 1.0, -1.0)
    breaks = _break_candidates(params)

    def cond(c: Carry) -> jax.Array:
        arrived = (jnp.abs(t_end - c.t) < eps_t) & (c.locating < 0)
        return (~c.done) & (~arrived) & (c.n_steps < st.max_steps)

    has_events = model.stop.kind != STOP_TIME or model.change_primary_at_soi or model.yaw_switch

    faithful = st.method == "rkn4" and st.formulation == "encke"
    if var_labels is not None and not highorder.variational_supported(model, var_labels):
        raise ValueError("explicit variational equations: Cowell, no impulses, events or break-time parameters")
    expo = highorder.control_exponent(st.method) if st.adaptive else None
    seg = _Segment(model, params, ephem, epoch_et, t_end, radius_sign, var_labels, direction, breaks, faithful, expo)

    body = functools.partial(_body_events if has_events else _body_plain, seg)
    c = jax.lax.while_loop(cond, body, c)
    hit_max = (~c.done) & (c.n_steps >= st.max_steps) & (jnp.abs(t_end - c.t) >= eps_t)
    return c._replace(
        status=jnp.where(hit_max, STATUS_MAX_STEPS, c.status).astype(jnp.int32),
        done=c.done | hit_max,
    )


def restart_from_state(model: ForceModel, params: Params, c: Carry, x: jax.Array) -> Carry:
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
