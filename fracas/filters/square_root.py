"""TEAM square-root filter algebra: the covariance is carried as P = W Wᵀ.

The optional square-root mode of the error analysis (Draper Doc. 4 §4.2 "filter-weighting
matrix" W, E = W Wᵀ; see the W-matrix digest §10).  Instead of integrating Doc. 4's
approximate W differential equation, each step here is an exact orthogonal triangularization
(QR) of a stacked factor, so W Wᵀ equals, to rounding, what the covariance-form functions of
:mod:`fracas.filters.covariance` give, while keeping W Wᵀ positive semidefinite by
construction:

* time update      [𝚽 W | Q^½]            -> W⁻       (FRACAS PROP eq. 1)
* measurement      [(I - K H) W | K R^½]  -> W⁺       (FRACAS FILTER eqs. 15-21, any gain)
* Kalman-Schmidt   F = H W, J = F Fᵀ + R, A = W Fᵀ, K = A J⁻¹ on the est rows (KSGAIN)
* Potter           scalar optimal update W⁺ = W - γ k zᵀ (digest §10.7, Lecture 23)

Same augmented layout [x, s, u, v, w] and units (km, km/s, kg, parameter units) as the
covariance form; W is (n, n), lower triangular except after :func:`potter_update`.  The WLS
non-consider covariance (n_est × n_est, no process noise) stays in covariance form: compute
the gain with :func:`fracas.filters.covariance.wls_gain` and apply it with
:func:`sqrt_joseph_update`.
"""

from __future__ import annotations

from functools import partial

import jax
import jax.numpy as jnp
from jax import lax
from jax.scipy.linalg import solve_triangular

from fracas import _jax  # noqa: F401  (float64 before any array exists)
from fracas.filters.covariance import Layout

__all__ = [
    "factor",
    "sqrt_time_update",
    "sqrt_kalman_schmidt_gain",
    "sqrt_joseph_update",
    "potter_update",
    "FACTOR_PIVOT_TOLERANCE",
]

#: In :func:`factor`, a pivot (conditional variance of a variable given the previous ones)
#: at or below FACTOR_PIVOT_TOLERANCE · n · P_jj is rounding noise of a semidefinite P: the
#: column is set to zero instead of dividing by its square root.  10 machine epsilons per
#: accumulated term is the rounding floor of the pivot's running sum.
FACTOR_PIVOT_TOLERANCE = 10.0 * 2.220446049250313e-16


def _tria(M: jax.Array) -> jax.Array:
    """Lower-triangular L (r, r) with L Lᵀ = M Mᵀ for M (r, c), c ≥ r, by QR of Mᵀ; the
    diagonal is made non-negative."""
    R = jnp.linalg.qr(M.T, mode="r")[: M.shape[0], :]
    L = R.T
    sgn = jnp.where(jnp.diag(L) < 0.0, -1.0, 1.0)
    return L * sgn[None, :]


@jax.jit
def factor(P: jax.Array) -> jax.Array:
    """Lower-triangular square root W (n, n), W Wᵀ = P, of a positive SEMI-definite P.

    Column-by-column Cholesky (outer-product form) in which a pivot d_j = P_jj - Σ_k<j W_jk²
    at or below :data:`FACTOR_PIVOT_TOLERANCE` · n · P_jj gives a zero column: zero-variance
    rows (a mass with zero a-priori sigma, the zero w block of an assumed covariance) come out
    exactly zero and linearly dependent variables do not divide by rounding noise.  An
    indefinite P is not flagged here (its negative pivots give zero columns); use
    :func:`fracas.filters.covariance.psd_check`.
    """
    P = 0.5 * (P + P.T)
    n = P.shape[0]
    rows = jnp.arange(n)
    diag = jnp.diag(P)

    def body(j, W):
        v = P[:, j] - W @ W[j, :]  # columns ≥ j of W are still zero
        d = v[j]
        keep = d > FACTOR_PIVOT_TOLERANCE * n * jnp.maximum(diag[j], 0.0)
        col = jnp.where(keep & (rows >= j), v / jnp.sqrt(jnp.where(keep, d, 1.0)), 0.0)
        return W.at[:, j].set(col)

    return lax.fori_loop(0, n, body, jnp.zeros((n, n), dtype=jnp.float64))


