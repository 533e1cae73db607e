"""TSIM random draws (fracas.tsim.sampling) against references this code did not produce.

References: the defining second moments of each model (Gauss–Markov σ² exp(−|Δt|/τ), the
covariance P of CSAMP, Gates's covariance as written independently in
fracas.guidance.impulsive.gates_covariance, low-thrust execution_covariance), geometry by hand
(RTN frame), and bitwise equality of draws (RNUM).

Monte Carlo bounds use fixed keys (deterministic) and are set at ~5σ of the estimator's known
sampling distribution, so a correct implementation fails with probability < 1e-4 per test even
counting all the checks in it (union bound), while errors of a few SE show:
* a variance estimated from N draws of known zero mean: N s²/σ² ~ χ²(N), two-sided 1e-7 quantiles;
* a correlation E[xy]/σ² from N pairs of correlation ρ: SE = sqrt((1 + ρ²)/N);
* a full covariance: the likelihood-ratio (Wishart) test of fracas.tsim.statistics, p > 1e-4
  (false alarm 1e-4), plus each variance within 5 sqrt(2/N) relative.
All functions are traced once (vmap over keys), never in a loop.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import stats

from fracas.guidance.impulsive import gates_covariance
from fracas.guidance.low_thrust import execution_covariance
from fracas.tsim import sampling as sp
from fracas.tsim import statistics as ts

N_GM = 4000
N_MC = 20000


def _keys(seed, n, stream=sp.STREAM_INITIAL):
    idx = jnp.arange(n)
    return jax.vmap(lambda i: sp.stream_key(sp.mission_key(seed, i), stream))(idx)


def _cov(sigmas, seed):
    rng = np.random.default_rng(seed)
    q, r = np.linalg.qr(rng.standard_normal((len(sigmas), len(sigmas))))
    q = q * np.sign(np.diag(r))
    return q @ np.diag(np.square(sigmas)) @ q.T


# ---------------------------------------------------------------- Gauss–Markov noise (NOISE)

_GM = jax.jit(jax.vmap(sp.gauss_markov, in_axes=(0, None, None, None)))
SIGMA_GM = np.array([1.0, 2.5])  # e.g. km/s² of an acceleration noise: any unit
TAU_GM = np.array([50.0, 50.0])  # s, τ = 5 dt


def _check_gm(x, sigma, t):
    """Variance σ² at every node (χ² bounds) and lag-1, lag-5 correlations exp(−Δt/τ) (5 SE)."""
    n = x.shape[0]
    lo, hi = stats.chi2.ppf(1e-7, n) / n, stats.chi2.isf(1e-7, n) / n
    v = np.mean(x**2, axis=0) / sigma**2  # (K+1, c)
    assert np.all((v > lo) & (v < hi)), (v.min(), v.max(), lo, hi)
    for lag in (1, 5):
        r = np.mean(x[:, lag:] * x[:, :-lag], axis=0) / sigma**2  # (K+1-lag, c)
        rho = np.exp(-(t[lag:] - t[:-lag])[:, None] / TAU_GM[None, :])
        se = np.sqrt((1.0 + rho**2) / n)
        assert np.all(np.abs(r - rho) < 5.0 * se), np.max(np.abs(r - rho) / se)


def test_gauss_markov_regular_steps():
    """K = 60 steps of 10 s, τ = 50 s, N = 4000 paths: stationary variance and the exponential
    autocorrelation (bounds in the module docstring; 122 + 236 checks, union false alarm < 1e-4)."""
    dt = np.full(60, 10.0)
    x = np.asarray(_GM(_keys(1, N_GM, sp.STREAM_NOISE), SIGMA_GM, TAU_GM, dt))
    assert x.shape == (N_GM, 61, 2) and x.dtype == np.float64
    _check_gm(x, SIGMA_GM, np.concatenate([[0.0], np.cumsum(dt)]))


def test_gauss_markov_irregular_steps_and_zero_steps():
    """Steps uniform in [0, 20] s with two zero steps: same moments with Δt = t_j − t_i
    (the exact discretization holds for any step); a zero step repeats the value exactly."""
    dt = np.random.default_rng(5).uniform(0.0, 20.0, 60)
    dt[[5, 30]] = 0.0
    x = np.asarray(_GM(_keys(2, N_GM, sp.STREAM_NOISE), SIGMA_GM, TAU_GM, dt))
    _check_gm(x, SIGMA_GM, np.concatenate([[0.0], np.cumsum(dt)]))
    np.testing.assert_array_equal(x[:, 6], x[:, 5])
    np.testing.assert_array_equal(x[:, 31], x[:, 30])


def test_gauss_markov_zero_sigma_and_infinite_tau():
    """σ = 0 gives exactly zeros; τ = inf (φ = 1 exactly) gives a constant path whose value
    has variance σ² (χ² bound as above)."""
    dt = np.full(60, 10.0)
    sigma = np.array([0.0, 2.5])
    x = np.asarray(_GM(_keys(3, N_GM, sp.STREAM_NOISE), sigma, np.array([50.0, np.inf]), dt))
    assert np.all(x[..., 0] == 0.0)
    np.testing.assert_array_equal(x[:, :, 1], np.broadcast_to(x[:, :1, 1], (N_GM, 61)))
    v = np.mean(x[:, 0, 1] ** 2) / 2.5**2
    assert stats.chi2.ppf(1e-7, N_GM) / N_GM < v < stats.chi2.isf(1e-7, N_GM) / N_GM


_GM_MEANS = jax.jit(jax.vmap(sp.gauss_markov_cell_means, in_axes=(0, None, None, None)))


def test_gauss_markov_cell_means_against_the_integrated_process():
    """Cell means (issue 24): the running integral I(t_j) = sum_k a_k dt_k over irregular
    steps (dt/tau from 0 to 0.8, a zero step) has the exact variance of the integrated
    process, 2 sigma^2 tau^2 (T/tau - 1 + e^{-T/tau}) at every node, and the last row (eta at
    the last node) the stationary sigma^2 with its exact covariance with I(T),
    sigma^2 tau (1 - e^{-T/tau}) (chi^2 bounds and 5 SE, as above).  Holding the node value
    instead over-states I's variance by (computed exactly from the discrete sum) 0.1 % at
    dt = tau/10, 2.7 % at tau/2, 10 % at tau and 40 % at 2 tau (a deck's noise_step_days);
    at dt = tau this test's statistic rejects it."""
    dt = np.random.default_rng(9).uniform(0.0, 40.0, 40)
    dt[7] = 0.0
    tau = TAU_GM
    x = np.asarray(_GM_MEANS(_keys(4, N_MC, sp.STREAM_NOISE), SIGMA_GM, tau, dt))
    assert x.shape == (N_MC, 41, 2)
    integral = np.cumsum(x[:, :-1] * dt[None, :, None], axis=1)  # (N, K, c)
    T = np.cumsum(dt)[:, None]
    var = 2.0 * SIGMA_GM**2 * tau**2 * (T / tau - 1.0 + np.exp(-T / tau))
    lo, hi = stats.chi2.ppf(1e-7, N_MC) / N_MC, stats.chi2.isf(1e-7, N_MC) / N_MC
    r = np.mean(integral**2, axis=0) / var
    assert np.all((r > lo) & (r < hi)), (r.min(), r.max(), lo, hi)
    v_end = np.mean(x[:, -1] ** 2, axis=0) / SIGMA_GM**2
    assert np.all((v_end > lo) & (v_end < hi))
    c = SIGMA_GM**2 * tau * (1.0 - np.exp(-T[-1] / tau))
    rho = c / np.sqrt(var[-1] * SIGMA_GM**2)
    got = np.mean(integral[:, -1] * x[:, -1], axis=0) / np.sqrt(var[-1] * SIGMA_GM**2)
    assert np.all(np.abs(got - rho) < 5.0 * np.sqrt((1.0 + rho**2) / N_MC))
    # the node-held process on steps of tau is detectably wrong (the reason for cell means)
    held = np.asarray(_GM(_keys(4, N_MC, sp.STREAM_NOISE), SIGMA_GM, tau, np.full(8, 50.0)))
    ih = np.sum(held[:, :-1] * 50.0, axis=1)
    Th = 400.0
    vh = 2.0 * SIGMA_GM**2 * tau**2 * (Th / tau - 1.0 + np.exp(-Th / tau))
    assert np.all(np.mean(ih**2, axis=0) / vh > hi)


def test_gauss_markov_cell_means_degenerate():
    """sigma = 0: zeros; tau = inf: every mean equals the constant value."""
    x = np.asarray(
        _GM_MEANS(_keys(5, 64, sp.STREAM_NOISE), np.array([0.0, 2.5]), np.array([50.0, np.inf]), np.full(10, 10.0))
    )
    assert np.all(x[..., 0] == 0.0)
    np.testing.assert_allclose(x[:, :, 1], np.broadcast_to(x[:, :1, 1], (64, 11)), rtol=1e-15)


# ---------------------------------------------------------------- covariance sampling (CSAMP)

_SAMPLE = jax.jit(jax.vmap(sp.sample_normal, in_axes=(0, None)))
_SCALE = np.diag([1.0, 1.0, 1.0, 1e-3, 1e-3, 1e-3])  # km, km/s
P6 = _SCALE @ _cov((5.0, 2.0, 1.0, 0.5, 0.2, 0.05), 17) @ _SCALE


def _check_csamp(x, p, dof):
    s = np.cov(x.T)
    stat, d, pval = ts.covariance_test(s, x.shape[0], p)
    assert d == dof and pval > 1e-4, (stat, d, pval)
    keep = np.diag(p) > 0
    rel = np.diag(s)[keep] / np.diag(p)[keep] - 1.0
    assert np.all(np.abs(rel) < 5.0 * np.sqrt(2.0 / x.shape[0])), rel


def test_covariance_factor_reproduces_p():
    """L Lᵀ = P to rounding (1e-13 relative to max |P|) for both methods; Cholesky refuses a
    singular P; a slightly indefinite P is clipped (L Lᵀ = R max(Λ, 0) Rᵀ computed here)."""
    for method in ("eigen", "cholesky"):
        f = sp.covariance_factor(P6, method)
        np.testing.assert_allclose(f @ f.T, P6, rtol=0, atol=1e-13 * np.abs(P6).max())
    b = np.random.default_rng(9).standard_normal((6, 4))
    with pytest.raises(ValueError, match="positive definite"):
        sp.covariance_factor(b @ b.T, "cholesky")
    with pytest.raises(ValueError):
        sp.covariance_factor(P6, "svd")
    lam, vec = np.linalg.eigh(P6)
    lam[0] = -1e-3 * lam[-1]
    indef = (vec * lam) @ vec.T
    f = sp.covariance_factor(indef)
    clipped = (vec * np.maximum(lam, 0.0)) @ vec.T
    np.testing.assert_allclose(f @ f.T, clipped, rtol=0, atol=1e-13 * np.abs(P6).max())


def test_csamp_full_rank():
    """N = 20000 draws of a correlated 6×6 P (km, km/s scales): Wishart LR test p > 1e-4 on
    21 dof and every variance within 5 sqrt(2/N) = 5 % relative."""
    x = np.asarray(_SAMPLE(_keys(4, N_MC), sp.covariance_factor(P6)))
    _check_csamp(x, P6, 21)


def test_csamp_singular():
    """Rank-4 P, two ways.  (a) P = B Bᵀ (B 6×4, no zero diagonal): the LR test on P's range
    (10 dof) passes and the spread along the null space of Bᵀ is rounding (< 1e-12 of the
    spread in the range).  (b) components 2 and 5 with zero variance: their samples are exactly
    zero, the others match P (same bounds)."""
    b = _SCALE @ np.random.default_rng(23).standard_normal((6, 4))
    pa = b @ b.T
    x = np.asarray(_SAMPLE(_keys(5, N_MC), sp.covariance_factor(pa)))
    _check_csamp(x, pa, 10)
    null = np.linalg.svd(b.T)[2][4:]  # (2, 6) rows spanning the null space of Bᵀ
    assert np.abs(x @ null.T).max() < 1e-12 * np.abs(x).max()

    pb = P6.copy()
    pb[[2, 5], :] = 0.0
    pb[:, [2, 5]] = 0.0
    x = np.asarray(_SAMPLE(_keys(6, N_MC), sp.covariance_factor(pb)))
    assert np.all(x[:, [2, 5]] == 0.0)
    _check_csamp(x, pb, 10)


# ---------------------------------------------------------------- execution errors

_GATES = jax.jit(jax.vmap(sp.gates_error, in_axes=(0, None, None, None, None, None)))
DV = np.array([3e-3, -4e-3, 1.2e-2])  # km/s (13 m/s)


def test_gates_error_matches_gates_covariance():
    """σ_β1 = σ_β2: the Monte Carlo covariance of N = 20000 errors against the independent
    gates_covariance (LR test p > 1e-4, 6 dof; variances within 5 sqrt(2/N)) and zero mean
    (χ² test p > 1e-4)."""
    args = (0.02, 0.03, 0.03, 1e-4)  # σ_p, σ_β1, σ_β2 (rad), σ_res (km/s): all visible at 13 m/s
    eps = np.asarray(_GATES(_keys(7, N_MC, sp.STREAM_EXECUTION), DV, *args))
    ref = np.asarray(gates_covariance(DV, *args))
    _check_csamp(eps, ref, 6)
    assert ts.mean_test(eps.mean(axis=0), N_MC, ref)[2] > 1e-4


def test_gates_error_unequal_pointing():
    """σ_β1 ≠ σ_β2: along d the variance is σ_p²|d|² + σ_res²; across d the two eigenvalues are
    |d|²σ_β1² + σ_res² and |d|²σ_β2² + σ_res² (two orthogonal pointing axes ⊥ d); each sample
    variance/eigenvalue within 5 sqrt(2/N) relative (eigenvalues 9:1 apart, so their sampling
    bias ~ λ₂/(N(λ₁ − λ₂)) is negligible)."""
    sp_, sb1, sb2, sres = 0.02, 0.03, 0.01, 1e-4
    eps = np.asarray(_GATES(_keys(8, N_MC, sp.STREAM_EXECUTION), DV, sp_, sb1, sb2, sres))
    d2 = DV @ DV
    u = DV / np.sqrt(d2)
    tol = 5.0 * np.sqrt(2.0 / N_MC)
    along = np.var(eps @ u, ddof=1)
    assert along == pytest.approx(sp_**2 * d2 + sres**2, rel=tol)
    e1, e2 = np.linalg.svd(u[None, :])[2][1:]  # any basis of the plane ⊥ d
    perp = np.cov(np.stack([eps @ e1, eps @ e2]))
    lam = np.sort(np.linalg.eigvalsh(perp))
    np.testing.assert_allclose(lam, np.sort([d2 * sb1**2 + sres**2, d2 * sb2**2 + sres**2]), rtol=tol)
    # the trace is gates_covariance's (which averages σ_β² about d)
    np.testing.assert_allclose(np.trace(np.cov(eps.T)), np.trace(gates_covariance(DV, sp_, sb1, sb2, sres)), rtol=tol)


def test_gates_error_zero_dv_is_finite():
    """d = 0: ε = σ_res z (no NaN from normalizing d); its variances σ_res² (χ² bounds as above)."""
    eps = np.asarray(_GATES(_keys(9, N_MC, sp.STREAM_EXECUTION), np.zeros(3), 0.02, 0.03, 0.03, 1e-4))
    assert np.all(np.isfinite(eps))
    v = np.mean(eps**2, axis=0) / 1e-8
    assert np.all((v > stats.chi2.ppf(1e-7, N_MC) / N_MC) & (v < stats.chi2.isf(1e-7, N_MC) / N_MC))


@pytest.mark.parametrize("u", [[1.0, 0, 0], [-1.0, 0, 0], [0, 1.0, 0], [0, 0, -1.0], [0.6, 0.8, 0], [0.91, 0.3, 0.2]])
def test_perpendicular_pair(u):
    """(u, e1, e2) orthonormal and right-handed for axes and near the branch |u_x| = 0.9."""
    u = np.asarray(u) / np.linalg.norm(u)
    e1, e2 = (np.asarray(e) for e in sp._perpendicular_pair(jnp.asarray(u)))
    m = np.stack([u, e1, e2], axis=1)
    np.testing.assert_allclose(m.T @ m, np.eye(3), atol=1e-15)
    assert np.linalg.det(m) == pytest.approx(1.0, abs=1e-14)


def test_proportional_error_matches_execution_covariance():
    """Low thrust: the error of δU ~ N(0, P_U) (δU drawn per sample) against
    execution_covariance(P_U, fraction) = diag(fraction² diag P_U) (independent reference in
    fracas.guidance.low_thrust).  The error f δU z is a Gaussian scale mixture, not Gaussian
    (E ε⁴ = 9 (f² P)²), so the bounds are its own: var(s²)/σ⁴ = 8/N, variances within
    5 sqrt(8/N) = 10 sqrt(2/N); a correlation of the uncorrelated components ε_i, ε_j has
    var = (1 + 2ρ_ij²)/N (ρ_ij that of δU), so |r| < 5 sqrt((1 + 2ρ²)/N).  Given δU, the error
    is exactly fraction × δU × z (same key, same z)."""
    controls = ("proportionality", "alpha", "beta", "t_on", "t_off")
    p_u = _cov((1e-3, 2e-2, 1e-2, 50.0, 20.0), 29)
    frac = np.array([0.01, 0.02, 0.02, 0.005, 0.005])
    f = sp.covariance_factor(p_u)

    def draw(key):
        du = sp.sample_normal(jax.random.fold_in(key, 0), f)
        return sp.proportional_error(jax.random.fold_in(key, 1), du, frac)

    eps = np.asarray(jax.jit(jax.vmap(draw))(_keys(10, N_MC, sp.STREAM_EXECUTION)))
    ref = np.asarray(execution_covariance(controls, p_u, frac))
    s = np.cov(eps.T)
    np.testing.assert_allclose(np.diag(s) / np.diag(ref), 1.0, atol=10.0 * np.sqrt(2.0 / N_MC))
    r = s / np.sqrt(np.outer(np.diag(s), np.diag(s)))
    rho = p_u / np.sqrt(np.outer(np.diag(p_u), np.diag(p_u)))
    iu = np.triu_indices(5, 1)
    assert np.all(np.abs(r[iu]) < 5.0 * np.sqrt((1.0 + 2.0 * rho[iu] ** 2) / N_MC))
    du = np.array([1.0, -2.0, 0.0, 3.0, 4.0])
    z = np.asarray(jax.random.normal(jax.random.PRNGKey(0), (5,), jnp.float64))
    np.testing.assert_array_equal(np.asarray(sp.proportional_error(jax.random.PRNGKey(0), du, frac)), frac * du * z)


# ---------------------------------------------------------------- RTN frame

R0 = np.array([7000.0, -1200.0, 3000.0])  # km
V0 = np.array([1.1, 6.8, -2.0])  # km/s


def test_rtn_matrix_geometry():
    """Columns by hand: R = r/|r|, N ∥ r × v, T = N × R, orthonormal and right-handed, and T
    along the motion (T·v > 0 for any non-radial v)."""
    c = np.asarray(sp.rtn_matrix(R0, V0))
    np.testing.assert_allclose(c.T @ c, np.eye(3), atol=1e-15)
    assert np.linalg.det(c) == pytest.approx(1.0, abs=1e-14)
    np.testing.assert_allclose(c[:, 0], R0 / np.linalg.norm(R0), rtol=1e-15)
    h = np.cross(R0, V0)
    np.testing.assert_allclose(c[:, 2], h / np.linalg.norm(h), rtol=1e-14)
    assert c[:, 1] @ V0 > 0 and abs(c[:, 1] @ R0) < 1e-10
    np.testing.assert_allclose(c @ [1.0, 0.0, 0.0], R0 / np.linalg.norm(R0), rtol=1e-15)


def test_pure_radial_covariance_stays_radial():
    """Peer bug "1 km RIC covariance producing 2 km along Z": a 1 km² pure-R covariance mapped
    to inertial has trace 1 km² (rotation invariant), its one nonzero eigenvalue 1 with
    eigenvector ±r/|r|, i.e. it is r̂ r̂ᵀ; velocity and a 7th (carried) component untouched."""
    c = sp.rtn_matrix(R0, V0)
    p = np.zeros((7, 7))
    p[0, 0] = 1.0
    p[6, 6] = 0.25
    pi = np.asarray(sp.rotate_state_covariance(p, c))
    rhat = R0 / np.linalg.norm(R0)
    assert np.trace(pi[:3, :3]) == pytest.approx(1.0, rel=1e-14)
    lam, vec = np.linalg.eigh(pi[:3, :3])
    np.testing.assert_allclose(lam, [0.0, 0.0, 1.0], atol=1e-14)
    assert abs(vec[:, 2] @ rhat) == pytest.approx(1.0, abs=1e-14)
    np.testing.assert_allclose(pi[:3, :3], np.outer(rhat, rhat), atol=1e-15)
    assert not pi[3:6].any() and pi[6, 6] == 0.25
    # a general RTN covariance: trace preserved and back-rotation recovers it
    q = _cov((1.0, 3.0, 0.5, 1e-3, 2e-3, 1e-4), 31)
    qi = np.asarray(sp.rotate_state_covariance(q, c))
    assert np.trace(qi[:3, :3]) == pytest.approx(np.trace(q[:3, :3]), rel=1e-13)
    np.testing.assert_allclose(np.asarray(sp.rotate_state_covariance(qi, c.T)), q, atol=1e-14)


# ---------------------------------------------------------------- random-number streams (RNUM)


def test_mission_draws_independent_of_batch():
    """RNUM: mission i's normal draws (initial state, knowledge, a maneuver's execution error)
    are bitwise the same in a jitted vmap batch of 17 missions, of 3, and computed alone;
    streams and maneuver indices differ.  Values computed from the draws (L z, Gates's error)
    are compared to a few ulp, not bitwise: XLA may sum a batched matmul or fuse (FMA) in
    another order than for a single mission, an ulp-level difference of arithmetic only."""
    f = sp.covariance_factor(P6)

    def mission(i):
        key = sp.mission_key(1234, i)
        z = jnp.concatenate(
            [
                jax.random.normal(sp.stream_key(key, sp.STREAM_INITIAL), (6,), jnp.float64),
                jax.random.normal(sp.stream_key(key, sp.STREAM_KNOWLEDGE, 2), (3,), jnp.float64),
                jax.random.normal(sp.stream_key(key, sp.STREAM_EXECUTION, 2), (6,), jnp.float64),
            ]
        )
        x0 = sp.sample_normal(sp.stream_key(key, sp.STREAM_INITIAL), f)
        ex = sp.gates_error(sp.stream_key(key, sp.STREAM_EXECUTION, 2), DV, 0.02, 0.03, 0.03, 1e-4)
        return z, jnp.concatenate([x0, ex])

    batch = jax.jit(jax.vmap(mission))
    z17, y17 = (np.asarray(a) for a in batch(jnp.arange(17)))
    z3, y3 = (np.asarray(a) for a in batch(jnp.array([11, 2, 16])))
    z1, y1 = (np.asarray(a) for a in jax.jit(mission)(5))
    np.testing.assert_array_equal(z3, z17[[11, 2, 16]])
    np.testing.assert_array_equal(z1, z17[5])
    assert len({row.tobytes() for row in z17}) == 17
    scale = np.abs(y17).max(axis=0)
    assert np.all(np.abs(y3 - y17[[11, 2, 16]]) <= 1e-14 * scale)
    assert np.all(np.abs(y1 - y17[5]) <= 1e-14 * scale)
    np.testing.assert_allclose(y17[:, :6], z17[:, :6] @ np.asarray(f).T, rtol=1e-13, atol=1e-15 * scale[:3].max())
    k = sp.mission_key(1234, 0)
    a, b = (
        np.asarray(jax.random.normal(sp.stream_key(k, s), (3,))) for s in (sp.STREAM_KNOWLEDGE, sp.STREAM_EXECUTION)
    )
    assert not np.array_equal(a, b)
    assert not np.array_equal(
        np.asarray(jax.random.normal(sp.stream_key(k, sp.STREAM_EXECUTION, 0), (3,))),
        np.asarray(jax.random.normal(sp.stream_key(k, sp.STREAM_EXECUTION, 1), (3,))),
    )
