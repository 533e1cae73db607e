"""Variational equations of the trajectory core (FRACAS DERY's F matrix, PATH, STMGEN).

The trajectory core integrates the Encke deviations; the error analysis needs the
*Cowell* form of the same dynamics and its first derivatives along the nominal:

    x = (r km, v km/s, m kg)  relative to the current primary,
    xdot = f(t, x, p) = (v,  -mu r/|r|^3 + a_d(t, r, v, m, p),  mdot(t, r, p))     (1)
    A(t) = df/dx  (7, 7),     B(t) = df/dp  (7, np)                               (2)
    Phidot = A Phi,  Phi(t0, t0) = I;   Thetadot = A Theta + B,  Theta(t0) = 0      (3)

a_d is exactly the perturbation the Encke integrator uses (``encke.perturbation``: J2,
third bodies, SRP, thrust with the arc controls active at t, ``encke.step_controls``), so
(3) integrated along the nominal reproduces ``propagate_with_sensitivities``' STM and
parameter matrices (tests/dynamics/test_variational.py checks it).  A and B are exact,
by forward-mode automatic differentiation (B through ``params.set_values``), where
FRACAS DERY used the analytic gravity gradient G and thrust transformation T.

For the TEAM process-noise models (``fracas.filters.process_noise``; FRACAS DYNO, DERY
and App. 9.3 eq. 2, delta xdot = f dx + g du + h d eta), the Gauss-Markov thrust noise
eta has the three components of :data:`THRUST_NOISE_LABELS` (proportionality, in-plane
and out-of-plane pointing), and

    h(t) = d xdot / d eta  = the B columns of those labels          (FRACAS DYNO eq. 5)

(position rows zero; velocity rows km/s^2 per unit of the label; mass row kg/s per unit:
a proportionality error changes the mass flow too).  h is zero while coasting.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

from fracas import _jax  # noqa: F401
from fracas.dynamics import forces
from fracas.dynamics.model import ForceModel, IntegratorSettings, Params
from fracas.dynamics.parameters import get_values, set_values
from fracas.integrate import encke
from fracas.params import THRUST_NOISE_LABELS

__all__ = [
    "THRUST_NOISE_LABELS",
    "jacobians_at",
    "saltation_at",
    "state_derivative",
    "state_jacobians",
]

# Gauss-Markov thrust error components (FRACAS DYNO's eta; App. 9.3): overall thrust
# proportionality (the ``thrust_scale`` factor, dimensionless; a 2 % error is sigma = 0.02
# when the nominal scale is 1), in-plane and out-of-plane pointing (rad).  Catalogued in
# fracas.params; re-exported here.


def state_derivative(model: ForceModel, params: Params, ephem, epoch_et_s, t, x, primary):
    """Cowell-form derivative xdot = (v, a, mdot) (7,) of the full force model, eq. (1).

    t: s from the epoch ``epoch_et_s`` (TDB s past J2000); x (7,): r km, v km/s, m kg
    relative to body index ``primary``; returns (km/s, km/s^2, kg/s).  The thrust controls
    are those active at t (arc k for t_on[k] <= t < t_off[k], ``encke.step_controls``),
    a = -mu_p r/|r|^3 + a_free + force/m (``encke.perturbation``; FRACAS GRAVFO, EP, POWER).
    """
    t = jnp.asarray(t, jnp.float64)
    x = jnp.asarray(x, jnp.float64)
    primary = jnp.asarray(primary, jnp.int32)
    r, v, m = x[:3], x[3:6], x[6]
    pos, _ = encke.body_states(model, params, ephem, epoch_et_s + t)
    ctl = encke.step_controls(model, params, t)
    a_free, force, mdot = encke.perturbation(model, params, t, r, v, primary, pos, ctl)
    acc = forces.point_mass_accel(r, params.mu[primary]) + a_free + force / m
    return jnp.concatenate([v, acc, jnp.reshape(mdot, (1,))])


def state_jacobians(model: ForceModel, params: Params, ephem, epoch_et_s, t, x, primary, labels: Sequence[str]):
    """(A (7, 7), B (7, len(labels))): A = d xdot/dx, B = d xdot/dp of eq. (1) at (t, x).

    Forward-mode AD; B's columns follow ``labels`` (``fracas.params`` labels, e.g.
    ``"mu[sun]"``, ``"thrust_scale"``), each in (xdot units) per (label unit).  With
    ``labels = THRUST_NOISE_LABELS`` B is DYNO's h(t).  Jit-friendly (``labels`` static).
    """
    labels = tuple(labels)
    x = jnp.asarray(x, jnp.float64)
    p0 = get_values(params, labels, model)

    def f(xx, pp):
        prm = set_values(params, labels, pp, model) if labels else params
        return state_derivative(model, prm, ephem, epoch_et_s, t, xx, primary)

    a_mat, b_mat = jax.jacfwd(f, argnums=(0, 1))(x, p0)
    return a_mat, jnp.reshape(b_mat, (7, len(labels)))


@partial(jax.jit, static_argnums=(0, 7))
def _jacobians_at(static: ForceModel, params, ephem, epoch_et_s, t_nodes, x_nodes, primary_nodes, labels):
    def one(t, x, p):
        return state_jacobians(static, params, ephem, epoch_et_s, t, x, p, labels)

    return jax.vmap(one)(t_nodes, x_nodes, primary_nodes)


def jacobians_at(
    model: ForceModel, params: Params, ephem, epoch_et_s, t_nodes, x_nodes, primary_nodes, labels: Sequence[str]
):
    """A (k, 7, 7) and B (k, 7, np) at k nodes (t_nodes (k,) s, x_nodes (k, 7), primary_nodes (k,)),
    computed on the nodes padded to ``propagate.output_bucket(k)`` (one program for most counts).

    At a thrust switch time the controls of [t_on, t_off) apply (DYNO/PATH intervals should
    end at switches, where h jumps).  Vmapped and jitted once per (force model structure,
    labels, array shapes): the integrator constants are not part of the dynamics and are
    dropped from the cache key, so decks differing only in step control share the compiled
    function.
    """
    from fracas.integrate.propagate import output_bucket

    static = dataclasses.replace(model, integrator=IntegratorSettings())
    k = int(np.shape(t_nodes)[0])
    kp = output_bucket(k)  # padded (last node repeated): one compile for most runs' node counts

    def pad(a, dtype):
        a = np.asarray(a, dtype)
        return jnp.asarray(np.concatenate([a, np.repeat(a[-1:], kp - k, axis=0)]) if kp > k else a)

    A, B = _jacobians_at(
        static,
        params,
        ephem,
        epoch_et_s,
        pad(t_nodes, np.float64),
        pad(x_nodes, np.float64),
        pad(primary_nodes, np.int32),
        tuple(labels),
    )
    return A[:k], B[:k]


@partial(jax.jit, static_argnums=(0,))
def _saltation_at(static: ForceModel, params, ephem, epoch_et_s, t, x, primary, old_sign):
    return encke.saltation_matrix(static, params, ephem, epoch_et_s, t, x, primary, old_sign)


def saltation_at(model: ForceModel, params: Params, ephem, epoch_et_s, t, x, primary) -> jax.Array:
    """The saltation matrix (7, 7) of the yaw flip at (t s, x (7,) about body index
    ``primary``): ``encke.saltation_matrix`` with the sign held before the flip taken from the
    state's velocity just before it (x - xdot 1e-3 s: g is ~1e-8 there, its sign clear), the
    jump that maps a covariance across the flip, P+ = S P- S^T (PDOT)."""
    static = dataclasses.replace(model, integrator=IntegratorSettings())
    x = jnp.asarray(x, jnp.float64)
    xd = state_derivative(static, params, ephem, epoch_et_s, t, x, primary)
    before = x - 1e-3 * xd
    h = jnp.cross(before[:3], before[3:6])
    old = jnp.where(h[0] * before[1] - h[1] * before[0] >= 0.0, 1.0, -1.0)
    return _saltation_at(
        static, params, ephem, epoch_et_s, jnp.asarray(t, jnp.float64), x, jnp.asarray(primary, jnp.int32), old
    )