@jax.jit
def sqrt_time_update(W: jax.Array, phi_aug: jax.Array, Q: jax.Array) -> jax.Array:
    """Square-root time update (FRACAS PROP eq. 1 in factored form).

    W⁻ = tria([𝚽 W | Q^½]) with Q (nx, nx) the process noise on the x block (km², km²/s²,
    kg²; may be singular), Q^½ = :func:`factor` (Q) padded with zero rows.  Then
    W⁻ W⁻ᵀ = 𝚽 W Wᵀ 𝚽ᵀ + Q.  Returns lower-triangular W⁻ (n, n).
    """
    n, nx = W.shape[0], Q.shape[0]
    Sq = jnp.zeros((n, nx), dtype=jnp.float64).at[:nx, :].set(factor(Q))
    return _tria(jnp.concatenate([phi_aug @ W, Sq], axis=1))


@partial(jax.jit, static_argnames=("layout",))
def sqrt_kalman_schmidt_gain(W: jax.Array, H: jax.Array, R: jax.Array, layout: Layout) -> jax.Array:
    """Kalman-Schmidt gain from the factor (FRACAS KSGAIN with FILTER eqs. 1-6).

    F = H W (m, n), J = F Fᵀ + R, A = W Fᵀ; J's Cholesky factor L_J comes from the QR of
    [F | R^½] (never forming J), and K_est = A_est L_J⁻ᵀ L_J⁻¹ by two triangular solves.
    Returns K (n, m) with the u, v, w rows exactly zero.
    """
    F = H @ W
    L_J = _tria(jnp.concatenate([F, factor(R)], axis=1))
    A_est = W[layout.est] @ F.T
    X = solve_triangular(L_J, A_est.T, lower=True)
    K_est = solve_triangular(L_J.T, X, lower=False).T
    K = jnp.zeros((layout.n, H.shape[0]), dtype=jnp.float64)
    return K.at[layout.est].set(K_est)


@jax.jit
def sqrt_joseph_update(W: jax.Array, H: jax.Array, R: jax.Array, K: jax.Array) -> jax.Array:
    """Square-root measurement update for ANY gain K (n, m) (FRACAS FILTER eqs. 7-21).

    W⁺ = tria([(I - K H) W | K R^½]), so W⁺ W⁺ᵀ = (I - KH) P (I - KH)ᵀ + K R Kᵀ, the Joseph
    form of :func:`fracas.filters.covariance.joseph_update`: the assumed update with its own
    (KS or WLS) gain, or the true update with the assumed gain and true H, R.
    """
    n = W.shape[0]
    IKH = jnp.eye(n, dtype=jnp.float64) - K @ H
    return _tria(jnp.concatenate([IKH @ W, K @ factor(R)], axis=1))


def _potter_scalar(W: jax.Array, h: jax.Array, r: jax.Array) -> jax.Array:
    z = W.T @ h
    beta = z @ z + r
    k = (W @ z) / beta
    gamma = 1.0 / (1.0 + jnp.sqrt(r / beta))
    return W - gamma * jnp.outer(k, z)


@jax.jit
def potter_update(W: jax.Array, h: jax.Array, r: jax.Array) -> jax.Array:
    """Potter's square-root update for the optimal (Kalman) gain (digest §10.7, Battin's
    Lecture 23): with z = Wᵀh, β = zᵀz + r, k = W z / β, γ = 1 / (1 + √(r/β)),

        W⁺ = W - γ k zᵀ,   so   W⁺W⁺ᵀ = P - P h hᵀ P / β.

    ``h`` is (n,) with scalar variance ``r`` (measurement unit²), or (m, n) with ``r`` (m,),
    processed one scalar at a time, which equals the vector update only for a DIAGONAL
    measurement covariance diag(r).  Valid only where the gain is optimal for every row,
    i.e. with no consider or ignore parameters in W.  W⁺ is in general not triangular.
    """
    h = jnp.asarray(h, dtype=jnp.float64)
    r = jnp.asarray(r, dtype=jnp.float64)
    if h.ndim == 1:
        return _potter_scalar(W, h, r.reshape(()))
    r = jnp.broadcast_to(r.reshape(-1), (h.shape[0],))

    def step(Wc, hr):
        return _potter_scalar(Wc, hr[0], hr[1]), None

    W, _ = lax.scan(step, W, (h, r))
    return W
