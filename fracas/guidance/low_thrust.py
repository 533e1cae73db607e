"""Low-thrust primary guidance (FRACAS GUIDM §5.3.6, low-thrust branch; digest B.7).

Equations of the seed digest ``tom-tsim-guidance.md`` §B.7 [RECON, medium-high]:

* Controls (a selectable subset, :data:`LOW_THRUST_CONTROLS`) of one guidance arc [t_I, t_c],
  a thrust arc switched on at t_I and off at t_c: δU = [δk, δα, δβ, δt_I, δt_c] on the
  fracas labels ``arc_thrust_scale[j]``, ``arc_alpha[j]``, ``arc_beta[j]``, ``arc_t_on[j]``,
  ``arc_t_off[j]``.
* (L-1) S = ∂[r, v, m](t_c)/∂U (7×M) with X(t_I) held fixed (:func:`control_sensitivity`).
* (L-2) K = ΨS, Λ = ΨΦ(t_c, t_I), Γ_U = K^{+W}Λ, δU = −Γ_U δX̂(t_I)
  (:func:`weighted_correction_matrix`, which is also the impulsive (G-3) with K = Ψ_v).
* (L-3) P_U = Γ_U P̃ Γ_Uᵀ (the same algebra as :func:`fracas.guidance.impulsive.dv_covariance`).
* (L-4) the ΔV and propellant cost of a correction (:func:`correction_cost_jacobians`).
* Execution errors of a low-thrust correction: the report gives no model;
  :func:`execution_covariance` is a fracas choice.

Units: km, km/s, kg, s, rad; thrust in kg km/s² (= kN, fracas's canonical thrust unit,
:func:`fracas.dynamics.propulsion.thrust_magnitude`); accelerations km/s²; exhaust velocity
c km/s.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array
from jax.typing import ArrayLike

from fracas import _jax  # noqa: F401  (float64 before any array exists)
from fracas.dynamics.parameters import get_values
from fracas.guidance.target_kinds import CONTROL_UNITS, LOW_THRUST_CONTROLS
from fracas.integrate import encke
from fracas.integrate.propagate import propagate_with_sensitivities

if TYPE_CHECKING:
    from fracas.dynamics.model import Params
    from fracas.integrate.problem import Problem

__all__ = [
    "LOW_THRUST_CONTROLS",
    "CONTROL_UNITS",
    "CONTROL_LABEL_NAMES",
    "control_labels",
    "control_sensitivity",
    "weighted_correction_matrix",
    "correction_cost_jacobians",
    "execution_covariance",
]

# The controls of one guidance arc (digest (L-1)), in the report's order, and their units
# (proportionality is the dimensionless per-arc thrust scale, nominal 1): the jax-free
# catalogue fracas.guidance.target_kinds, which the deck validation reads too.
#: The fracas parameter (:mod:`fracas.params`) each control varies.
CONTROL_LABEL_NAMES = {
    "proportionality": "arc_thrust_scale",
    "alpha": "arc_alpha",
    "beta": "arc_beta",
    "t_on": "arc_t_on",
    "t_off": "arc_t_off",
}


def _check_controls(controls: Sequence[str]) -> tuple[str, ...]:
    controls = tuple(controls)
    for c in controls:
        if c not in LOW_THRUST_CONTROLS:
            raise KeyError(f"unknown low-thrust control {c!r}; known: {', '.join(LOW_THRUST_CONTROLS)}")
    return controls


def control_labels(arc: int, controls: Sequence[str] = LOW_THRUST_CONTROLS) -> list[str]:
    """The parameter labels of ``controls`` on thrust arc ``arc``, e.g. ``arc_t_off[0]``."""
    return [f"{CONTROL_LABEL_NAMES[c]}[{int(arc)}]" for c in _check_controls(controls)]


# ------------------------------------------------------------------- sensitivities (L-1)
def _arc_of(label: str) -> tuple[str, int]:
    name, _, rest = label.partition("[")
    return name, int(rest.rstrip("]")) if rest else -1


def _arc_thrust_rate(problem: Problem, params: Params, t: float, x: np.ndarray, primary: int, arc: int) -> np.ndarray:
    """f_j = [0; T û/m; −T/c] (7,): the state rate that thrust arc ``arc`` alone adds at (t, x)
    (thrust and pointing of that arc, power at t; FRACAS EP)."""
    model = problem.model
    # the arc's pointing law at t (encke.step_controls's, with only this arc on)
    law = encke.arc_law(params, jnp.arange(model.n_arcs) == arc) if model.steering else None
    ctl_on = encke.StepControls(
        params.thrust_scale * params.arc_throttle[arc] * params.arc_thrust_scale[arc],
        params.arc_alpha[arc] + params.arc_bias_in_rad[arc] + params.bias_in_rad,
        params.arc_beta[arc] + params.arc_bias_out_rad[arc] + params.bias_out_rad,
        params.arc_frame[arc],
        None,
        law,
    )
    z = jnp.zeros(())
    ctl_off = encke.StepControls(z, z, z, z)
    # Problem.ephem is declared `object | None` (an EphemerisTable or None)
    pos, _ = encke.body_states(model, params, problem.ephem, problem.epoch_et_s + t)  # type: ignore[arg-type]
    r, v = jnp.asarray(x[0:3]), jnp.asarray(x[3:6])
    _, f_on, md_on = encke.perturbation(model, params, t, r, v, primary, pos, ctl_on)
    _, f_off, md_off = encke.perturbation(model, params, t, r, v, primary, pos, ctl_off)
    out = np.zeros(7)
    out[3:6] = np.asarray(f_on - f_off) / float(x[6])
    out[6] = float(md_on - md_off)
    return out


def control_sensitivity(problem: Problem, t_from_s: float, t_to_s: float, labels: Sequence[str]) -> tuple[Array, Array]:
    """S = ∂[r, v, m](t_to)/∂U (7×M), X(t_from) held fixed, and Φ(t_to, t_from) (7×7) (digest (L-1)).

    problem: a :class:`fracas.integrate.problem.Problem` (x0 at t = 0); labels: parameter
    labels, typically :func:`control_labels`.  One :func:`propagate_with_sensitivities` over
    [0,] t_from, t_to; S and Φ are its last par_step and stm_step (as
    :func:`fracas.team.reference.integrate_reference` chains them).  The 7-state Φ carries the
    mass, so a proportionality or switch-time change reaches every later acceleration.

    Switch times at an end of the interval.  The guidance arc usually starts at t_from = t_I
    and ends at t_to = t_c, where the state is a one-sided function of the switch time and AD
    through the integrator gives no (or a wrong) derivative.  fracas uses the convention of
    the digest (L-1): a switch of arc j at an end acts as an impulse f_j δt there, with
    f_j = [0; a û; −T/c] the state rate that arc adds at that state and time:

    * ``arc_t_off[j]`` = t_to: ∂X(t_c)/∂t_c = +f_j(t_c);  ``arc_t_on[j]`` = t_to: −f_j(t_to);
    * ``arc_t_on[j]`` = t_from: ∂X/∂t_I = −Φ(t_to, t_I) f_j(t_I);
      ``arc_t_off[j]`` = t_from: +Φ(t_to, t_from) f_j(t_from).

    These are the derivatives of the state that a later propagation (from t_to with the
    nominal switch) needs, and equal central differences when the interval is extended past
    the switch.  Arcs are assumed not to overlap at the switch.
    Units: S column per control unit (km, km/s, kg per 1, rad or s).
    """
    labels = tuple(labels)
    t_from = float(t_from_s)
    t_to = float(t_to_s)
    if not t_to > t_from:
        raise ValueError(f"t_to_s ({t_to}) must be after t_from_s ({t_from})")
    lead = t_from > 0.0
    t_out = np.array([0.0, t_from, t_to] if lead else [t_from, t_to])
    traj, sens = propagate_with_sensitivities(
        problem.model, problem.params, problem.ephem, problem.epoch_et_s, problem.x0, t_out, labels
    )
    phi = np.array(sens.stm_step[-1])
    s = np.array(sens.par_step[-1])
    if not (np.all(np.isfinite(phi)) and np.all(np.isfinite(s))):
        raise ValueError(f"propagation from {t_from} s to {t_to} s did not reach t_to (status {int(traj.status)})")
    x_from, x_to = np.asarray(traj.x[-2]), np.asarray(traj.x[-1])
    p_from, p_to = int(traj.primary[-2]), int(traj.primary[-1])
    eps = float(problem.model.integrator.eps_t_s)
    values = np.asarray(get_values(problem.params, labels, problem.model))
    for k, label in enumerate(labels):
        name, arc = _arc_of(label)
        if name not in ("arc_t_on", "arc_t_off"):
            continue
        sign = -1.0 if name == "arc_t_on" else 1.0
        if abs(values[k] - t_to) < eps:
            s[:, k] = sign * _arc_thrust_rate(problem, problem.params, t_to, x_to, p_to, arc)
        elif abs(values[k] - t_from) < eps:
            s[:, k] = sign * (phi @ _arc_thrust_rate(problem, problem.params, t_from, x_from, p_from, arc))
    return jnp.asarray(s), jnp.asarray(phi)


# ---------------------------------------------------------------- correction matrix (L-2)
def weighted_correction_matrix(
    k_mat: ArrayLike,
    lam: ArrayLike,
    weights: ArrayLike | Sequence[float] | None = None,
    tolerances: ArrayLike | Sequence[float] | None = None,
    rtol: float = 1e-12,
) -> tuple[Array, Array]:
    """Γ_U = K^{+W} Λ (M×n) and the rank of the weighted K (digest (L-2), (G-3); GUIDM §5.3.6).

    k_mat: K (m×M), targets per control; lam: Λ (m×n), targets per state deviation;
    weights: (M,) W = diag(weights), default ones; tolerances: (m,) E_ε = diag, default ones.

    * M > m (controls outnumber targets): Γ = W Kᵀ (K W Kᵀ)⁻¹ Λ, the correction of least
      Σ δU_i²/w_i that meets the targets;
    * M < m: Γ = (Kᵀ E_ε⁻² K)⁻¹ Kᵀ E_ε⁻² Λ, least squares weighted by the tolerances;
    * M = m: Γ = K⁻¹ Λ.

    One formula, Γ = W^{1/2} (E_ε⁻¹ K W^{1/2})⁺ E_ε⁻¹ Λ, by SVD with singular values below
    ``rtol``·σ_max discarded; ``rank`` counts those kept (rank < min(m, M): some target
    combination is uncontrollable, Γ is then the weighted minimum-norm least-squares solution).
    """
    k_mat = jnp.asarray(k_mat)
    lam = jnp.asarray(lam)
    m, n_u = k_mat.shape
    w = jnp.ones(n_u) if weights is None else jnp.asarray(weights)
    tol = jnp.ones(m) if tolerances is None else jnp.asarray(tolerances)
    sqrt_w = jnp.sqrt(w)
    a = (k_mat / tol[:, None]) * sqrt_w[None, :]
    u, s, vt = jnp.linalg.svd(a, full_matrices=False)
    keep = s > rtol * s[0]
    s_inv = jnp.where(keep, 1.0 / jnp.where(keep, s, 1.0), 0.0)
    a_pinv = (vt.T * s_inv[None, :]) @ u.T
    gamma = sqrt_w[:, None] * (a_pinv @ (lam / tol[:, None]))
    return gamma, jnp.sum(keep)


# ----------------------------------------------------------------------- cost (L-4)
def correction_cost_jacobians(
    controls: Sequence[str],
    a_i: float | Array,
    a_c: float | Array,
    m_i: float | Array,
    m_c: float | Array,
    c: float | Array,
    thrust_i: float | Array,
    thrust_c: float | Array,
    proportionality: float | Array = 1.0,
) -> tuple[jax.Array, jax.Array]:
    """J_ΔV (M,) and J_m (M,): first-order ΔV and propellant change per unit of each control (digest (L-4)).

    ΔV_arc = c ln(m_I/m_c) and propellant m_I − m_c over the guidance arc [t_I, t_c]; the mass
    m_I at t_I does not move with t_I (the arc follows a coast).  With k the nominal
    proportionality (``proportionality``, default 1; T ∝ k so ∂m_c/∂k = −(m_I − m_c)/k):

    * J_ΔV = [c(m_I − m_c)/(k m_c), 0, 0, −a_I m_I/m_c, a_c]   (km/s per 1, rad, rad, s, s);
    * J_m  = [(m_I − m_c)/k, 0, 0, −T_I/c, T_c/c]                (kg per 1, rad, rad, s, s).

    The digest's forms (k = 1) check against finite differences of re-propagated arcs
    (tests/guidance/test_low_thrust.py); pointing does not change the propellant at first
    order for constant c.  a_i, a_c: thrust acceleration T/m at t_I, t_c (km/s²); m_i, m_c
    kg; c km/s; thrust_i, thrust_c: T at t_I, t_c in kg km/s².  σ_ΔV² = J_ΔV P_U J_ΔVᵀ.
    """
    controls = _check_controls(controls)
    k = proportionality
    used = m_i - m_c
    dv = {
        "proportionality": c * used / (k * m_c),
        "alpha": 0.0 * c,
        "beta": 0.0 * c,
        "t_on": -a_i * m_i / m_c,
        "t_off": a_c + 0.0 * c,
    }
    mass = {
        "proportionality": used / k,
        "alpha": 0.0 * used,
        "beta": 0.0 * used,
        "t_on": -thrust_i / c,
        "t_off": thrust_c / c,
    }
    j_dv = jnp.stack([jnp.asarray(dv[u], jnp.float64) for u in controls])
    j_m = jnp.stack([jnp.asarray(mass[u], jnp.float64) for u in controls])
    return j_dv, j_m


# ------------------------------------------------------------------ execution errors
def execution_covariance(
    controls: Sequence[str], p_u: ArrayLike, fraction: ArrayLike = 0.01, floor: ArrayLike | None = None
) -> jax.Array:
    """Execution-error covariance (M×M) of a low-thrust correction δU: a fracas choice.

    The report gives no low-thrust execution model.  fracas takes each control's correction
    as executed with an independent fractional error: Σ_U = diag(fraction² diag(P_U)) (the
    variance of fraction × δU_i averaged over δU ~ N(0, P_U)), plus diag(floor²) when
    ``floor`` (scalar or (M,), in each control's unit, :data:`CONTROL_UNITS`) is given — a
    resolution of the commanded value.  fraction: scalar or (M,), default 1 % (the
    high-thrust proportionality σ of App. 9.1, report L2722).
    """
    controls = _check_controls(controls)
    p_u = jnp.asarray(p_u)
    if p_u.shape != (len(controls), len(controls)):
        raise ValueError(f"p_u has shape {p_u.shape}; expected ({len(controls)}, {len(controls)})")
    var = jnp.square(jnp.asarray(fraction, jnp.float64)) * jnp.diagonal(p_u)
    if floor is not None:
        var = var + jnp.square(jnp.asarray(floor, jnp.float64))
    return jnp.diag(var * jnp.ones(len(controls)))
