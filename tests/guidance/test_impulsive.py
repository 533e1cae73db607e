"""Impulsive guidance (fracas.guidance.impulsive) against references this code did not produce.

* Γ: numpy.linalg.solve (square), an explicit Lagrangian (KKT) solve and scipy.optimize
  SLSQP (under-determined, weighted minimum norm), numpy.linalg.lstsq (over-determined).
  Tolerances 1e-10 relative for the linear-algebra references (condition numbers here are
  < 1e3, so rounding is < 1e-12); 1e-6 for SLSQP (its own ftol 1e-14 on a unit-scale cost).
* Monte Carlo (N = 20,000, seeded): the errors are sampled with the covariance structure of
  each model of digest §B.3, the guidance law ΔV = −Γ δX̂ and Gates execution errors are
  applied sample by sample with numpy written here, and every element of the sample
  covariance (zero-mean, S = XᵀX/N) is required within 4 standard deviations of the
  prediction Σ, where Var S_ij = (Σ_ii Σ_jj + Σ_ij²)/N for Gaussian data.  The execution
  errors make ΔV⁺ non-Gaussian (products of Gaussians); their fourth moments are larger, so
  for covariances that contain them the bound uses the sample's own variance of x_i x_j.
  Negative controls use the wrong model and must break the bound.
"""

from __future__ import annotations

import jax
import numpy as np
import pytest
from scipy import optimize

from fracas.guidance import impulsive as gi

N = 20_000


def _spd(rng, n, scales):
    a = rng.standard_normal((n, n))
    q, _ = np.linalg.qr(a)
    d = np.diag(scales) @ q
    return d @ d.T + np.diag(np.square(scales)) * 0.1


def _psi(rng, m, n=6):
    # targets of km scale: ∂T/∂r ~ 1, ∂T/∂v ~ 1e4 s (a few hours to go)
    psi = rng.standard_normal((m, n))
    psi[:, 3:6] *= 1.0e4
    return psi


SCALES = np.array([10.0, 8.0, 12.0, 0.01, 0.012, 0.008])  # km, km/s


def _bound_gauss(s, sigma, n, k=4.0):
    var = (np.outer(np.diag(sigma), np.diag(sigma)) + sigma**2) / n
    return np.abs(s - sigma) <= k * np.sqrt(var)


def _bound_sample(x, sigma, k=4.0):
    n = x.shape[0]
    prod = x[:, :, None] * x[:, None, :]
    s = prod.mean(axis=0)
    sd = prod.std(axis=0, ddof=1) / np.sqrt(n)
    return np.abs(s - sigma) <= k * sd


def _cov0(x):
    return x.T @ x / x.shape[0]


def _gates_samples(rng, d, sp, sb, sr):
    """ε given commanded d, sampled directly: along-d proportionality, two pointing angles
    about orthonormal axes across d, isotropic resolution (written here, not from fracas)."""
    dn = np.linalg.norm(d, axis=1, keepdims=True)
    u = d / dn
    helper = np.where(np.abs(u[:, :1]) < 0.9, np.array([[1.0, 0.0, 0.0]]), np.array([[0.0, 1.0, 0.0]]))
    e1 = np.cross(u, helper)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    e2 = np.cross(u, e1)
    g = rng.standard_normal((d.shape[0], 6))
    return sp * g[:, :1] * d + sb * dn * (g[:, 1:2] * e1 + g[:, 2:3] * e2) + sr * g[:, 3:6]


# ---------------------------------------------------------------- Γ


def test_square_exact():
    rng = np.random.default_rng(1)
    psi = _psi(rng, 3)
    g = gi.guidance_matrix(psi, weights=[1.0, 5.0, 0.2], tolerances=[1.0, 2.0, 3.0])
    ref = np.linalg.solve(psi[:, 3:6], psi)
    np.testing.assert_allclose(np.asarray(g.gamma), ref, rtol=1e-10, atol=1e-10 * np.abs(ref).max())
    assert int(g.rank) == 3
    np.testing.assert_allclose(psi[:, 3:6] @ np.asarray(g.gamma), psi, rtol=1e-10, atol=1e-10 * np.abs(psi).max())


