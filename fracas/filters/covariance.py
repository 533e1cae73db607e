"""TEAM covariance-form filter algebra: augmented transition, time update, Kalman-Schmidt,
sequential weighted least squares and the general (any-gain) measurement update.

Pure JAX functions of arrays (float64), jit-compiled, no I/O and no Python control flow on
values.  The event schedule (which update when, true vs assumed pass) lives in ``fracas/team``.

Augmented state, in this order (FRACAS PROP eq. 2)::

    z = [x, s, u, v, w]
        x  dynamic state, nx = 6 (r km, v km/s) or 7 (+ mass kg while thrust acts)
        s  solve-for parameters            (estimated)
        u  dynamic consider parameters     (affect the dynamics, not estimated)
        v  measurement consider parameters (affect the measurements, not estimated)
        w  ignore parameters               (only in the TRUE covariance)

    P = [[P     C_xs  C_xu  C_xv  C_xw],
         [.     P_s   C_su  C_sv  C_sw],
         [.     .     U_o   C_uv  C_uw],
         [.     .     .     V_o   C_vw],
         [.     .     .     .     W_o ]]

Units follow the state: km, km/s, kg for x; each parameter's own unit for s, u, v, w.

Generalized covariance analysis (FRACAS CØVP/FILTER remarks) is done by the caller with two
matrices of the SAME layout: the ASSUMED covariance has its w rows and columns zero, the TRUE
one carries w.  Every function here works on both; nothing special-cases ignore parameters
beyond their zero blocks.  The gains come from the assumed pass and are applied to the true
covariance with :func:`joseph_update` (FRACAS FILTER eqs. 15-21).

The report's block equations (NASA CR-112256 §5.3.4 FILTER, §5.3.13 PROP, §5.3.24 WLSGAN)
are implemented here as the equivalent full-matrix products; ``tests/filters/test_covariance.py``
implements the blocks literally and checks the equivalence.  Several scanned equations are
garbled and were rebuilt there (listed in that test's module docstring).
"""

from __future__ import annotations

from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax.scipy.linalg import cho_factor, cho_solve

from fracas import _jax  # noqa: F401  (float64 before any array exists)

__all__ = [
    "Layout",
    "augmented_transition",
    "time_update",
    "innovation",
    "kalman_schmidt_gain",
    "joseph_update",
    "wls_time_update",
    "wls_gain",
    "psd_check",
    "correlations",
    "PSD_TOLERANCE",
]

#: ``psd_check`` flags a covariance when the smallest eigenvalue of its scale-free
#: (correlation-normalised) form is below ``-PSD_TOLERANCE``.  1e-6 is ~5e9 machine epsilons:
#: a measurement update that shrinks a variance by up to ~10 orders of magnitude produces
#: rounding-level negative eigenvalues well inside it, while a genuine loss of definiteness
#: (an implied |correlation| > 1 + 1e-6) is caught.
PSD_TOLERANCE = 1.0e-6


class Layout(NamedTuple):
    """Sizes of the augmented-state blocks [x, s, u, v, w] (hashable: a jit static argument)."""

    nx: int
    ns: int
    nu: int
    nv: int
    nw: int

    @property
    def n(self) -> int:
        """Total augmented dimension nx + ns + nu + nv + nw."""
        return self.nx + self.ns + self.nu + self.nv + self.nw

    @property
    def n_est(self) -> int:
        """Estimated dimension nx + ns (state and solve-for parameters)."""
        return self.nx + self.ns

    @property
    def x(self) -> slice:
        return slice(0, self.nx)

    @property
    def s(self) -> slice:
        return slice(self.nx, self.nx + self.ns)

    @property
    def u(self) -> slice:
        a = self.nx + self.ns
        return slice(a, a + self.nu)

    @property
    def v(self) -> slice:
        a = self.nx + self.ns + self.nu
        return slice(a, a + self.nv)

    @property
    def w(self) -> slice:
        a = self.nx + self.ns + self.nu + self.nv
        return slice(a, a + self.nw)

    @property
    def est(self) -> slice:
        return slice(0, self.nx + self.ns)


def _sym(P: jax.Array) -> jax.Array:
    return 0.5 * (P + P.T)


