"""High-order steps of the propagation loop: embedded Runge-Kutta(-Nystrom) tableaux in the
Cowell and the Encke formulation, with the step's local error measured for step control.

``encke.advance`` calls :func:`step` for every method other than FRACAS's own Encke/RKN4
step (``encke._nystrom_step``, kept as the faithful option).  The loop around it -- breaks at
thrust switches, impulses and output times, event location, change of primary, mass,
status codes -- is the same for every method; only the step and the step-size rule differ.

Formulations (``IntegratorSettings.formulation``):

* ``cowell``: the state (r, v) itself is integrated, r'' = -mu r/|r|^3 + a_d(t, r, v, m).
  The carry holds it in ``rc``, ``vc`` with zero deviations, so the rest of the loop (state
  extraction, impulses, primary changes) is unchanged; a Cowell carry never rectifies.
* ``encke``: the deviations (delta, nu) from the osculating conic are integrated with
  Doc. 4 eq. 4.1-3 (Potter's f(q)), the conic being evaluated at every distinct stage time
  t + c_i h by one Kepler solve vectorised over the nodes (from the step's starting conic
  point, warm-started by a third-order prediction and finished by Newton steps).

Methods (``IntegratorSettings.method``; tableaux and sources in :mod:`fracas.integrate.tableaux`):

* ``dprkn12`` -- Dormand, El-Mikkawy & Prince (1987) RKN 12(10), 17 stages;
* ``dprkn8`` -- Dormand & Prince RKN 8(6), 9 stages;
* ``rkn4`` -- the classical 4th-order Nystrom method (no embedded pair: c_nom rule only);
* ``dop853`` -- Hairer's DOP853 (8(5,3), 12 stages plus the error stage at the new point), a
  first-order method, for accelerations that depend on velocity or mass (thrust).

The special RKN methods assume y'' = f(t, y): with thrust the acceleration depends on the
mass, which is itself integrated (m' = mdot(t, r)), i.e. on a first-order variable; such
models are refused by the configuration and served by ``dop853``.

Error norm.  ``err = max(|e_r| / |r|, |e_v| / |v|, |e_m| / m) / tol``: the embedded estimates
of the step's position, velocity and mass errors, each relative to the magnitude of the
state block (for Encke: of the full r = r_con + delta, not of the deviation), so ``tol`` is
a relative local error per step, independent of units and of the central body.  A step is
accepted when err <= 1.  DOP853's two estimates are combined as in Hairer's dop853.f.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from fracas import _jax  # noqa: F401
from fracas.dynamics import forces
from fracas.dynamics.kepler import kepler_fg, predict_universal_anomaly
from fracas.integrate import stages as _stages
from fracas.integrate.tableaux import DOP853, DPRKN8, DPRKN12, RKN4, RungeKuttaTableau

__all__ = [
    "variational_supported",
    "METHODS",
    "FORMULATIONS",
    "tableau_of",
    "embedded",
    "control_exponent",
    "stages_per_step",
    "step",
]

FORMULATIONS = ("encke", "cowell")
METHODS = {"rkn4": RKN4, "dprkn8": DPRKN8, "dprkn12": DPRKN12, "dop853": DOP853}
# Newton steps of the stage Kepler solves, from a third-order prediction over up to one step:
# at 1.5 rad of mean motion (the longest LEO steps at tol 1e-8) the prediction is ~0.2 off in
# x and Newton's quadratic convergence reaches rounding in 5-6 steps; 8 leave a margin.
_N_NEWTON = 8


def tableau_of(method: str):
    return METHODS[method]


def embedded(method: str) -> bool:
    """Whether the method has an embedded error estimate (tolerance step control)."""
    tab = METHODS[method]
    return isinstance(tab, RungeKuttaTableau) or tab.bbar_low is not None


def control_exponent(method: str) -> float:
    """1/(q+1) of the step-size controller h_new = h * 0.9 err^(-1/(q+1))."""
    tab = METHODS[method]
    if isinstance(tab, RungeKuttaTableau):
        return 1.0 / tab.order  # dop853.f: the combined estimate behaves as h^8
    return 1.0 / ((tab.embedded_order or tab.order) + 1)


def stages_per_step(method: str) -> int:
    """Acceleration evaluations per step (distinct stages; DOP853 counts its error stage)."""
    return _stages.plan_of_tableau(METHODS[method]).stages


# --------------------------------------------------------------------- stage geometry
class _Nodes:
    """What a step's stages need besides their own state, prepared once per step at the
    plan's distinct nodes t + c h (``stages.StagePlan.nodes``, 1.0 included): body positions
    and velocities (one vectorised ephemeris evaluation), and for Encke the conic states (one
    Kepler solve vectorised over the nodes, from the step's starting conic point: a
    third-order prediction of the universal anomaly, then ``_N_NEWTON`` Newton steps).
    Stage i reads row ``plan.node[i]`` (a dynamic index: the stage function is traced once)."""

    def __init__(self, model, params, ephem, epoch_et, c, h, plan, body_states):
        self.model, self.params, self.ephem, self.epoch_et = model, params, ephem, epoch_et
        self.c, self.h, self.body_states = c, h, body_states
        # without primary changes the primary is the model's (static): plain slices, no gathers
        self.primary = c.primary if model.change_primary_at_soi else model.primary
        self.mu = params.mu[self.primary]
        self.encke = model.integrator.formulation == "encke"
        nodes = jnp.asarray(plan.nodes)
        self.node = jnp.asarray(plan.node)
        self.c_stage = jnp.asarray(plan.c)
        self.plan = plan
        self.t_nodes = c.t + nodes * h
        self.pos, self.vel = jax.vmap(lambda tt: body_states(model, params, ephem, epoch_et + tt))(self.t_nodes)
        if self.encke:
            rc, vc, mu = c.rc, c.vc, self.mu
            sqrt_mu = jnp.sqrt(mu)

            def solve(tau):
                xs = predict_universal_anomaly(0.0, rc, vc, mu, sqrt_mu, tau)
                cs = kepler_fg(rc, vc, tau, mu, xs, n_newton=_N_NEWTON, short_arc=True)
                return cs.r, cs.v

            rs, vs = jax.vmap(solve)(nodes * h)
            at0 = (nodes == 0.0)[:, None]
            self.rc_nodes = jnp.where(at0, rc, rs)
            self.vc_nodes = jnp.where(at0, vc, vs)

    def node_of(self, i):
        """Row of stage i in the node arrays (a Python int for an unrolled stage)."""
        return int(self.plan.node[i]) if isinstance(i, int) else self.node[i]

    def t_of(self, i):
        ci = float(self.plan.c[i]) if isinstance(i, int) else self.c_stage[i]
        return self.c.t + ci * self.h

    def bodies_end(self):
        """(positions, velocities) of the bodies at t + h (node 1.0, the last)."""
        return self.pos[-1], self.vel[-1]

    def conic_end(self):
        return self.rc_nodes[-1], self.vc_nodes[-1]


def _accel(nd: _Nodes, i, q, p, m, ctl, perturbation, params=None, pos=None):
    """(q'', mdot) at stage i for stage state (q, p, m) of the formulation."""
    model = nd.model
    params = nd.params if params is None else params
    t = nd.t_of(i)
    ni = nd.node_of(i)
    pos = nd.pos[ni] if pos is None else pos
    if nd.encke:
        rc = nd.rc_nodes[ni]
        r, v = rc + q, nd.vc_nodes[ni] + p
    else:
        r, v = q, p
    fused_j2 = model.j2 and not nd.encke
    a_free, force, mdot = perturbation(model, params, t, r, v, nd.primary, pos, ctl, with_j2=not fused_j2)
    has_force = model.srp or model.thrust  # else force is zero: skip force/m
    mu = params.mu[nd.primary]
    if nd.encke:
        acc = forces.encke_deviation_accel(mu, rc, q, a_free, force if has_force else 0.0, m)
    else:
        if fused_j2:
            b = nd.primary
            acc = forces.central_j2_accel(r, mu, params.j2[b], params.radius[b], params.pole[b]) + a_free
        else:
            acc = forces.point_mass_accel(r, mu) + a_free
        if has_force:
            acc = acc + force / m
    return acc, mdot


def _error_ratio(e_r, e_v, e_m, r1, v1, m1, tol):
    """max(|e_r|/|r|, |e_v|/|v|, |e_m|/m) / tol (module docstring); inf when not finite."""
    # ratios of squares, one square root: no float64 rsqrt (perf-notes)
    err = jnp.sqrt(
        jnp.maximum(forces.dot3(e_r, e_r) / forces.dot3(r1, r1), forces.dot3(e_v, e_v) / forces.dot3(v1, v1))
    )
    if e_m is not None:
        err = jnp.maximum(err, jnp.abs(e_m) / jnp.abs(m1))
    err = err / tol
    return jnp.where(jnp.isfinite(err), err, jnp.inf)


def _dop853_error(e5, e3, r1, v1, m1, tol):
    """dop853.f: err = err5^2 / sqrt(err5^2 + 0.01 err3^2), per scaled component."""
    s5 = _error_ratio(e5[0], e5[1], e5[2], r1, v1, m1, 1.0)
    s3 = _error_ratio(e3[0], e3[1], e3[2], r1, v1, m1, 1.0)
    den = jnp.sqrt(s5 * s5 + 0.01 * s3 * s3)
    err = jnp.where(den > 0, s5 * s5 / jnp.where(den > 0, den, 1.0), 0.0) / tol
    return jnp.where(jnp.isfinite(err), err, jnp.inf)


def step(
    model, params, ephem, epoch_et, c, dt, ctl, tol, *, perturbation, body_states, step_controls=None, var_labels=None
):
    """One step of size dt with the model's (method, formulation).

    Returns ((t + dt, rc, vc, delta, nu, m), (body positions, velocities) at t + dt, err)
    with err the error ratio of the module docstring (0 for a method without an embedded
    pair).  ``perturbation`` and ``body_states`` are the loop's force-model functions
    (``encke.perturbation``, ``encke.body_states``, ``encke.step_controls``: the last only
    needed by DOP853's variational equations), passed in to keep this module below the loop
    in the import order.  The stages run as data (:mod:`fracas.integrate.stages`):
    the force model is traced once per step program, whatever the method.

    ``var_labels`` (a tuple of parameter labels, or None): also advance ``c.phi`` (7, 7 + np),
    the sensitivities of (r, v, m) to the state at the start of the segment and to the
    labelled parameters, by the explicit variational equations with the same stages
    (:func:`_variational_rkn`, :func:`_variational_rk`); returned as a seventh element of the
    state tuple.
    """
    st = model.integrator
    plan = _stages.plan_of_tableau(METHODS[st.method])
    unroll = st.stage_loop == "unrolled"
    nd = _Nodes(model, params, ephem, epoch_et, c, dt, plan, body_states)
    if var_labels is not None:
        if plan.first_order:
            return _variational_rk(model, params, nd, plan, c, dt, ctl, tol, perturbation, step_controls, var_labels)
        return _variational_rkn(model, params, nd, plan, c, dt, ctl, tol, perturbation, var_labels)
    if nd.encke:
        q, p = c.delta, c.nu
    else:
        q, p = c.rc + c.delta, c.vc + c.nu
    m = c.m
    h = dt
    if not plan.first_order:
        # velocity at the stage: only used by velocity-dependent forces, which the special
        # RKN methods exclude (the configuration refuses them); p is a placeholder.  The mass
        # is constant (no thrust with these methods).
        ks = _stages.nystrom_stages(
            lambda i, qi: _accel(nd, i, qi, p, m, ctl, perturbation)[0], q, p, h, plan, unroll=unroll
        )
        q1 = q + h * p + (h * h) * ks.weighted(plan.bbar)
        p1 = p + h * ks.weighted(plan.b)
        m1 = m
    else:
        varying_mass = model.thrust

        def stage(i, y):
            qi, pi, mi = y
            k, md = _accel(nd, i, qi, pi, mi if varying_mass else m, ctl, perturbation)
            return pi, k, (md if varying_mass else jnp.zeros(()))

        ks = _stages.rk_stages(stage, (q, p, m), h, plan, unroll=unroll)
        kq, kp, km = ks.part(0), ks.part(1), ks.part(2)
        q1 = q + h * kq.weighted(plan.b)
        p1 = p + h * kp.weighted(plan.b)
        m1 = m + h * km.weighted(plan.b) if varying_mass else m
    if nd.encke:
        rc1, vc1 = nd.conic_end()
        r1, v1 = rc1 + q1, vc1 + p1
        out = (c.t + dt, rc1, vc1, q1, p1, m1)
    else:
        r1, v1 = q1, p1
        z3 = jnp.zeros(3)
        out = (c.t + dt, q1, p1, z3, z3, m1)
    if not plan.first_order:
        if plan.e is None:
            err = jnp.zeros(())
        else:
            e_q = (h * h) * ks.weighted(plan.ebar)
            e_p = h * ks.weighted(plan.e)
            err = _error_ratio(e_q, e_p, None, r1, v1, m1, tol)
    else:
        e5 = [h * k.weighted(plan.e) for k in (kq, kp, km)]
        e3 = [h * k.weighted(plan.e_aux) for k in (kq, kp, km)]
        if not model.thrust:
            e5[2] = e3[2] = None
        err = _dop853_error(e5, e3, r1, v1, m1, tol)
    return out, nd.bodies_end(), err


# ------------------------------------------------------------- variational equations
_BREAK_FIELDS = ("arc_t_on", "arc_t_off", "impulse_t")


def variational_supported(model, labels=()) -> bool:
    """Whether :func:`step` can integrate explicit variational equations for this model and
    these parameter labels: Cowell, no impulses, no located events (stop conditions, primary
    changes), and no label that moves a step boundary (thrust switch or impulse times: the
    derivative through a break's step size is not a variational equation).  Any method: the
    special RKN ones (no thrust) and DOP853 (thrust, mass and switching arcs included).
    Elsewhere the forward-mode AD path (``propagate_with_sensitivities(method="ad")``) serves,
    and it is the cross-check here."""
    from fracas.params import parse_label

    st = model.integrator
    if any(parse_label(lab, model)[0] in _BREAK_FIELDS for lab in labels):
        return False
    return (
        st.formulation == "cowell"
        and model.n_impulses == 0
        and model.stop.kind == "time"
        and not model.change_primary_at_soi
    )


def _label_params(model, params, labels):
    """(p0, params_of): the labelled values and a function p -> Params with them replaced."""
    from fracas.dynamics.parameters import get_values, set_values

    if not labels:
        return jnp.zeros(0), lambda pp: params
    return get_values(params, labels, model), lambda pp: set_values(params, labels, pp, model)


def _stage_jacobians(model, params, nd, i, r, m, ctl, perturbation, labels):
    """Acceleration a (3,) at stage i and its derivatives: G = da/dr (3, 3), a_m = da/dm
    (3,) or None (no force), a_p = da/dp (3, np) or None.  The two-body part of G is analytic,
    mu/r^3 (3 r_hat r_hat^T - I) (the gravity gradient, FRACAS DERY's G), as is a_m =
    -force/m^2; the perturbations (J2, third bodies, SRP) are differentiated by forward-mode
    AD in r, and every parameter column by AD in the parameter."""
    t = nd.t_of(i)
    mu = nd.mu
    zero_v = jnp.zeros(3)
    pos = nd.pos[nd.node_of(i)]
    has_force = model.srp or model.thrust
    a, _ = _accel(nd, i, r, zero_v, m, ctl, perturbation)  # the state path's own value

    def pert(rr):
        a_free, force, _ = perturbation(model, params, t, rr, zero_v, nd.primary, pos, ctl)
        return a_free + force / m if has_force else a_free

    has_pert = model.j2 or bool(model.acting_third_bodies()) or has_force
    g = jax.jacfwd(pert)(r) if has_pert else jnp.zeros((3, 3))
    inv_rr = 1.0 / forces.dot3(r, r)
    inv_r = jnp.sqrt(inv_rr)
    k3 = mu * inv_rr * inv_r
    # 3 mu r r^T / r^5 - mu / r^3 I, as broadcasts (no batched dot_general under vmap)
    g = g + (3.0 * k3 * inv_rr) * (r[:, None] * r[None, :]) - k3 * jnp.eye(3)
    a_m = None
    if has_force:
        _, force, _ = perturbation(model, params, t, r, zero_v, nd.primary, pos, ctl)
        a_m = -force / (m * m)
    a_p = None
    if labels:
        p0, params_of = _label_params(model, params, labels)

        def acc_p(pp):
            prm = params_of(pp)
            # the DE421 table does not depend on parameters; fixed-conic bodies do
            pos_p = nd.body_states(model, prm, nd.ephem, nd.epoch_et + t)[0] if model.conic_bodies else pos
            a_free, force, _ = perturbation(model, prm, t, r, zero_v, nd.primary, pos_p, ctl)
            return forces.point_mass_accel(r, prm.mu[nd.primary]) + a_free + force / m

        a_p = jnp.reshape(jax.jacfwd(acc_p)(p0), (3, len(labels)))
    return a, g, a_m, a_p


def _matmul3(g, q):
    """g (3, 3) @ q (3, n) as three broadcast products (a batched dot_general under vmap runs
    as a separate, unvectorised kernel on XLA CPU)."""
    return g[:, 0:1] * q[0:1, :] + g[:, 1:2] * q[1:2, :] + g[:, 2:3] * q[2:3, :]


def _variational_rkn(model, params, nd, plan, c, dt, ctl, tol, perturbation, labels):
    """A special-RKN Cowell step of the state and of Phi = d(r, v, m)/d(x_start, p) (7, 7 + np):

        Q'' = G(t, r) Q + a_m M + a_p S,   Q = Phi[0:3], Q' = Phi[3:6], M = Phi[6] (constant)

    (S selects the parameter columns), integrated with the state's own stages and weights, so
    Phi is the exact derivative of the discrete step map at fixed step sizes -- what the AD
    path computes, to rounding (FRACAS STMGEN integrates the variational equations alongside
    the state; tests/integrate/test_variational_stm.py)."""
    labels = tuple(labels)
    n_p = len(labels)
    h = dt
    unroll = model.integrator.stage_loop == "unrolled"
    r, v, m = c.rc + c.delta, c.vc + c.nu, c.m
    phi = c.phi
    # without a force (thrust, SRP) nothing depends on the mass: its column of d(r, v)/dx0 is
    # zero for good, so only the 6 state columns and the parameters are integrated (the 6x6
    # block, not the 7x7: issue 23) and the mass column is put back unchanged
    mass_col = model.srp or model.thrust
    n_x = 7 if mass_col else 6

    def cols(a):  # the integrated columns (static slices: no gather)
        return a if mass_col else jnp.concatenate([a[..., :6], a[..., 7:]], axis=-1)

    q_mat, p_mat, m_row = cols(phi[0:3]), cols(phi[3:6]), cols(phi[6])

    def stage(i, y):
        ri, qi = y
        a, g, a_m, a_p = _stage_jacobians(model, params, nd, i, ri, m, ctl, perturbation, labels)
        km = _matmul3(g, qi)
        if a_m is not None:
            km = km + a_m[:, None] * m_row[None, :]
        if n_p:
            km = km + jnp.concatenate([jnp.zeros((3, n_x)), a_p], axis=1)
        return a, km

    ks = _stages.nystrom_stages(stage, (r, q_mat), (v, p_mat), h, plan, unroll=unroll)
    (r1, q1) = jax.tree_util.tree_map(
        lambda x, y, k: x + h * y + (h * h) * k, (r, q_mat), (v, p_mat), ks.weighted(plan.bbar)
    )
    (v1, p1) = jax.tree_util.tree_map(lambda y, k: y + h * k, (v, p_mat), ks.weighted(plan.b))
    phi1 = jnp.concatenate([q1, p1, m_row[None, :]], axis=0)
    if not mass_col:
        phi1 = jnp.concatenate([phi1[:, :6], phi[:, 6:7], phi1[:, 6:]], axis=1)
    if plan.e is None:
        err = jnp.zeros(())
    else:
        e_q = (h * h) * ks.part(0).weighted(plan.ebar)
        e_p = h * ks.part(0).weighted(plan.e)
        err = _error_ratio(e_q, e_p, None, r1, v1, m, tol)
    z3 = jnp.zeros(3)
    return (c.t + dt, r1, v1, z3, z3, m, phi1), nd.bodies_end(), err


def _variational_rk(model, params, nd, plan, c, dt, ctl, tol, perturbation, step_controls, labels):
    """A first-order (DOP853) Cowell step of x = (r, v, m) and of Phi = dx/d(x_start, p)
    (7, 7 + np), thrust, mass and the arc controls included:

        Phi' = A(t, x) Phi + B(t, x) S,   A = df/dx (7, 7),  B = df/dp (7, np)

    integrated with the state's stages and weights.  Each stage's A Phi + B S is one
    forward-mode derivative of the stage function f(x, p) along the columns of (Phi, S)
    (``jax.jvp`` vectorised over the columns: the primal is evaluated once), with the thrust
    controls of the step recomputed from p, so a column of an arc's angle or throttle is
    exact.  Phi is the exact derivative of the discrete step map at fixed step sizes, as in
    :func:`_variational_rkn`."""
    labels = tuple(labels)
    n_p = len(labels)
    h = dt
    unroll = model.integrator.stage_loop == "unrolled"
    x = jnp.concatenate([c.rc + c.delta, c.vc + c.nu, c.m[None]])
    phi = c.phi
    p0, params_of = _label_params(model, params, labels)
    d_par = jnp.concatenate([jnp.zeros((n_p, 7)), jnp.eye(n_p)], axis=1)  # S: parameter tangents
    t_mid = c.t + 0.5 * dt
    varying_mass = model.thrust

    def f(i, xx, pp):
        prm = params_of(pp) if n_p else params
        cc = step_controls(model, prm, t_mid)._replace(yaw_sign=ctl.yaw_sign) if (model.thrust and n_p) else ctl
        pos = None
        if n_p and model.conic_bodies:  # the DE421 table does not depend on parameters
            pos = nd.body_states(model, prm, nd.ephem, nd.epoch_et + nd.t_of(i))[0]
        acc, md = _accel(nd, i, xx[:3], xx[3:6], xx[6], cc, perturbation, params=prm, pos=pos)
        md = md if varying_mass else jnp.zeros(())
        return jnp.concatenate([xx[3:6], acc, jnp.reshape(md, (1,))])

    def stage(i, y):
        xi, phii = y

        def col(dx, dp):
            return jax.jvp(lambda xx, pp: f(i, xx, pp), (xi, p0), (dx, dp))

        k, kphi = jax.vmap(col, in_axes=(1, 1), out_axes=(None, 1))(phii, d_par)
        return k, kphi

    ks = _stages.rk_stages(stage, (x, phi), h, plan, unroll=unroll)
    kx = ks.part(0)
    x1 = x + h * kx.weighted(plan.b)
    phi1 = phi + h * ks.part(1).weighted(plan.b)
    r1, v1, m1 = x1[:3], x1[3:6], x1[6]
    e5 = [h * kx.cols(s).weighted(plan.e) for s in (slice(0, 3), slice(3, 6))]
    e3 = [h * kx.cols(s).weighted(plan.e_aux) for s in (slice(0, 3), slice(3, 6))]
    e5.append(h * kx.cols(6).weighted(plan.e) if varying_mass else None)
    e3.append(h * kx.cols(6).weighted(plan.e_aux) if varying_mass else None)
    err = _dop853_error(e5, e3, r1, v1, m1, tol)
    z3 = jnp.zeros(3)
    return (c.t + dt, r1, v1, z3, z3, m1, phi1), nd.bodies_end(), err
