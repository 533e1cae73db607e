"""Statistical and batch references for the TEAM filter algebra on a small LINEAR system.

A 4-state linear system with solve-for (s), dynamic consider (u), measurement consider (v)
and, for generalized covariance, ignore (w) parameters; random but well-conditioned
Φ (a matrix exponential of a near-skew matrix), Θ and H (two measurements per epoch, H
changes every epoch), 20 measurement epochs.  The Monte Carlo runs the ACTUAL estimator
(truth and estimate propagated and updated separately, numpy, fixed seed) and compares the
sample covariance of its errors with the covariance recursion of ``fracas.filters``.

Statistical bounds (errors have known zero mean, so N samples give N degrees of freedom):
* each variance: N·s²/σ² ~ χ²(N); the ratio s²/σ² must lie in the central 99.9% interval;
* the whole matrix: the likelihood-ratio statistic for H0: Σ = P with known zero mean,
  N·[tr(P⁻¹S) - ln det(P⁻¹S) - p], is asymptotically χ²(p(p+1)/2) (Anderson, An
  Introduction to Multivariate Statistical Analysis, §10.8; the Bartlett correction is
  O(p²/N) < 1% here); it must lie below the 99.9% quantile.
With a fixed seed the outcome is deterministic; for a random seed each check would fail a
correct implementation with probability 1e-3.  With N = 4000 the variance interval is
about ±7%, so a covariance that is 10% off anywhere is rejected, as the negative controls
(mis-modelled predictions that must be rejected) show.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from scipy.linalg import expm
from scipy.stats import chi2

from fracas.filters.covariance import (
    Layout,
    augmented_transition,
    joseph_update,
    kalman_schmidt_gain,
    time_update,
    wls_gain,
    wls_time_update,
)
from tests.filters.helpers import f64, random_cov

N_RUNS = 4000
N_EPOCHS = 20
M_MEAS = 2
CONF = 0.999


def linear_system(rng, L):
    """Φ, Θ (v columns dropped by augmented_transition), per-epoch H, R and Q."""
    nx, n = L.nx, L.n
    A = rng.normal(size=(nx, nx))
    phi = expm(0.4 * (A - A.T) + 0.05 * rng.normal(size=(nx, nx)))  # |eig| ~ 1, cond ~ 1
    theta = 0.4 * rng.normal(size=(nx, n - nx))
    F = np.asarray(augmented_transition(f64(phi), f64(theta), L))
    Hs = [0.8 * rng.normal(size=(M_MEAS, n)) for _ in range(N_EPOCHS)]
    R = random_cov(rng, M_MEAS, 0.3)
    Q = random_cov(rng, nx, 0.15)
    return F, Hs, R, Q


def covariance_run(L, F, Hs, P0, Q, R, gains=None):
    """Covariance recursion; KS gains of this run unless ``gains`` (assumed) are given.
    Returns the list of post-update covariances and the gains used."""
    P = f64(P0)
    out, used = [], []
    for k, H in enumerate(Hs):
        P = time_update(P, f64(F), f64(Q))
        K = kalman_schmidt_gain(P, f64(H), f64(R), L) if gains is None else gains[k]
        P = joseph_update(P, f64(H), f64(R), K)
        out.append(np.asarray(P))
        used.append(K)
    return out, used


def monte_carlo(rng, L, F, Hs, gains, P0, Q, R):
    """The estimator itself on N_RUNS simulated truths.  Returns, per epoch, the (N, n)
    augmented error [x - x̂, s - ŝ, u, v, w] (consider/ignore estimates stay at their zero
    mean)."""
    est, nx = L.est, L.nx
    Z = rng.normal(size=(N_RUNS, L.n)) @ np.linalg.cholesky(P0).T  # truth, a-priori
    zh = np.zeros((N_RUNS, L.n_est))  # estimate starts at the a-priori mean (0)
    Lq, Lr = np.linalg.cholesky(Q), np.linalg.cholesky(R)
    F_est = F[est, est]
    errs = []
    for H, K in zip(Hs, gains):
        K = np.asarray(K)
        Z = Z @ F.T
        Z[:, :nx] += rng.normal(size=(N_RUNS, nx)) @ Lq.T  # process noise
        zh = zh @ F_est.T  # filter prediction (u at its mean)
        y = Z @ H.T + rng.normal(size=(N_RUNS, M_MEAS)) @ Lr.T  # measurements
        zh = zh + (y - zh @ H[:, est].T) @ K[est].T
        e = Z.copy()
        e[:, est] -= zh
        errs.append(e)
    return errs


def lr_statistic(err, P):
    """Likelihood-ratio statistic for Σ = P, known zero mean, and its χ² dof."""
    N, p = err.shape
    S = err.T @ err / N
    M = np.linalg.solve(P, S)
    return N * (np.trace(M) - np.linalg.slogdet(M)[1] - p), p * (p + 1) // 2


def variance_ratios(err, P):
    return np.mean(err**2, axis=0) / np.diag(P)


def variance_interval(N):
    a = (1.0 - CONF) / 2.0
    return chi2.ppf(a, N) / N, chi2.ppf(1.0 - a, N) / N


def test_kalman_schmidt_covariance_matches_monte_carlo():
    """(a) Schmidt covariance = sample covariance of the Schmidt estimator's errors, with
    sampled a-priori state, dynamic and measurement consider parameters, white measurement
    noise and process noise."""
    rng = np.random.default_rng(20240601)
    L = Layout(4, 2, 2, 1, 0)
    F, Hs, R, Q = linear_system(rng, L)
    P0 = random_cov(rng, L.n)  # full correlations, including est-consider
    Ps, gains = covariance_run(L, F, Hs, P0, Q, R)
    errs = monte_carlo(rng, L, F, Hs, gains, P0, Q, R)
    lo, hi = variance_interval(N_RUNS)
    for k in (N_EPOCHS // 2 - 1, N_EPOCHS - 1):
        ratios = variance_ratios(errs[k][:, L.est], Ps[k][L.est, L.est])
        assert np.all((lo < ratios) & (ratios < hi)), (k, ratios, lo, hi)
        stat, dof = lr_statistic(errs[k][:, L.est], Ps[k][L.est, L.est])
        assert stat < chi2.ppf(CONF, dof), (k, stat, dof)
        # whole augmented matrix, so the cross-covariances C_xu, C_xv, C_su, C_sv are tested
        stat, dof = lr_statistic(errs[k], Ps[k])
        assert stat < chi2.ppf(CONF, dof), (k, stat, dof)

    # Negative control (the test can fail): a prediction that leaves out the consider
    # parameters' effect (u, v rows/columns of the a-priori zeroed, same gains) is rejected.
    P0_nc = P0.copy()
    P0_nc[L.n_est :, :] = 0.0
    P0_nc[:, L.n_est :] = 0.0
    Ps_nc, _ = covariance_run(L, F, Hs, P0_nc, Q, R, gains=gains)
    stat, dof = lr_statistic(errs[-1][:, L.est], Ps_nc[-1][L.est, L.est])
    assert stat > 10 * chi2.ppf(CONF, dof), stat
    # and so is one without process noise
    Ps_q0, _ = covariance_run(L, F, Hs, P0, 0.0 * Q, R, gains=gains)
    stat, dof = lr_statistic(errs[-1][:, L.est], Ps_q0[-1][L.est, L.est])
    assert stat > 10 * chi2.ppf(CONF, dof), stat


def test_generalized_true_covariance_matches_mis_modelled_filter():
    """(b) Generalized covariance: the filter assumes a wrong a-priori, a 3x smaller process
    noise, a 2x smaller measurement noise and knows nothing of one ignore parameter w.  The
    TRUE covariance (true statistics, assumed gains, joseph_update with true R) matches the
    Monte Carlo of that filter; the ASSUMED covariance does not."""
    rng = np.random.default_rng(19720401)
    L = Layout(4, 2, 2, 1, 1)
    F, Hs, R_a, Q_a = linear_system(rng, L)
    P0_a = random_cov(rng, L.n)
    P0_a[L.w, :] = 0.0
    P0_a[:, L.w] = 0.0
    P0_t = random_cov(rng, L.n, 1.4)  # other correlations, 1.4x sigmas, and w with sigma 1.4
    Q_t, R_t = 3.0 * Q_a, 2.0 * R_a
    Ps_a, gains = covariance_run(L, F, Hs, P0_a, Q_a, R_a)
    Ps_t, _ = covariance_run(L, F, Hs, P0_t, Q_t, R_t, gains=gains)
    errs = monte_carlo(rng, L, F, Hs, gains, P0_t, Q_t, R_t)
    lo, hi = variance_interval(N_RUNS)
    for k in (N_EPOCHS // 2 - 1, N_EPOCHS - 1):
        ratios = variance_ratios(errs[k], Ps_t[k])
        assert np.all((lo < ratios) & (ratios < hi)), (k, ratios, lo, hi)
        stat, dof = lr_statistic(errs[k], Ps_t[k])  # full matrix, including C_xw, C_sw
        assert stat < chi2.ppf(CONF, dof), (k, stat, dof)
    # the assumed covariance visibly fails the same tests
    e = errs[-1][:, L.est]
    ratios_a = variance_ratios(e, Ps_a[-1][L.est, L.est])
    assert np.any((ratios_a < lo) | (ratios_a > hi)), ratios_a
    stat, dof = lr_statistic(e, Ps_a[-1][L.est, L.est])
    assert stat > 10 * chi2.ppf(CONF, dof), stat


def test_sequential_wls_equals_batch_least_squares():
    """(c) No process noise: sequential WLS (WLSGAN) = batch weighted least squares with the
    a-priori as a pseudo-measurement, both the non-consider covariance and the consider
    (knowledge) covariance, at the final epoch."""
    rng = np.random.default_rng(7)
    L = Layout(4, 2, 2, 1, 1)
    F, Hs, R, _ = linear_system(rng, L)
    P0 = random_cov(rng, L.n)  # est-consider correlations a-priori included
    est, con = L.est, slice(L.n_est, L.n)

    # sequential
    P, Pnc = f64(P0), f64(P0[est, est])
    Q0 = jnp.zeros((L.nx, L.nx), dtype=jnp.float64)
    for H in Hs:
        P = time_update(P, f64(F), Q0)
        Pnc = wls_time_update(Pnc, f64(F), L)
        K, Pnc = wls_gain(Pnc, f64(H), f64(R), L)
        P = joseph_update(P, f64(H), f64(R), K)
    P, Pnc = np.asarray(P), np.asarray(Pnc)

    # batch: y_k = H_k Ψ_k z0 + ε_k, Ψ_k = F^k; estimate z0_est, consider treated at mean 0.
    Ri = np.linalg.inv(R)
    Psi = np.eye(L.n)
    Lam = np.linalg.inv(P0[est, est])
    G = np.zeros((L.n_est, L.n - L.n_est))
    rows = []
    for H in Hs:
        Psi = F @ Psi
        A = (H @ Psi)[:, est]
        C = (H @ Psi)[:, con]
        Lam += A.T @ Ri @ A
        G += A.T @ Ri @ C
        rows.append(A)
    Lam_inv = np.linalg.inv(Lam)
    # epoch-0 error e0 = Λ⁻¹[P0_ee⁻¹ δz_est - G δz_con - Σ A_kᵀ R⁻¹ ε_k]; map to t_K with Ψ_K
    M = Lam_inv @ np.hstack([np.linalg.inv(P0[est, est]), -G])
    T = np.zeros((L.n, L.n))
    T[est, :] = Psi[est, est] @ M
    T[est, con] += Psi[est, con]
    T[con, con] = np.eye(L.n - L.n_est)
    P_batch = T @ P0 @ T.T
    for A in rows:
        Nk = Psi[est, est] @ Lam_inv @ A.T @ Ri
        P_batch[est, est] += Nk @ R @ Nk.T
    Pnc_batch = Psi[est, est] @ Lam_inv @ Psi[est, est].T

    # Tolerance 1e-9 (scale-free, relative to each variance): the batch side inverts Λ
    # (cond ~3e2) and the sequential side accumulates 20 Joseph updates, so both carry
    # rounding of ~1e-14 (measured 6e-15); 1e-9 leaves margin for other platforms while any
    # algebra slip is O(1e-2) or more.
    d = np.sqrt(np.diag(P_batch))
    assert np.max(np.abs(P - P_batch) / np.outer(d, d)) < 1e-9
    dn = np.sqrt(np.diag(Pnc_batch))
    assert np.max(np.abs(Pnc - Pnc_batch) / np.outer(dn, dn)) < 1e-9
    # the consider covariance really differs from the non-consider one (test not vacuous)
    assert np.max(np.abs(P[est, est] - Pnc) / np.outer(dn, dn)) > 1e-2