def test_underdetermined_weighted_min_norm():
    rng = np.random.default_rng(2)
    psi = _psi(rng, 2)
    w = np.array([1.0, 4.0, 0.25])
    g = gi.guidance_matrix(psi, weights=w)
    gamma = np.asarray(g.gamma)
    assert int(g.rank) == 2
    psv = psi[:, 3:6]
    # explicit Lagrangian: min Σ ΔV_i²/w_i s.t. Ψ_v ΔV = −Ψ δX, for every unit δX
    kkt = np.block([[2.0 * np.diag(1.0 / w), psv.T], [psv, np.zeros((2, 2))]])
    rhs = np.vstack([np.zeros((3, 6)), -psi])
    ref = -np.linalg.solve(kkt, rhs)[:3]
    np.testing.assert_allclose(gamma, ref, rtol=1e-10, atol=1e-10 * np.abs(ref).max())
    np.testing.assert_allclose(psv @ gamma, psi, rtol=1e-10, atol=1e-10 * np.abs(psi).max())
    # scipy.optimize on one deviation
    dx = rng.standard_normal(6) * SCALES
    target = -psi @ dx
    scale = np.abs(gamma @ dx).max()
    res = optimize.minimize(
        lambda v: np.sum(v**2 / w),
        np.zeros(3),
        method="SLSQP",
        constraints={"type": "eq", "fun": lambda v: (psv @ (v * scale) - target) / np.abs(target).max()},
        options={"ftol": 1e-14, "maxiter": 500},
    )
    assert res.success
    np.testing.assert_allclose(res.x * scale, -gamma @ dx, rtol=1e-6, atol=1e-6 * scale)
    # the weights change the split: unweighted differs
    g1 = np.asarray(gi.guidance_matrix(psi).gamma)
    assert np.abs(g1 - gamma).max() > 1e-3 * np.abs(gamma).max()


def test_overdetermined_least_squares():
    rng = np.random.default_rng(3)
    psi = _psi(rng, 5)
    g = gi.guidance_matrix(psi)
    assert int(g.rank) == 3
    ref = np.linalg.lstsq(psi[:, 3:6], psi, rcond=None)[0]
    np.testing.assert_allclose(np.asarray(g.gamma), ref, rtol=1e-10, atol=1e-10 * np.abs(ref).max())
    tol = np.array([1.0, 0.1, 10.0, 2.0, 0.5])
    gw = gi.guidance_matrix(psi, weights=[3.0, 1.0, 1.0], tolerances=tol)  # weights drop out
    refw = np.linalg.lstsq(psi[:, 3:6] / tol[:, None], psi / tol[:, None], rcond=None)[0]
    np.testing.assert_allclose(np.asarray(gw.gamma), refw, rtol=1e-10, atol=1e-10 * np.abs(refw).max())


def test_rank_deficient_and_jit_vmap():
    rng = np.random.default_rng(4)
    psi = _psi(rng, 3)
    psi[2, 3:6] = 2.0 * psi[0, 3:6] - psi[1, 3:6]  # ΔV cannot move one target combination
    g = gi.guidance_matrix(psi)
    assert int(g.rank) == 2
    ref = np.linalg.lstsq(psi[:, 3:6], psi, rcond=1e-12)[0]  # minimum-norm least squares
    np.testing.assert_allclose(np.asarray(g.gamma), ref, rtol=1e-8, atol=1e-8 * np.abs(ref).max())
    batch = np.stack([_psi(rng, 3) for _ in range(4)])
    gb = jax.jit(jax.vmap(gi.guidance_matrix))(batch)
    for k in range(4):
        np.testing.assert_allclose(
            np.asarray(gb.gamma[k]), np.linalg.solve(batch[k, :, 3:6], batch[k]), rtol=1e-9, atol=1e-12
        )