@partial(jax.jit, static_argnames=("layout",))
def augmented_transition(phi: jax.Array, theta: jax.Array, layout: Layout) -> jax.Array:
    """Augmented transition matrix (FRACAS PTRAN / PROP eq. 3), shape (n, n)::

        [[Φ  Θ_xs  Θ_xu  0  Θ_xw],
         [0  I     0     0  0   ],
         ...                     ]
         [0  0     0     0  I   ]]

    ``phi`` (nx, nx) is the state transition matrix ∂x(t_k+1)/∂x(t_k) (units km, km/s, kg);
    ``theta`` (nx, ns+nu+nv+nw) the parameter sensitivities ∂x(t_k+1)/∂p, columns in layout
    order s, u, v, w.  Its v columns are ignored (set to zero): the state does not depend on
    measurement parameters over a transition.  Parameters are constants (identity rows).
    """
    nx, n = layout.nx, layout.n
    if phi.shape != (nx, nx) or theta.shape != (nx, n - nx):
        raise ValueError(f"phi {phi.shape} / theta {theta.shape} do not fit layout {layout}")
    theta = jnp.asarray(theta, dtype=jnp.float64)
    v0, v1 = layout.v.start - nx, layout.v.stop - nx
    theta = theta.at[:, v0:v1].set(0.0)
    top = jnp.concatenate([jnp.asarray(phi, dtype=jnp.float64), theta], axis=1)
    bottom = jnp.concatenate([jnp.zeros((n - nx, nx), dtype=jnp.float64), jnp.eye(n - nx, dtype=jnp.float64)], axis=1)
    return jnp.concatenate([top, bottom], axis=0)


@jax.jit
def time_update(P: jax.Array, phi_aug: jax.Array, Q: jax.Array) -> jax.Array:
    """Covariance time update P⁻(k+1) = 𝚽 P⁺(k) 𝚽ᵀ + Q̃ (FRACAS PROP eqs. 1-16).

    ``P`` (n, n) augmented covariance at t_k, ``phi_aug`` (n, n) from
    :func:`augmented_transition`, ``Q`` (nx, nx) process noise over the interval (km², km²/s²,
    kg² blocks; e.g. from DYNO), added to the x block only (PROP eq. 4).  The full product is
    PROP eqs. 5-16 in matrix form.  Returns the symmetrized (n, n) covariance at t_k+1.
    """
    nx = Q.shape[0]
    P = phi_aug @ P @ phi_aug.T
    P = P.at[:nx, :nx].add(Q)
    return _sym(P)


@jax.jit
def innovation(P: jax.Array, H: jax.Array, R: jax.Array) -> tuple[jax.Array, jax.Array]:
    """Cross-covariance and residual covariance (FRACAS FILTER eqs. 1-6).

    ``H`` (m, n) = [H_x H_s H_u H_v H_w] (measurement units per state unit), ``R`` (m, m) the
    measurement white-noise covariance.  Returns ``A_all = P Hᵀ`` (n, m), whose row blocks
    x, s, u, v, w are FILTER's A, B, D, E, F (eqs. 2-6), and ``J = H P Hᵀ + R`` (m, m,
    eq. 1, symmetrized).
    """
    A_all = P @ H.T
    J = _sym(H @ A_all + R)
    return A_all, J


@partial(jax.jit, static_argnames=("layout",))
def kalman_schmidt_gain(P: jax.Array, H: jax.Array, R: jax.Array, layout: Layout) -> jax.Array:
    """Kalman-Schmidt gain (FRACAS KSGAIN): K_x = A J⁻¹, K_s = B J⁻¹ with A, B, J from
    FILTER eqs. 1-3.

    Returns K (n, m); the u, v, w rows are exactly zero (consider and ignore parameters are
    not estimated).  J⁻¹ is applied by a Cholesky solve; a J that is not positive definite
    gives non-finite gains, which :func:`psd_check` on the updated covariance reports.
    """
    A_all, J = innovation(P, H, R)
    c = cho_factor(J, lower=True)
    K_est = cho_solve(c, A_all[layout.est].T).T
    K = jnp.zeros((layout.n, H.shape[0]), dtype=jnp.float64)
    return K.at[layout.est].set(K_est)


@jax.jit
def joseph_update(P: jax.Array, H: jax.Array, R: jax.Array, K: jax.Array) -> jax.Array:
    """Measurement update for ANY gain K (n, m) (FRACAS FILTER eqs. 7-21)::

        P⁺ = (I - K H) P⁻ (I - K H)ᵀ + K R Kᵀ  =  P⁻ - K Aᵀ - A Kᵀ + K J Kᵀ.

    With the u, v, w rows of K zero this is, block by block, FILTER eqs. 15-17 (x-x, x-s, s-s),
    eqs. 9, 10, 12, 13 (C_xu, C_xv, C_su, C_sv), eq. 14 and 20-21 (consider/ignore blocks
    unchanged) and eqs. 18-19 (C_xw, C_sw).  For the Kalman-Schmidt gain of this same P it
    reduces to eqs. 7-14.  Used for the assumed covariance (own gain) and for the true
    covariance (assumed gain, true H and R).  Returns the symmetrized (n, n) covariance.
    """
    n = P.shape[0]
    IKH = jnp.eye(n, dtype=jnp.float64) - K @ H
    return _sym(IKH @ P @ IKH.T + K @ R @ K.T)


