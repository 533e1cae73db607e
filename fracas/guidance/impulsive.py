"""Linear impulsive guidance (FRACAS GUIDM §5.3.6, impulsive branch; XGUID §5.3.25).

Pure JAX functions of arrays, float64, jit- and vmap-able (no Python control flow on values).
The equations are those of the seed digest ``tom-tsim-guidance.md`` Part B, whose labels are
quoted: (G-0) the covariance of the estimated deviation, (G-3)..(G-5) the guidance matrix and
the ΔV covariance, (G-6) Gates execution errors, (G-7)/(G-8) the post-guidance control and
target covariances.  The report's own guidance equations are lost from the scan (digest §0);
these are the standard linear-guidance forms the digest rebuilt [RECON/EXT].

Notation and units
------------------
* State deviation δX at the guidance epoch t_G, n ≥ 6 components ordered
  ``[r (km), v (km/s), ...]``; anything after the velocity (mass, solve-for/consider
  parameters) is carried along.  ``B = [0; I₃; 0]`` (n×3) selects the velocity rows.
* Ψ (m×n): variation of the m targets with respect to δX(t_G) (TARMAT §5.4.9,
  Ψ = A_T Φ(t_f, t_G), digest (G-2)); Ψ = [Ψ_r Ψ_v ...] with Ψ_v = Ψ[:, 3:6].
* P_c = cov δX (control covariance), P_k = cov e (knowledge covariance, e = X − X̂, the
  *true* TEAM knowledge covariance, digest P-B3), C_xe = E[δX eᵀ].
* Guidance: ΔV = −Γ δX̂ with δX̂ = δX − e (digest (G-4)); Γ is 3×n.
* ΔV, its covariance and execution errors in km/s and km²/s².

Models of the estimated-deviation covariance (digest §B.3, decision P-B1)
--------------------------------------------------------------------------
``cov δX̂ = P̃ = P_c − C_xe − C_xeᵀ + P_k`` (G-0), with C_xe fixed by ``mode``:

=============== ========== ================= ==============================================
mode            C_xe       P̃                 meaning
=============== ========== ================= ==============================================
``report``      P_k/2      P_c               TEAM as written ("pessimistic"); the DEFAULT
``orthogonal``  P_k        P_c − P_k         optimal filter, E[δX̂ eᵀ] = 0
``tsim``        0          P_c + P_k         e independent of δX (TSIM's sampling)
``tracked``     given      exact             caller tracks C_xe (``cross=``)
=============== ========== ================= ==============================================

The same C_xe enters the exact post-guidance covariance (G-7); in ``report`` mode the
post-guidance covariance is the report's reset to the knowledge instead (see
:func:`post_guidance_covariance`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax import Array
from jax.typing import ArrayLike

from fracas import _jax  # noqa: F401  (float64 before any array exists)
from fracas.guidance.low_thrust import weighted_correction_matrix

__all__ = [
    "MODES",
    "SIGMA_PROPORTIONALITY",
    "SIGMA_POINTING_RAD",
    "SIGMA_RESOLUTION_KM_S",
    "GuidanceMatrix",
    "velocity_selector",
    "cross_covariance",
    "estimate_deviation_covariance",
    "guidance_matrix",
    "dv_covariance",
    "gates_covariance",
    "execution_error_covariance",
    "post_guidance_covariance",
    "post_correction_covariance",
    "target_covariance",
]

MODES = ("report", "orthogonal", "tsim", "tracked")

# App. 9.1 high-thrust (Mariner-class) execution errors, report L2722 (digest §B.2, §B.11).
SIGMA_PROPORTIONALITY = 0.01  # 1 %
SIGMA_POINTING_RAD = 7.0e-3  # 7 mrad, each of the two pointing angles
SIGMA_RESOLUTION_KM_S = 1.0e-5  # 0.01 m/s

_VEL = slice(3, 6)


class GuidanceMatrix(NamedTuple):
    """Γ (3×n, ΔV = −Γ δX̂) and the rank of the weighted velocity sensitivity Ψ_v.

    rank == min(m, 3) means the targeting is well posed: exact when m = 3, minimum weighted
    |ΔV| when m < 3, weighted least squares when m > 3.  A smaller rank means some target
    combination is uncontrollable by ΔV; Γ is then the weighted minimum-norm least-squares
    (pseudo-inverse) solution.
    """

    gamma: jax.Array
    rank: jax.Array


def velocity_selector(n: int) -> jax.Array:
    """B = [0; I₃; 0] (n×3): velocity rows of an n-state (n ≥ 6), digest (G-7)."""
    return jnp.zeros((n, 3)).at[_VEL, :].set(jnp.eye(3))


def cross_covariance(
    p_control: ArrayLike, p_knowledge: ArrayLike, mode: str = "report", cross: ArrayLike | None = None
) -> jax.Array:
    """C_xe = E[δX eᵀ] of the model ``mode`` (digest §B.3 table); ``cross`` for ``tracked``."""
    p_k = jnp.asarray(p_knowledge)
    if mode == "report":
        return 0.5 * p_k
    if mode == "orthogonal":
        return p_k
    if mode == "tsim":
        return jnp.zeros_like(p_k)
    if mode == "tracked":
        if cross is None:
            raise ValueError("mode 'tracked' needs cross = E[δX eᵀ]")
        return jnp.asarray(cross)
    raise ValueError(f"unknown mode {mode!r}; expected one of {MODES}")


def estimate_deviation_covariance(
    p_control: ArrayLike, p_knowledge: ArrayLike, mode: str = "report", cross: ArrayLike | None = None
) -> jax.Array:
    """P̃ = cov δX̂ = P_c − C_xe − C_xeᵀ + P_k (digest (G-0), default ``report``: P̃ = P_c).

    FRACAS GUIDM §5.3.6 uses P_c ("pessimistic", report L1700); ``orthogonal`` gives the
    consistent linear-covariance value P_c − P_k; ``tsim`` gives P_c + P_k (TSIM's sampling);
    ``tracked`` uses the caller's C_xe.  All matrices n×n in the state's units.
    """
    p_c = jnp.asarray(p_control)
    p_k = jnp.asarray(p_knowledge)
    c = cross_covariance(p_c, p_k, mode, cross)
    return p_c - c - c.T + p_k


def guidance_matrix(
    psi: ArrayLike,
    weights: ArrayLike | Sequence[float] | None = None,
    tolerances: ArrayLike | Sequence[float] | None = None,
    rtol: float = 1e-12,
) -> GuidanceMatrix:
    """Γ = Ψ_v^{+W} Ψ, the linear impulsive guidance matrix (digest (G-3); GUIDM §5.3.6).

    psi: Ψ (m×n), targets with respect to the state at the guidance epoch (TARMAT §5.4.9);
        columns 3:6 are the velocity block Ψ_v.
    weights: per ΔV component (3,), W = diag(weights), default ones.  Used when controls
        outnumber targets (m < 3): Γ = W Ψ_vᵀ (Ψ_v W Ψ_vᵀ)⁻¹ Ψ, the ΔV that meets the targets
        with the least Σ ΔV_i²/w_i — a larger weight lets that component take a larger share
        ("selective weighting ... distributes the control correction", report L1700).
    tolerances: per target (m,), E_ε = diag(tolerances), default ones.  Used when targets
        outnumber controls (m > 3): Γ = (Ψ_vᵀ E_ε⁻² Ψ_v)⁻¹ Ψ_vᵀ E_ε⁻² Ψ (weighted least squares).
    m = 3 gives Γ = Ψ_v⁻¹ Ψ; weights and tolerances drop out.  Whenever rank Ψ_v = m ≤ 3 the
    targeting is exact, Ψ_v Γ = Ψ: the ΔV cancels the predicted miss Ψ δX̂.

    All three are one formula, Γ = W^{1/2} (E_ε⁻¹ Ψ_v W^{1/2})⁺ E_ε⁻¹ Ψ, evaluated by SVD with
    singular values below ``rtol``·σ_max discarded; ``rank`` counts those kept
    (:func:`fracas.guidance.low_thrust.weighted_correction_matrix` with K = Ψ_v, Λ = Ψ).
    Units: Γ maps a state deviation (km, km/s, ...) to ΔV in km/s.
    """
    psi = jnp.asarray(psi)
    gamma, rank = weighted_correction_matrix(psi[:, _VEL], psi, weights, tolerances, rtol)
    return GuidanceMatrix(gamma=gamma, rank=rank)


def dv_covariance(gamma: ArrayLike, p_tilde: ArrayLike) -> jax.Array:
    """P_ΔV = Γ P̃ Γᵀ (digest (G-5)), km²/s²; P̃ from :func:`estimate_deviation_covariance`."""
    gamma = jnp.asarray(gamma)
    return gamma @ jnp.asarray(p_tilde) @ gamma.T


def _gates_form(
    m: Array, trace_m: Array, sigma_p: ArrayLike, sigma_beta1: ArrayLike, sigma_beta2: ArrayLike, sigma_res: ArrayLike
) -> Array:
    """σ_p² M + σ̄_β² (tr M · I − M) + σ_res² I, σ̄_β² = (σ_β1² + σ_β2²)/2 (digest (G-6)):
    Gates's covariance for M = d dᵀ, its average over d for M = E[d dᵀ]."""
    sb2 = 0.5 * (jnp.square(sigma_beta1) + jnp.square(sigma_beta2))
    eye = jnp.eye(3)
    return jnp.square(sigma_p) * m + sb2 * (trace_m * eye - m) + jnp.square(sigma_res) * eye


def gates_covariance(
    dv: ArrayLike,
    sigma_p: ArrayLike = SIGMA_PROPORTIONALITY,
    sigma_beta1: ArrayLike = SIGMA_POINTING_RAD,
    sigma_beta2: ArrayLike = SIGMA_POINTING_RAD,
    sigma_res: ArrayLike = SIGMA_RESOLUTION_KM_S,
) -> jax.Array:
    """Execution-error covariance of one commanded ΔV d (km/s), Gates (1963) (digest (G-6)).

    cov ε = σ_p² d dᵀ + σ̄_β² (|d|² I − d dᵀ) + σ_res² I, σ̄_β² = (σ_β1² + σ_β2²)/2:
    proportionality σ_p (fraction) along d, two pointing angles σ_β1, σ_β2 (rad) across d,
    averaged about d (exact when σ_β1 = σ_β2; digest P-B7), and an isotropic resolution
    σ_res (km/s) as the digest writes it.  Errors of App. 9.1 (report L2722) are the defaults.
    """
    d = jnp.asarray(dv)
    return _gates_form(jnp.outer(d, d), jnp.dot(d, d), sigma_p, sigma_beta1, sigma_beta2, sigma_res)


def execution_error_covariance(
    dv_nominal: ArrayLike,
    p_dv: ArrayLike,
    sigma_p: ArrayLike = SIGMA_PROPORTIONALITY,
    sigma_beta1: ArrayLike = SIGMA_POINTING_RAD,
    sigma_beta2: ArrayLike = SIGMA_POINTING_RAD,
    sigma_res: ArrayLike = SIGMA_RESOLUTION_KM_S,
) -> jax.Array:
    """Σ_ex, the Gates covariance averaged over the commanded ΔV = d₀ + δ, δ ~ N(0, P_ΔV).

    Gates's cov ε is linear in d dᵀ, so the average is :func:`gates_covariance`'s form with
    d dᵀ replaced by M = E[d dᵀ] = d₀d₀ᵀ + P_ΔV and |d|² by tr M:
    Σ_ex = σ_p² M + σ̄_β² (tr M · I − M) + σ_res² I (digest (G-6); exact for σ_β1 = σ_β2).
    d₀ = 0 (a purely statistical correction) gives the digest's formula.  ε has zero mean
    given d, so it is uncorrelated with the state and the knowledge error.
    dv_nominal (3,) km/s; p_dv (3×3) km²/s²; result km²/s².
    """
    d0 = jnp.asarray(dv_nominal)
    mm = jnp.outer(d0, d0) + jnp.asarray(p_dv)
    return _gates_form(mm, jnp.trace(mm), sigma_p, sigma_beta1, sigma_beta2, sigma_res)


def post_guidance_covariance(
    p_control: ArrayLike,
    p_knowledge: ArrayLike,
    gamma: ArrayLike,
    sigma_exec: ArrayLike,
    mode: str = "report",
    cross: ArrayLike | None = None,
    n_state: int = 6,
) -> jax.Array:
    """P_c⁺, the control covariance just after the impulse (digest (G-7); GUIDM §5.3.6).

    ``mode="report"`` (default, report L1702 with decision P-B2): the state block becomes the
    knowledge plus the execution errors, P_k,xx + B Σ_ex Bᵀ; the state–parameter blocks
    become the knowledge's C_k,xp; the parameter block keeps P_c,pp (estimating a parameter
    does not change its actual dispersion).  ``n_state`` is the size of the state block
    (6, or 7 with mass); rows beyond it are parameters.

    Other modes: the exact propagation of δX⁺ = (I − BΓ)δX + BΓe + Bε with C_xe of the mode::

        P_c⁺ = (I−BΓ)P_c(I−BΓ)ᵀ + BΓP_kΓᵀBᵀ + (I−BΓ)C_xeΓᵀBᵀ + BΓC_xeᵀ(I−BΓ)ᵀ + BΣ_exBᵀ

    (``orthogonal``: (I−BΓ)(P_c−P_k)(I−BΓ)ᵀ + P_k + BΣ_exBᵀ).  For three targets Ψ(I−BΓ) = 0
    and both forms give the same target covariance Ψ(P_k + BΣ_exBᵀ)Ψᵀ (digest G1).
    All n×n; sigma_exec (3×3, km²/s²) from :func:`execution_error_covariance`.
    """
    p_c = jnp.asarray(p_control)
    n = p_c.shape[0]
    b = velocity_selector(n)
    bsb = b @ jnp.asarray(sigma_exec) @ b.T
    g_mat = b @ jnp.asarray(gamma)
    return post_correction_covariance(p_c, p_knowledge, g_mat, mode, cross, n_state) + bsb


def post_correction_covariance(
    p_control: ArrayLike,
    p_knowledge: ArrayLike,
    g_mat: ArrayLike,
    mode: str = "report",
    cross: ArrayLike | None = None,
    n_state: int = 6,
    reset: str = "state",
) -> jax.Array:
    """P_c⁺ of any linear correction δX⁺ = (I − G)δX + G e, execution errors excluded
    (digest (G-7) with BΓ → G: G = BΓ for an impulse, Φ⁻¹SΓ_U for a low-thrust arc
    written at its initiation).

    ``mode="report"`` with ``reset="state"``: the state rows and columns (the first
    ``n_state``) become the knowledge's, the parameter block keeps P_c,pp (P-B2);
    ``reset="all"``: every block becomes the knowledge's.  Other modes, or
    ``reset="exact"``: (I−G)P_c(I−G)ᵀ + G P_k Gᵀ + (I−G)C_xe Gᵀ + G C_xeᵀ(I−G)ᵀ with the
    mode's C_xe (``report``: P_k/2).
    """
    p_c = jnp.asarray(p_control)
    p_k = jnp.asarray(p_knowledge)
    if mode == "report" and reset != "exact":
        if reset == "all":
            return p_k
        x = slice(0, n_state)
        return p_c.at[x, :].set(p_k[x, :]).at[:, x].set(p_k[:, x])
    c = cross_covariance(p_c, p_k, mode, cross)
    g_mat = jnp.asarray(g_mat)
    a = jnp.eye(p_c.shape[0]) - g_mat
    cross_term = a @ c @ g_mat.T
    return a @ p_c @ a.T + g_mat @ p_k @ g_mat.T + cross_term + cross_term.T


def target_covariance(psi: ArrayLike, p: ArrayLike) -> jax.Array:
    """P_T = Ψ P Ψᵀ (digest (G-8)): the target covariance before (P = P_c) or after (P_c⁺)."""
    psi = jnp.asarray(psi)
    return psi @ jnp.asarray(p) @ psi.T