# ---------------------------------------------------------------- covariances


def test_gates_closed_form():
    d = np.array([0.0, 0.0, 0.02])
    c = np.asarray(gi.gates_covariance(d, 0.01, 0.007, 0.007, 1e-5))
    side = (0.007 * 0.02) ** 2 + 1e-10
    np.testing.assert_allclose(c, np.diag([side, side, (0.01 * 0.02) ** 2 + 1e-10]), rtol=1e-12)
    p = np.diag([1e-4, 4e-4, 9e-4])
    ex = np.asarray(gi.execution_error_covariance(np.zeros(3), p, 0.01, 0.005, 0.009, 0.0))
    sb2 = 0.5 * (0.005**2 + 0.009**2)
    np.testing.assert_allclose(ex, 1e-4 * p + sb2 * (np.trace(p) * np.eye(3) - p), rtol=1e-12)


def test_square_identity_g1():
    rng = np.random.default_rng(5)
    psi = _psi(rng, 3)
    p_k = _spd(rng, 6, 0.5 * SCALES)
    p_c = p_k + _spd(rng, 6, SCALES)
    gamma = np.asarray(gi.guidance_matrix(psi).gamma)
    b = np.asarray(gi.velocity_selector(6))
    np.testing.assert_allclose(psi @ (np.eye(6) - b @ gamma), 0.0, atol=1e-9 * np.abs(psi).max())
    p_dv = gi.dv_covariance(gamma, gi.estimate_deviation_covariance(p_c, p_k))
    sx = gi.execution_error_covariance(np.array([0.01, 0.0, 0.0]), p_dv)
    ref = psi @ (p_k + b @ np.asarray(sx) @ b.T) @ psi.T
    for mode in ("report", "orthogonal", "tsim"):
        pt = np.asarray(gi.target_covariance(psi, gi.post_guidance_covariance(p_c, p_k, gamma, sx, mode)))
        np.testing.assert_allclose(pt, ref, rtol=1e-8, atol=1e-10 * np.abs(ref).max())


def test_report_post_covariance_blocks():
    rng = np.random.default_rng(6)
    n = 8  # 6 state + 2 parameters
    p_k = _spd(rng, n, np.r_[0.5 * SCALES, 1.0, 2.0])
    p_c = p_k + _spd(rng, n, np.r_[SCALES, 1.0, 2.0])
    gamma = np.asarray(gi.guidance_matrix(_psi(rng, 3, n)).gamma)
    sx = np.diag([1e-8, 2e-8, 3e-8])
    out = np.asarray(gi.post_guidance_covariance(p_c, p_k, gamma, sx, "report", n_state=6))
    expect = p_c.copy()
    expect[:6, :] = p_k[:6, :]
    expect[:, :6] = p_k[:, :6]
    expect[3:6, 3:6] += sx
    np.testing.assert_allclose(out, expect, rtol=1e-14)
    assert np.allclose(out[6:, 6:], p_c[6:, 6:])
    assert jax.jit(gi.post_guidance_covariance, static_argnames=("mode", "n_state"))(
        p_c, p_k, gamma, sx, mode="orthogonal"
    ).shape == (n, n)
    with pytest.raises(ValueError):
        gi.estimate_deviation_covariance(p_c, p_k, "tracked")
    with pytest.raises(ValueError):
        gi.estimate_deviation_covariance(p_c, p_k, "bogus")


def _sample_model(rng, mode, p_k, p_other):
    """Return (δX, e, P_c, C_xe) with the structure of the mode (digest §B.3)."""
    e = rng.multivariate_normal(np.zeros(6), p_k, size=N)
    if mode == "orthogonal":  # δX̂ independent of e; δX = δX̂ + e
        xhat = rng.multivariate_normal(np.zeros(6), p_other, size=N)
        return xhat + e, e, p_other + p_k, p_k
    if mode == "tsim":  # δX independent of e
        return rng.multivariate_normal(np.zeros(6), p_other, size=N), e, p_other, np.zeros((6, 6))
    # tracked: δX = M e + f, f independent
    m = 0.3 * rng.standard_normal((6, 6)) * (SCALES[:, None] / SCALES[None, :])
    f = rng.multivariate_normal(np.zeros(6), p_other, size=N)
    return e @ m.T + f, e, m @ p_k @ m.T + p_other, m @ p_k


