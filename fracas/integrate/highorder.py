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
from fracas.integrate import rkn as _rkn
from fracas.integrate.tableaux import DOP853, DPRKN8, DPRKN12, RKN4, NystromTableau, RungeKuttaTableau

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
    tab = METHODS[method]
    if isinstance(tab, RungeKuttaTableau):
        return tab.stages + 1
    return sum(1 for d in _duplicates(tab) if d is None)


# the tableau helpers of the pure kernels (fracas.integrate.rkn): one definition
_lincomb = _rkn._lincomb
_duplicates = _rkn._duplicate_stages


@jax.custom_batching.custom_vmap
def _materialise(k):
    """Keep a stage value as a value of its own (perf-notes: XLA CPU otherwise re-fuses the
    cheap part of every stage into each later stage).  The identity; under ``vmap`` it adds
    0 x (the sum over every lane, non-finite values mapped to 0), a reduction across the
    batch that the stage's consumers cannot fuse through, so the stage is computed once for
    all lanes and stored (measured 1.3-1.7x on DPRKN12 LEO batches)."""
    return k


@_materialise.def_vmap
def _materialise_vmap(axis_size, in_batched, k):
    (batched,) = in_batched
    if not batched:
        return k, False
    # nan_to_num: a lane that failed (NaN/inf) must not poison the others through the sum
    return k + 0.0 * jnp.nan_to_num(jnp.sum(k), nan=0.0, posinf=0.0, neginf=0.0), True


# --------------------------------------------------------------------- stage geometry
class _Frame:
    """What a stage needs besides its own state: time, body positions, conic (Encke)."""

    def __init__(self, model, params, ephem, epoch_et, c, h, body_states):
        self.model, self.params, self.ephem, self.epoch_et = model, params, ephem, epoch_et
        self.c, self.h = c, h
        self.body_states = body_states
        # without primary changes the primary is the model's (static): plain slices, no gathers
        self.primary = c.primary if model.change_primary_at_soi else model.primary
        self.mu = params.mu[self.primary]
        self._pos = {}
        self._conic = {0.0: (c.rc, c.vc)}
        self.encke = model.integrator.formulation == "encke"

    def bodies(self, ci: float):
        if ci not in self._pos:
            self._pos[ci] = self.body_states(
                self.model, self.params, self.ephem, self.epoch_et + self.c.t + ci * self.h
            )
        return self._pos[ci]

    def prepare_conics(self, nodes):
        """Conic states at t + c h for every node: one vectorised Kepler solve over the nodes
        from the step's starting conic point (a third-order prediction of the universal
        anomaly, then ``_N_NEWTON`` Newton steps: one compiled solve, not one per node)."""
        if not self.encke:
            return
        todo = sorted({float(x) for x in nodes} - {0.0})
        rc, vc, mu = self.c.rc, self.c.vc, self.mu
        sqrt_mu = jnp.sqrt(mu)

        def solve(tau):
            xs = predict_universal_anomaly(0.0, rc, vc, mu, sqrt_mu, tau)
            cs = kepler_fg(rc, vc, tau, mu, xs, n_newton=_N_NEWTON, short_arc=True)
            return cs.r, cs.v

        rs, vs = jax.vmap(solve)(jnp.asarray(todo) * self.h)
        for k, ci in enumerate(todo):
            self._conic[ci] = (rs[k], vs[k])

    def conic(self, ci: float):
        return self._conic[float(ci)]


