"""Square-root mode (P = W Wᵀ) against the covariance mode and dense formulas.

Tolerances are in the scale-free metric max |ΔP_ij| / (σ_i σ_j) (σ from the reference
covariance), i.e. relative to each variance, which is stricter than relative to the largest
variance when units span decades.  Both modes are backward-stable orthogonal/Cholesky
algebra on well-conditioned (cond ≲ 1e3) matrices, so they agree to ~1e-14 per step; the
bound 1e-10 after a dozen mixed updates leaves room for accumulation while any algebra slip
(a missing K R Kᵀ, a transposed Φ) is O(1e-2) or larger.
"""

from __future__ import annotations

import numpy as np

from fracas.filters.covariance import (
    Layout,
    augmented_transition,
    joseph_update,
    kalman_schmidt_gain,
    time_update,
    wls_gain,
    wls_time_update,
)
from fracas.filters.square_root import (
    factor,
    potter_update,
    sqrt_joseph_update,
    sqrt_kalman_schmidt_gain,
    sqrt_time_update,
)
from tests.filters.helpers import f64, random_cov, scaled_err

TOL = 1e-10


def test_factor_of_semidefinite_covariance():
    rng = np.random.default_rng(11)
    L = Layout(7, 2, 2, 1, 2)
    scales = 10.0 ** rng.uniform(-2, 2, size=L.n)
    P = random_cov(rng, L.n, scales)
    # SPD: the unique positive-diagonal Cholesky factor (numpy reference), to rounding
    W = np.asarray(factor(f64(P)))
    Lc = np.linalg.cholesky(P)
    assert np.max(np.abs(W - Lc) / scales[:, None]) < 1e-13  # same algorithm up to order
    # zero mass variance (row 6) and the zero w block of an assumed covariance
    Pa = P.copy()
    zero = [6] + list(range(L.w.start, L.w.stop))
    Pa[zero, :] = 0.0
    Pa[:, zero] = 0.0
    W = np.asarray(factor(f64(Pa)))
    assert np.array_equal(W, np.tril(W))  # lower triangular, exactly
    assert not np.any(W[zero, :])  # zero rows stay exactly zero
    assert np.all(np.isfinite(W))
    assert scaled_err(W @ W.T, Pa, Pa) < 1e-13  # one factorization: rounding only
    # rank-deficient without zero rows: P = B Bᵀ, B (n, n-3) (linearly dependent variables)
    B = rng.normal(size=(L.n, L.n - 3)) * scales[:, None]
    Pr = B @ B.T
    W = np.asarray(factor(f64(Pr)))
    assert np.all(np.isfinite(W)) and np.array_equal(W, np.tril(W))
    # pivots at rounding level are dropped: the lost variance is ≤ n·10·eps of each variance,
    # and the error of the remaining entries stays at the conditioning of B's column space
    assert scaled_err(W @ W.T, Pr, Pr) < 1e-10
    assert np.linalg.matrix_rank(W, tol=1e-8 * np.abs(W).max()) == L.n - 3