@partial(jax.jit, static_argnames=("layout",))
def wls_time_update(P_nc: jax.Array, phi_aug: jax.Array, layout: Layout) -> jax.Array:
    """Propagate the WLS non-consider covariance (FRACAS WLSGAN eqs. 1-3).

    ``P_nc`` (n_est, n_est) is the covariance of [x, s] that the sequential weighted least
    squares filter would have if it ignored consider parameters; no process noise enters it.
    P_nc⁻ = 𝚽_est P_nc⁺ 𝚽_estᵀ with 𝚽_est = [[Φ Θ_xs],[0 I]] the est block of ``phi_aug``.
    """
    F = phi_aug[layout.est, layout.est]
    return _sym(F @ P_nc @ F.T)


@partial(jax.jit, static_argnames=("layout",))
def wls_gain(P_nc: jax.Array, H: jax.Array, R: jax.Array, layout: Layout) -> tuple[jax.Array, jax.Array]:
    """Sequential weighted-least-squares gain and non-consider update (FRACAS WLSGAN eqs. 4-11).

    A, B = P_nc [H_x H_s]ᵀ (eqs. 4-5), J = H_est A + R (eq. 6), K_x, K_s = A J⁻¹, B J⁻¹
    (eqs. 7-8, Cholesky solve).  The non-consider update (eqs. 9-11, P⁺ = P⁻ - K Aᵀ) is
    evaluated in the algebraically equal Joseph form for numerical robustness.
    Returns (K (n, m) zero outside the est rows, P_nc⁺ (n_est, n_est)).  The knowledge
    covariance is then updated with this K by :func:`joseph_update` (FILTER eqs. 15-21).
    """
    H_est = H[:, layout.est]
    A = P_nc @ H_est.T
    J = _sym(H_est @ A + R)
    c = cho_factor(J, lower=True)
    K_est = cho_solve(c, A.T).T
    P_plus = joseph_update(P_nc, H_est, R, K_est)
    K = jnp.zeros((layout.n, H.shape[0]), dtype=jnp.float64)
    return K.at[layout.est].set(K_est), P_plus


@jax.jit
def psd_check(P: jax.Array) -> tuple[jax.Array, jax.Array]:
    """Positive-semidefiniteness check of a covariance (n, n).

    Returns ``(min_eigenvalue, ok)``: the smallest eigenvalue of P itself (mixed units; for
    reporting) and ``ok`` False when P has non-finite entries, a negative variance below
    -PSD_TOLERANCE · max variance, or the scale-free matrix D^-1/2 P D^-1/2 (D = diag P, zero
    variances scaled by 1) has an eigenvalue below -:data:`PSD_TOLERANCE`.  The scale-free
    test is unit-independent, so a small badly-determined parameter is judged on its own scale.
    Eigendecomposition: call per event only where definiteness must be watched.
    """
    finite = jnp.all(jnp.isfinite(P))
    Ps = jnp.where(jnp.isfinite(P), _sym(P), 0.0)
    d = jnp.diag(Ps)
    dmax = jnp.max(jnp.abs(d))
    scale = jnp.where(d > 0.0, jnp.sqrt(jnp.where(d > 0.0, d, 1.0)), 1.0)
    S = Ps / jnp.outer(scale, scale)
    min_eig = jnp.min(jnp.linalg.eigvalsh(Ps))
    min_scaled = jnp.min(jnp.linalg.eigvalsh(S))
    ok = finite & (min_scaled >= -PSD_TOLERANCE) & jnp.all(d >= -PSD_TOLERANCE * dmax)
    min_eig = jnp.where(finite, min_eig, jnp.nan)
    return min_eig, ok


@jax.jit
def correlations(P: jax.Array) -> tuple[jax.Array, jax.Array]:
    """Standard deviations and correlation coefficients (FRACAS PRINT/GPRINT output).

    Returns ``sigma`` (n,) = sqrt(max(diag P, 0)) in each state's unit and ``corr`` (n, n) =
    P_ij / (σ_i σ_j), unit diagonal; rows/columns of zero variance give zero correlations
    (not NaN).  Values are not clipped, so |corr| > 1 shows a covariance that lost
    definiteness.
    """
    sigma = jnp.sqrt(jnp.maximum(jnp.diag(P), 0.0))
    pos = sigma > 0.0
    inv = jnp.where(pos, 1.0 / jnp.where(pos, sigma, 1.0), 0.0)
    corr = P * jnp.outer(inv, inv)
    i = jnp.arange(P.shape[0])
    corr = corr.at[i, i].set(pos.astype(jnp.float64))
    return sigma, corr