def _accel(frame: _Frame, ci, q, p, m, ctl, perturbation):
    """(q'' , mdot) at stage node ci for stage state (q, p, m) of the formulation."""
    c = frame.c
    t = c.t + ci * frame.h
    pos, _ = frame.bodies(ci)
    if frame.encke:
        rc, vc = frame.conic(ci)
        r, v = rc + q, vc + p
    else:
        r, v = q, p
    fused_j2 = frame.model.j2 and not frame.encke
    a_free, force, mdot = perturbation(
        frame.model, frame.params, t, r, v, frame.primary, pos, ctl, with_j2=not fused_j2
    )
    has_force = frame.model.srp or frame.model.thrust  # else force is zero: skip force/m
    if frame.encke:
        acc = forces.encke_deviation_accel(frame.mu, rc, q, a_free, force if has_force else 0.0, m)
    else:
        if fused_j2:
            prm, b = frame.params, frame.primary
            acc = forces.central_j2_accel(r, frame.mu, prm.j2[b], prm.radius[b], prm.pole[b]) + a_free
        else:
            acc = forces.point_mass_accel(r, frame.mu) + a_free
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


def step(model, params, ephem, epoch_et, c, dt, ctl, tol, *, perturbation, body_states, var_labels=None):
    """One step of size dt with the model's (method, formulation).

    Returns ((t + dt, rc, vc, delta, nu, m), (body positions, velocities) at t + dt, err)
    with err the error ratio of the module docstring (0 for a method without an embedded
    pair).  ``perturbation`` and ``body_states`` are the loop's force-model functions
    (``encke.perturbation``, ``encke.body_states``), passed in to keep this module below
    the loop in the import order.

    ``var_labels`` (a tuple of parameter labels, or None): also advance ``c.phi`` (7, 7 + np),
    the sensitivities of (r, v, m) to the state at the start of the segment and to the
    labelled parameters, by the explicit variational equations with the same stages
    (:func:`_variational_rkn`); returned as a seventh element of the state tuple.
    """
    st = model.integrator
    tab = METHODS[st.method]
    frame = _Frame(model, params, ephem, epoch_et, c, dt, body_states)
    nodes = list(tab.c) + [1.0]
    frame.prepare_conics(nodes)
    if frame.encke:
        q, p = c.delta, c.nu
    else:
        q, p = c.rc + c.delta, c.vc + c.nu
    m = c.m
    h = dt
    if var_labels is not None:
        return _variational_rkn(model, params, frame, tab, c, dt, ctl, tol, perturbation, var_labels)
    if isinstance(tab, NystromTableau):
        dup = _duplicates(tab)
        ks = []
        mds = []
        for i in range(tab.stages):
            if dup[i] is not None:
                ks.append(ks[dup[i]])
                mds.append(mds[dup[i]])
                continue
            ci = float(tab.c[i])
            qi = q if ci == 0.0 else q + (ci * h) * p
            s = _lincomb(tab.a_bar[i, :i], ks)
            if s is not None:
                qi = qi + (h * h) * s
            # velocity at the stage: only used by velocity-dependent forces, which the
            # special RKN methods exclude (the configuration refuses them); p is a placeholder
            k, md = _accel(frame, ci, qi, p, m, ctl, perturbation)
            ks.append(_materialise(k))
            mds.append(md)
        q1 = q + h * p + (h * h) * _lincomb(tab.bbar, ks)
        p1 = p + h * _lincomb(tab.b, ks)
        m1 = m + h * _lincomb(tab.b, mds) if model.thrust else m
        if tab.bbar_low is None:
            err = jnp.zeros(())
            e_q = e_p = None
        else:
            e_q = (h * h) * _lincomb(tab.ebar, ks)
            e_p = h * _lincomb(tab.e, ks)
    else:
        # the stages of (q, p, m) kept as three arrays (no concatenation per stage: XLA CPU
        # copies); k_q of a stage is its velocity p_i, k_p its acceleration, k_m its mass flow
        varying_mass = model.thrust
        kq, kp, km = [], [], []
        for i in range(tab.stages):
            row = tab.a[i, :i]
            sq = _lincomb(row, kq)
            qi = q if sq is None else q + h * sq
            sp = _lincomb(row, kp)
            pi = p if sp is None else p + h * sp
            mi = m
            if varying_mass and sp is not None:
                mi = m + h * _lincomb(row, km)
            k, md = _accel(frame, float(tab.c[i]), qi, pi, mi, ctl, perturbation)
            kq.append(pi)
            kp.append(_materialise(k))
            km.append(md)
        q1 = q + h * _lincomb(tab.b, kq)
        p1 = p + h * _lincomb(tab.b, kp)
        m1 = m + h * _lincomb(tab.b, km) if varying_mass else m
        k_end, md_end = _accel(frame, 1.0, q1, p1, m1, ctl, perturbation)
        kq.append(p1)
        kp.append(k_end)
        km.append(md_end)
        e5 = [h * _lincomb(tab.e, kq), h * _lincomb(tab.e, kp), h * _lincomb(tab.e, km) if varying_mass else None]
        e3 = [h * _lincomb(tab.e_aux, kq), h * _lincomb(tab.e_aux, kp)]
        e3.append(h * _lincomb(tab.e_aux, km) if varying_mass else None)
    if frame.encke:
        rc1, vc1 = frame.conic(1.0)
        r1, v1 = rc1 + q1, vc1 + p1
        out = (c.t + dt, rc1, vc1, q1, p1, m1)
    else:
        r1, v1 = q1, p1
        z3 = jnp.zeros(3)
        out = (c.t + dt, q1, p1, z3, z3, m1)
    if isinstance(tab, NystromTableau):
        if e_q is not None:
            err = _error_ratio(e_q, e_p, None, r1, v1, m1, tol)
    else:
        # dop853.f: err = err5^2 / sqrt(err5^2 + 0.01 err3^2), per scaled component
        s5 = _error_ratio(e5[0], e5[1], e5[2], r1, v1, m1, 1.0)
        s3 = _error_ratio(e3[0], e3[1], e3[2], r1, v1, m1, 1.0)
        den = jnp.sqrt(s5 * s5 + 0.01 * s3 * s3)
        err = jnp.where(den > 0, s5 * s5 / jnp.where(den > 0, den, 1.0), 0.0) / tol
        err = jnp.where(jnp.isfinite(err), err, jnp.inf)
    return out, frame.bodies(1.0), err