@pytest.mark.parametrize("mode", ["orthogonal", "tsim", "tracked"])
@pytest.mark.parametrize("m_targets", [3, 2])
def test_monte_carlo(mode, m_targets):
    rng = np.random.default_rng(100 + 10 * m_targets + len(mode))
    psi = _psi(rng, m_targets)
    p_k = _spd(rng, 6, 0.6 * SCALES)
    p_other = _spd(rng, 6, SCALES)
    dx, e, p_c, cxe = _sample_model(rng, mode, p_k, p_other)
    xhat = dx - e

    # guidance law, written here: Γ from solve / the unweighted minimum-norm formula
    psv = psi[:, 3:6]
    gamma_t = np.linalg.solve(psv, psi) if m_targets == 3 else psv.T @ np.linalg.solve(psv @ psv.T, psi)
    dv = -xhat @ gamma_t.T

    gamma = np.asarray(gi.guidance_matrix(psi).gamma)
    np.testing.assert_allclose(gamma, gamma_t, rtol=1e-9, atol=1e-9 * np.abs(gamma_t).max())
    p_tilde = gi.estimate_deviation_covariance(p_c, p_k, mode, cross=cxe if mode == "tracked" else None)
    p_dv = np.asarray(gi.dv_covariance(gamma, p_tilde))
    assert _bound_gauss(_cov0(dv), p_dv, N).all(), (mode, _cov0(dv), p_dv)

    # negative control: the report's P̃ = P_c is wrong for these structures
    p_dv_report = np.asarray(gi.dv_covariance(gamma, gi.estimate_deviation_covariance(p_c, p_k, "report")))
    assert not _bound_gauss(_cov0(dv), p_dv_report, N).all()

    # execution errors on the commanded ΔV = d₀ + ΔV (large σ so that they show)
    d0 = np.array([0.3, -0.1, 0.2]) * np.sqrt(np.trace(p_dv))
    sp, sb, sr = 0.05, 0.04, 0.2 * np.sqrt(np.trace(p_dv) / 3)
    eps = _gates_samples(rng, d0 + dv, sp, sb, sr)
    sx = np.asarray(gi.execution_error_covariance(d0, p_dv, sp, sb, sb, sr))
    assert _bound_sample(eps, sx).all()

    # post-maneuver state: δX⁺ = δX + B(ΔV + ε) (the nominal d₀ is in the reference)
    b = np.zeros((6, 3))
    b[3:6] = np.eye(3)
    dx_plus = dx + (dv + eps) @ b.T
    p_plus = np.asarray(
        gi.post_guidance_covariance(p_c, p_k, gamma, sx, mode, cross=cxe if mode == "tracked" else None)
    )
    assert _bound_sample(dx_plus, p_plus).all(), mode
    miss = dx_plus @ psi.T
    pt = np.asarray(gi.target_covariance(psi, p_plus))
    assert _bound_sample(miss, pt).all()
    # negative controls: no execution errors; the report's reset to the knowledge (m = 2 only:
    # for three targets it is exact in target space, digest G1)
    p_noex = np.asarray(gi.post_guidance_covariance(p_c, p_k, gamma, np.zeros((3, 3)), mode, cross=cxe))
    assert not _bound_sample(miss, gi.target_covariance(psi, p_noex)).all()
    if m_targets == 2:
        p_rep = np.asarray(gi.post_guidance_covariance(p_c, p_k, gamma, sx, "report"))
        assert not _bound_sample(dx_plus, p_rep).all()
