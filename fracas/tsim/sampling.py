"""Random draws of a TSIM Monte Carlo mission (FRACAS TSIM; digest items CSAMP, RNUM, NOISE).

Pure functions of arrays, float64, jit- and vmap-able (no Python control flow on traced values),
except :func:`covariance_factor`, which factors a fixed covariance once on the host (numpy).

Random numbers (RNUM)
---------------------
Every draw of mission ``i`` comes from ``mission_key(seed, i) = fold_in(PRNGKey(seed), i)``,
split further by :func:`stream_key` into independent streams (:data:`STREAM_INITIAL`,
:data:`STREAM_NOISE`, :data:`STREAM_KNOWLEDGE`, :data:`STREAM_EXECUTION`; the last two indexed
by the maneuver number).  A key is a function of ``(seed, i, stream, index)`` only, so mission
``i``'s draws are the same whatever the batch size, the order of the batch, or the number of
workers or devices that run it: a run can be split, resumed or rerun mission by mission.

Units: positions km, velocities and ΔV km/s, times s, covariances in the squares of these.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from fracas import _jax  # noqa: F401  (float64 before any array exists)
from fracas.dynamics.relative_motion import hill_axes

__all__ = [
    "STREAM_INITIAL",
    "STREAM_NOISE",
    "STREAM_KNOWLEDGE",
    "STREAM_EXECUTION",
    "mission_key",
    "stream_key",
    "covariance_factor",
    "sample_normal",
    "gauss_markov",
    "gauss_markov_cell_means",
    "rtn_matrix",
    "rotate_state_covariance",
    "gates_error",
    "proportional_error",
]

#: Stream of the initial-state dispersion (CSAMP of the injection covariance); index 0.
STREAM_INITIAL = 0
#: Stream of the Gauss–Markov noise processes (NOISE); index 0.
STREAM_NOISE = 1
#: Stream of the knowledge (navigation) error at a maneuver; index = maneuver number.
STREAM_KNOWLEDGE = 2
#: Stream of the execution error of a maneuver; index = maneuver number.
STREAM_EXECUTION = 3

# Eigenvalues below n·eps × the largest are rounding (eigh's absolute accuracy) and are set to zero.
_EIGEN_EPS = np.finfo(np.float64).eps


def mission_key(seed: int, mission_index) -> jax.Array:
    """The key of mission ``mission_index`` (int or traced integer) of the run with ``seed``:
    ``jax.random.fold_in(jax.random.PRNGKey(seed), mission_index)`` (RNUM).

    It depends on ``(seed, mission_index)`` alone, so mission i's draws do not depend on the
    batch size, the batch order or the number of workers; vmap it over an array of indices.
    """
    return jax.random.fold_in(jax.random.PRNGKey(seed), mission_index)


def stream_key(key: jax.Array, stream: int, index=0) -> jax.Array:
    """Key of stream ``stream`` (one of the ``STREAM_*`` constants) and item ``index`` (the
    maneuver number for knowledge and execution errors) of a mission key:
    ``fold_in(fold_in(key, stream), index)``."""
    return jax.random.fold_in(jax.random.fold_in(key, stream), index)


def covariance_factor(p, method: str = "eigen") -> np.ndarray:
    """A factor L (n×n, float64 numpy) with L Lᵀ = P of a covariance P (n×n) (CSAMP).

    P is symmetrized first.  ``method="eigen"`` (default): P = R Λ Rᵀ, L = R Λ^{1/2}, with
    negative eigenvalues, and those below n·ε × the largest (ε the float64 epsilon: below
    eigh's absolute accuracy, i.e. rounding), set to zero, so a singular or slightly indefinite
    P works and L Lᵀ is P with those eigenvalues clipped.  Components whose row and column of P
    are exactly zero (not dispersed) are left out of the decomposition, so their rows of L, and
    their samples, are exactly zero.
    ``method="cholesky"``: the lower Cholesky factor; P must be positive definite
    (:class:`ValueError` otherwise).  Units: those of √P (km, km/s, ...).
    """
    p = np.asarray(p, dtype=np.float64)
    if p.ndim != 2 or p.shape[0] != p.shape[1]:
        raise ValueError(f"covariance_factor: P must be square, got shape {p.shape}")
    if not np.all(np.isfinite(p)):
        raise ValueError("covariance_factor: P has non-finite entries")
    p = 0.5 * (p + p.T)
    n = p.shape[0]
    if method == "cholesky":
        try:
            return np.linalg.cholesky(p)
        except np.linalg.LinAlgError as exc:
            raise ValueError(
                "covariance_factor: P is not positive definite, so it has no Cholesky factor; "
                "use method='eigen' for a singular or semi-definite P"
            ) from exc
    if method != "eigen":
        raise ValueError(f"covariance_factor: unknown method {method!r}; expected 'eigen' or 'cholesky'")
    out = np.zeros((n, n))
    active = np.flatnonzero(np.any(p != 0.0, axis=0))
    if active.size == 0:
        return out
    lam, vec = np.linalg.eigh(p[np.ix_(active, active)])
    lam = np.where(lam > n * _EIGEN_EPS * max(lam.max(), 0.0), lam, 0.0)
    out[np.ix_(active, active)] = vec * np.sqrt(lam)
    return out


def sample_normal(key: jax.Array, factor) -> jax.Array:
    """One draw x = L z, z ~ N(0, I), of N(0, L Lᵀ); ``factor`` L (n×m), result (n,) (CSAMP:
    add the nominal X to get X + R Λ^{1/2} z)."""
    factor = jnp.asarray(factor, jnp.float64)
    return factor @ jax.random.normal(key, (factor.shape[1],), jnp.float64)


def gauss_markov(key: jax.Array, sigma, tau_s, dt_s) -> jax.Array:
    """Independent first-order Gauss–Markov processes at K+1 nodes (NOISE), shape (K+1, c).

    sigma (c,): steady-state standard deviations (any unit); tau_s (c,): correlation times (s);
    dt_s (K,): steps between the nodes t_0, t_0 + dt_0, ... (s, ≥ 0).  Exact discretization
    δn_{k+1} = φ_k δn_k + σ √(1 − φ_k²) z_k, φ_k = exp(−dt_k/τ), started stationary at
    δn_0 ~ N(0, σ²), so E[δn(t_i) δn(t_j)] = σ² exp(−|t_i − t_j|/τ) for any steps.
    σ = 0 gives zeros; τ = +inf a random constant (φ = 1); a zero step repeats the value.
    """
    sigma = jnp.asarray(sigma, jnp.float64)
    tau = jnp.broadcast_to(jnp.asarray(tau_s, jnp.float64), sigma.shape)
    dt = jnp.asarray(dt_s, jnp.float64)
    z = jax.random.normal(key, (dt.shape[0] + 1,) + sigma.shape, jnp.float64)
    ratio = jnp.where(dt[:, None] == 0.0, 0.0, dt[:, None] / tau[None, :])  # dt/inf = 0
    phi = jnp.exp(-ratio)
    q = sigma * jnp.sqrt(jnp.clip(1.0 - phi * phi, 0.0, 1.0))
    x0 = sigma * z[0]

    def step(x, inputs):
        phi_k, q_k, z_k = inputs
        x_next = phi_k * x + q_k * z_k
        return x_next, x_next

    _, rest = lax.scan(step, x0, (phi, q, z[1:]))
    return jnp.concatenate([x0[None, :], rest], axis=0)


def gauss_markov_cell_means(key: jax.Array, sigma, tau_s, dt_s) -> jax.Array:
    """Independent first-order Gauss–Markov processes as their *means over each cell*
    (NOISE, exact in the cell integral; issue 24), shape (K+1, c): row k < K is
    ā_k = (1/dt_k) ∫ η over [t_k, t_k + dt_k], the last row η at the last node.

    Held over its cell, ā_k gives the cell's velocity change ∫ a η ds exactly (for a
    constant a over the cell) and the position change to O((dt/τ)²), where holding the
    node value η(t_k) is off by O(dt/τ) (a variance 3 % low at dt = τ/10).  Sampled jointly
    with the node values, exactly: given η_k, with φ = e^{−dt/τ}, x = dt/τ,

        E[η_{k+1}] = φ η_k,            Var = σ² (1 − φ²),
        E[ā_k]    = η_k (1 − φ) / x,    Var = σ² (2x − 2(1 − φ) − (1 − φ)²) / x²,
        Cov(ā_k, η_{k+1}) = σ² (1 − φ)² / x,

    drawn with the 2×2 Cholesky factor; started stationary.  σ = 0 gives zeros; τ = +inf
    (or dt = 0) a constant ā_k = η_k (φ = 1).  sigma, tau_s (c,); dt_s (K,) s ≥ 0."""
    sigma = jnp.asarray(sigma, jnp.float64)
    tau = jnp.broadcast_to(jnp.asarray(tau_s, jnp.float64), sigma.shape)
    dt = jnp.asarray(dt_s, jnp.float64)
    z = jax.random.normal(key, (2 * dt.shape[0] + 1,) + sigma.shape, jnp.float64)
    x = jnp.where(dt[:, None] == 0.0, 0.0, dt[:, None] / tau[None, :])  # (K, c); dt/inf = 0
    small = x < 1e-8
    xs = jnp.where(small, 1.0, x)
    om = -jnp.expm1(-xs)  # 1 - phi
    phi = 1.0 - om
    l11 = jnp.where(small, 0.0, sigma * jnp.sqrt(jnp.clip(om * (2.0 - om), 0.0, None)))  # sqrt(1 - phi^2)
    va = sigma**2 * jnp.clip(2.0 * xs - 2.0 * om - om * om, 0.0, None) / xs**2
    cae = sigma**2 * om * om / xs
    l21 = jnp.where(small | (l11 == 0.0), 0.0, cae / jnp.where(l11 == 0.0, 1.0, l11))
    l22 = jnp.where(small, 0.0, jnp.sqrt(jnp.clip(va - l21 * l21, 0.0, None)))
    mean_a = jnp.where(small, 1.0, om / xs)
    phi = jnp.where(small, 1.0, phi)
    x0 = sigma * z[0]

    def step(e, inputs):
        ph, ma, a11, a21, a22, z1, z2 = inputs
        e_next = ph * e + a11 * z1
        avg = ma * e + a21 * z1 + a22 * z2
        return e_next, (avg, e_next)

    e_last, (avgs, _) = lax.scan(step, x0, (phi, mean_a, l11, l21, l22, z[1::2], z[2::2]))
    return jnp.concatenate([avgs, e_last[None, :]], axis=0)


def rtn_matrix(r, v) -> jax.Array:
    """Rotation C (3×3) from RTN (= RIC: radial, transverse/in-track, normal/cross-track) to
    the inertial frame of r (km) and v (km/s): columns R = r/|r|, T = N × R,
    N = (r × v)/|r × v|, so x_inertial = C x_rtn and P_inertial = C P_rtn Cᵀ."""
    return hill_axes(jnp.asarray(r, jnp.float64), jnp.asarray(v, jnp.float64))[0].T  # Hill rows = RTN


def rotate_state_covariance(p, c) -> jax.Array:
    """G P Gᵀ with G = blockdiag(C, C, I): a state covariance P (n×n, n ≥ 6, ordered
    [r (km), v (km/s), ...]) rotated by C (3×3) on its position and velocity blocks, the
    remaining components unchanged (e.g. RTN to inertial with C = :func:`rtn_matrix`)."""
    p = jnp.asarray(p, jnp.float64)
    c = jnp.asarray(c, jnp.float64)
    n = p.shape[0]
    if n < 6:
        raise ValueError(f"rotate_state_covariance: P must be at least 6×6, got {p.shape}")
    g = jnp.eye(n).at[0:3, 0:3].set(c).at[3:6, 3:6].set(c)
    return g @ p @ g.T


def _perpendicular_pair(u):
    """Orthonormal e1, e2 perpendicular to a unit vector u, with (u, e1, e2) right-handed.

    e1 is the normalized rejection from u of the coordinate axis least aligned with u (x unless
    |u_x| > 0.9, then y): the rejection has norm ≥ √(1 − 0.9²) > 0.43, so no division by zero.
    """
    ex = jnp.array([1.0, 0.0, 0.0])
    ey = jnp.array([0.0, 1.0, 0.0])
    a = jnp.where(jnp.abs(u[0]) > 0.9, ey, ex)
    w = a - jnp.dot(a, u) * u
    e1 = w / jnp.linalg.norm(w)
    e2 = jnp.cross(u, e1)
    return e1, e2


def gates_error(key: jax.Array, dv, sigma_p, sigma_b1, sigma_b2, sigma_res) -> jax.Array:
    """One Gates (1963) execution error ε (3,) (km/s) of a commanded ΔV d = ``dv`` (3,) (km/s):

    ε = σ_p z₁ d + |d| (σ_β1 z₂ e₁ + σ_β2 z₃ e₂) + σ_res (z₄, z₅, z₆),

    proportionality σ_p (fraction), pointing angles σ_β1, σ_β2 (rad) about the orthonormal
    pair e₁, e₂ ⊥ d, resolution σ_res (km/s).  Given d, cov ε = σ_p² d dᵀ
    + |d|² (σ_β1² e₁e₁ᵀ + σ_β2² e₂e₂ᵀ) + σ_res² I, which is
    :func:`fracas.guidance.impulsive.gates_covariance` when σ_β1 = σ_β2 (that function
    averages the two about d otherwise).  d = 0 gives ε = σ_res z₄..₆ (finite, NaN-free).
    """
    d = jnp.asarray(dv, jnp.float64)
    z = jax.random.normal(key, (6,), jnp.float64)
    norm = jnp.linalg.norm(d)
    nonzero = norm > 0.0
    u = jnp.where(nonzero, d / jnp.where(nonzero, norm, 1.0), jnp.array([0.0, 0.0, 1.0]))
    e1, e2 = _perpendicular_pair(u)
    return sigma_p * z[0] * d + norm * (sigma_b1 * z[1] * e1 + sigma_b2 * z[2] * e2) + sigma_res * z[3:6]


def proportional_error(key: jax.Array, du, fraction) -> jax.Array:
    """Execution error of a low-thrust correction δU (M,): fraction × δU × z, z ~ N(0, I),
    independent per control, variance fraction² δU² (fraction scalar or (M,)); its average
    over δU ~ N(0, P_U) is :func:`fracas.guidance.low_thrust.execution_covariance` (no floor).
    Units: those of each control."""
    du = jnp.asarray(du, jnp.float64)
    return jnp.asarray(fraction, jnp.float64) * du * jax.random.normal(key, du.shape, jnp.float64)