# ------------------------------------------------------------- variational equations
def variational_supported(model) -> bool:
    """Whether :func:`step` can integrate explicit variational equations for this model:
    Cowell with a special RKN method, no thrust (the mass is constant), no impulses and no
    located events (stop conditions, primary changes).  Elsewhere the forward-mode AD path
    (``propagate_with_sensitivities(method="ad")``) serves, and it is the cross-check here."""
    st = model.integrator
    return (
        st.formulation == "cowell"
        and isinstance(METHODS[st.method], NystromTableau)
        and not model.thrust
        and model.n_impulses == 0
        and model.stop.kind == "time"
        and not model.change_primary_at_soi
    )


def _stage_jacobians(model, params, frame, ci, r, m, ctl, perturbation, labels):
    """Acceleration a (3,) at stage node ci and its derivatives: G = da/dr (3, 3), a_m = da/dm
    (3,) or None (no force), a_p = da/dp (3, np) or None.  The two-body part of G is analytic,
    mu/r^3 (3 r_hat r_hat^T - I) (the gravity gradient, FRACAS DERY's G), as is a_m =
    -force/m^2; the perturbations (J2, third bodies, SRP) are differentiated by forward-mode
    AD in r, and every parameter column by AD in the parameter."""
    c = frame.c
    t = c.t + ci * frame.h
    mu = frame.mu
    zero_v = jnp.zeros(3)
    pos, _ = frame.bodies(ci)
    has_force = model.srp or model.thrust
    a, _ = _accel(frame, ci, r, zero_v, m, ctl, perturbation)  # the state path's own value

    def pert(rr):
        a_free, force, _ = perturbation(model, params, t, rr, zero_v, frame.primary, pos, ctl)
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
        _, force, _ = perturbation(model, params, t, r, zero_v, frame.primary, pos, ctl)
        a_m = -force / (m * m)
    a_p = None
    if labels:
        from fracas.dynamics.parameters import get_values, set_values

        def acc_p(pp):
            prm = set_values(params, labels, pp, model)
            pos_p, _ = frame.body_states(model, prm, frame.ephem, frame.epoch_et + t)
            a_free, force, _ = perturbation(model, prm, t, r, zero_v, frame.primary, pos_p, ctl)
            return forces.point_mass_accel(r, prm.mu[frame.primary]) + a_free + force / m

        a_p = jnp.reshape(jax.jacfwd(acc_p)(get_values(params, labels, model)), (3, len(labels)))
    return a, g, a_m, a_p