def test_square_root_mode_equals_covariance_mode():
    """A dozen events on the true/assumed pair: time updates with singular Q, KS updates
    (gain from W), WLS-gain updates (non-consider covariance in covariance form), and the
    true covariance updated with the assumed gains (generalized covariance)."""
    rng = np.random.default_rng(12)
    L = Layout(7, 2, 2, 1, 2)
    n, nx, m = L.n, L.nx, 3
    scales = 10.0 ** rng.uniform(-1.5, 1.5, size=n)
    phi = np.eye(nx) + 0.2 * rng.normal(size=(nx, nx))
    phi[6, :6] = 0.0  # mass does not depend on position/velocity
    theta = rng.normal(size=(nx, n - nx)) * 0.5 * scales[:nx, None] / scales[None, nx:]
    F = augmented_transition(f64(phi), f64(theta), L)
    Bq = rng.normal(size=(nx, 3)) * scales[:nx, None]
    Bq[:3] = 0.0
    Q_a = 0.05 * Bq @ Bq.T  # rank 3: velocity/mass noise only
    Q_t = 2.0 * Q_a
    P_t = random_cov(rng, n, scales)
    P_a = random_cov(rng, n, 0.8 * scales)
    for P in (P_t, P_a):
        P[6, :] = 0.0  # zero a-priori mass sigma
        P[:, 6] = 0.0
    P_a[L.w, :] = 0.0
    P_a[:, L.w] = 0.0
    R_a = random_cov(rng, m) * 0.2
    R_t = 1.5 * R_a
    Pnc = f64(P_a[L.est, L.est])
    P_a, P_t = f64(P_a), f64(P_t)
    W_a, W_t = factor(P_a), factor(P_t)
    for k in range(12):
        P_a, P_t = time_update(P_a, F, f64(Q_a)), time_update(P_t, F, f64(Q_t))
        W_a, W_t = sqrt_time_update(W_a, F, f64(Q_a)), sqrt_time_update(W_t, F, f64(Q_t))
        Pnc = wls_time_update(Pnc, F, L)
        assert scaled_err(W_a @ W_a.T, P_a, P_a) < TOL
        assert scaled_err(W_t @ W_t.T, P_t, P_t) < TOL
        H = f64(rng.normal(size=(m, n)) / scales[None, :])
        if k % 3 == 2:  # WLS-gain event (same gain in both modes)
            K, Pnc = wls_gain(Pnc, H, f64(R_a), L)
        else:  # Kalman-Schmidt event, gain from each mode's own factor
            K = kalman_schmidt_gain(P_a, H, f64(R_a), L)
            K_sqrt = sqrt_kalman_schmidt_gain(W_a, H, f64(R_a), L)
            gs = np.sqrt(np.abs(np.diag(np.asarray(P_a))))[:, None] + 1e-300
            assert np.max(np.abs(np.asarray(K_sqrt - K)) / gs) < TOL
            assert not np.any(np.asarray(K_sqrt)[L.n_est :])
            Pnc = wls_gain(Pnc, H, f64(R_a), L)[1]
        P_a = joseph_update(P_a, H, f64(R_a), K)
        P_t = joseph_update(P_t, H, f64(R_t), K)  # generalized: assumed gain, true R
        W_a = sqrt_joseph_update(W_a, H, f64(R_a), K)
        W_t = sqrt_joseph_update(W_t, H, f64(R_t), K)
        for W, P in ((W_a, P_a), (W_t, P_t)):
            Wn = np.asarray(W)
            assert np.array_equal(Wn, np.tril(Wn))
            assert scaled_err(Wn @ Wn.T, P, P) < TOL
    # the assumed w block stayed exactly zero in square-root form
    assert not np.any(np.asarray(W_a)[L.w, :])


def test_potter_equals_kalman_update():
    """Potter (scalar, sequential over a diagonal R) = the vector Kalman update, and the
    scalar case = the dense formula P - P h hᵀ P / (hᵀ P h + r) (digest §10.7)."""
    rng = np.random.default_rng(13)
    L = Layout(6, 2, 0, 0, 0)  # no consider/ignore: the KS gain is the Kalman gain
    scales = 10.0 ** rng.uniform(-1.5, 1.5, size=L.n)
    P = random_cov(rng, L.n, scales)
    H = rng.normal(size=(3, L.n)) / scales[None, :]
    r = np.array([0.3, 0.05, 1.2])
    W = factor(f64(P))
    Wp = np.asarray(potter_update(W, f64(H), f64(r)))
    K = kalman_schmidt_gain(f64(P), f64(H), f64(np.diag(r)), L)
    Pk = np.asarray(joseph_update(f64(P), f64(H), f64(np.diag(r)), K))
    # three rank-one downdates vs one Joseph update: rounding ~1e-15 relative to the prior
    assert scaled_err(Wp @ Wp.T, Pk, P) < 1e-12
    h = H[0]
    Ws = np.asarray(potter_update(W, f64(h), f64(r[0])))
    ref = P - np.outer(P @ h, P @ h) / (h @ P @ h + r[0])
    assert scaled_err(Ws @ Ws.T, ref, P) < 1e-12