def _matmul3(g, q):
    """g (3, 3) @ q (3, n) as three broadcast products (a batched dot_general under vmap runs
    as a separate, unvectorised kernel on XLA CPU)."""
    return g[:, 0:1] * q[0:1, :] + g[:, 1:2] * q[1:2, :] + g[:, 2:3] * q[2:3, :]


def _variational_rkn(model, params, frame, tab, c, dt, ctl, tol, perturbation, labels):
    """A special-RKN Cowell step of the state and of Phi = d(r, v, m)/d(x_start, p) (7, 7 + np):

        Q'' = G(t, r) Q + a_m M + a_p S,   Q = Phi[0:3], Q' = Phi[3:6], M = Phi[6] (constant)

    (S selects the parameter columns), integrated with the state's own stages and weights, so
    Phi is the exact derivative of the discrete step map at fixed step sizes -- what the AD
    path computes, to rounding (FRACAS STMGEN integrates the variational equations alongside
    the state; tests/integrate/test_variational_stm.py)."""
    labels = tuple(labels)
    n_p = len(labels)
    h = dt
    r, v, m = c.rc + c.delta, c.vc + c.nu, c.m
    phi = c.phi
    q_mat, p_mat, m_row = phi[0:3], phi[3:6], phi[6]
    dup = _duplicates(tab)
    ks, kms = [], []
    for i in range(tab.stages):
        if dup[i] is not None:
            ks.append(ks[dup[i]])
            kms.append(kms[dup[i]])
            continue
        ci = float(tab.c[i])
        ri = r if ci == 0.0 else r + (ci * h) * v
        qi = q_mat if ci == 0.0 else q_mat + (ci * h) * p_mat
        s = _lincomb(tab.a_bar[i, :i], ks)
        if s is not None:
            ri = ri + (h * h) * s
            qi = qi + (h * h) * _lincomb(tab.a_bar[i, :i], kms)
        a, g, a_m, a_p = _stage_jacobians(model, params, frame, ci, ri, m, ctl, perturbation, labels)
        km = _matmul3(g, qi)
        if a_m is not None:
            km = km + a_m[:, None] * m_row[None, :]
        if n_p:
            km = km + jnp.concatenate([jnp.zeros((3, 7)), a_p], axis=1)
        ks.append(_materialise(a))
        kms.append(_materialise(km))
    r1 = r + h * v + (h * h) * _lincomb(tab.bbar, ks)
    v1 = v + h * _lincomb(tab.b, ks)
    q1 = q_mat + h * p_mat + (h * h) * _lincomb(tab.bbar, kms)
    p1 = p_mat + h * _lincomb(tab.b, kms)
    phi1 = jnp.concatenate([q1, p1, m_row[None, :]], axis=0)
    if tab.bbar_low is None:
        err = jnp.zeros(())
    else:
        e_q = (h * h) * _lincomb(tab.ebar, ks)
        e_p = h * _lincomb(tab.e, ks)
        err = _error_ratio(e_q, e_p, None, r1, v1, m, tol)
    z3 = jnp.zeros(3)
    return (c.t + dt, r1, v1, z3, z3, m, phi1), frame.bodies(1.0), err
