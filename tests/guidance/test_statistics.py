"""|ΔV| statistics (fracas.guidance.statistics) against references this code did not produce.

References: closed forms (Maxwell/χ(3), half-normal/χ(1), Rayleigh/χ(2)), scipy's χ
distributions, an independent quadrature of the digest's integral form of E|ΔV|, the
digest's prototype table (G2), and seeded Monte Carlo of |ΔV| (N = 400,000).

Tolerances:
* closed forms and quadratures: 1e-10 relative; the code's quadrature is good to ~1e-13
  and scipy's special functions to ~1e-15, so 1e-10 leaves margin for neither to matter.
* the digest table G2 is printed to 6-7 significant digits: 5e-7 absolute on the means;
  its percentiles are 3-decimal values from its 4e6-sample prototype MC (2.575 against the
  exact 2.5758 = Φ⁻¹(0.995)), so 1e-3 absolute.
* Monte Carlo mean: 4 standard errors, SE = sample std(|ΔV|)/√N.
* Monte Carlo 99 % value: distribution-free.  If v99 is the true quantile, the number of
  samples with |ΔV| ≤ v99 is Binomial(N, 0.99); we require it within 4 binomial standard
  deviations, √(N·0.99·0.01) ≈ 63 for N = 400,000.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import integrate, stats

from fracas.guidance import statistics as st

N_MC = 400_000


def _rotation(rng):
    q, r = np.linalg.qr(rng.standard_normal((3, 3)))
    return q * np.sign(np.diag(r))


def _cov(sigmas, seed):
    rot = _rotation(np.random.default_rng(seed))
    return rot @ np.diag(np.square(sigmas)) @ rot.T


CASES = {
    "isotropic": (2.0e-3, 2.0e-3, 2.0e-3),  # km/s (2 m/s per axis)
    "flat": (3.0e-3, 1.0e-3, 0.0),  # one zero eigenvalue
    "elongated": (1.0, 1.0e-3, 1.0e-3),  # 1000:1 in sigma (1e6 in variance)
    "general": (3.0, 2.0, 1.0),
}


def test_maxwell_closed_form():
    sigma = 0.005
    p = _cov((sigma,) * 3, 1)
    assert st.mean_dv_magnitude(p) == pytest.approx(2.0 * sigma * np.sqrt(2.0 / np.pi), rel=1e-10)
    assert st.dv_magnitude_quantile(p, 0.99) == pytest.approx(sigma * stats.chi(3).ppf(0.99), rel=1e-10)
    assert st.dv_magnitude_quantile(p, 0.5) == pytest.approx(sigma * stats.chi(3).ppf(0.5), rel=1e-10)
    assert st.rms_dv_magnitude(p) == pytest.approx(sigma * np.sqrt(3.0), rel=1e-12)


def test_one_and_two_dimensional_closed_forms():
    p1 = np.diag([0.0, 4.0, 0.0])
    assert st.mean_dv_magnitude(p1) == pytest.approx(2.0 * np.sqrt(2.0 / np.pi), rel=1e-10)
    assert st.dv_magnitude_quantile(p1, 0.99) == pytest.approx(2.0 * stats.norm.ppf(0.995), rel=1e-10)
    p2 = np.diag([9.0, 0.0, 9.0])
    assert st.mean_dv_magnitude(p2) == pytest.approx(3.0 * np.sqrt(np.pi / 2.0), rel=1e-10)
    assert st.dv_magnitude_quantile(p2, 0.99) == pytest.approx(3.0 * np.sqrt(-2.0 * np.log(0.01)), rel=1e-10)
    assert st.dv_magnitude_cdf(p2, 3.0) == pytest.approx(stats.rayleigh.cdf(1.0), rel=1e-10)
    assert st.mean_dv_magnitude(np.zeros((3, 3))) == 0.0
    assert st.dv_magnitude_quantile(np.zeros((3, 3))) == 0.0


@pytest.mark.parametrize("name", list(CASES))
def test_mean_against_integral_form(name):
    # digest (G-9): E|ΔV| = (4π)^{-1/2} ∫ [1 − Π(1+2tλ)^{-1/2}] t^{-3/2} dt, by scipy.quad.
    lam = np.square(CASES[name])

    # with t = u² the integrand 2[1 − Π]/u² is smooth at 0; expm1/log1p avoid cancellation
    def f(u):
        return -2.0 * np.expm1(-0.5 * np.sum(np.log1p(2.0 * u * u * lam))) / (u * u) if u > 0 else 2.0 * lam.sum()

    # split at the scales λ^{-1/2} so that quad resolves each regime
    pts = sorted({0.0, *(x**-0.5 for x in lam if x > 0), np.inf})
    total = sum(integrate.quad(f, a, b, epsabs=0, epsrel=1e-13, limit=400)[0] for a, b in zip(pts[:-1], pts[1:]))
    ref = total / np.sqrt(4.0 * np.pi)
    assert st.mean_dv_magnitude(_cov(CASES[name], 7)) == pytest.approx(ref, rel=1e-10)


@pytest.mark.parametrize(
    ("sigmas", "mean", "p99"),
    [
        ((1, 0, 0), 0.797885, 2.575),
        ((1, 1, 0), 1.253314, 3.035),
        ((1, 1, 1), 1.595769, 3.369),
        ((3, 2, 1), 3.353081, None),
        ((1, 0.1, 0.1), 0.821887, None),
        ((1, 0.5, 0), 0.966283, None),
        ((10, 1, 0.3), 8.118492, None),
        ((2, 2, 0.5), 2.571334, None),
    ],
)
def test_digest_table_g2(sigmas, mean, p99):
    p = np.diag(np.square(np.asarray(sigmas, dtype=float)))
    assert st.mean_dv_magnitude(p) == pytest.approx(mean, abs=5e-7)
    if p99 is not None:
        assert st.dv_magnitude_quantile(p, 0.99) == pytest.approx(p99, abs=1e-3)


@pytest.mark.parametrize("name", list(CASES))
def test_quadrature_converged(name):
    p = _cov(CASES[name], 3)
    a = st.dv_magnitude_quantile(p, 0.99)
    b = st.dv_magnitude_quantile(p, 0.99, nodes=256)
    assert a == pytest.approx(b, rel=1e-11)


@pytest.mark.parametrize("name", list(CASES))
def test_monte_carlo(name):
    p = _cov(CASES[name], 11)
    rng = np.random.default_rng(20240609)
    # independent sampling: Cholesky-free, from the eigen-decomposition done here
    lam, vec = np.linalg.eigh(p)
    g = rng.standard_normal((N_MC, 3))
    dv = (g * np.sqrt(np.clip(lam, 0, None))) @ vec.T
    mag = np.linalg.norm(dv, axis=1)

    mean = st.mean_dv_magnitude(p)
    se = mag.std(ddof=1) / np.sqrt(N_MC)
    assert abs(mag.mean() - mean) < 4.0 * se, (mag.mean(), mean, se)

    v99 = st.dv_magnitude_quantile(p, 0.99)
    count = np.count_nonzero(mag <= v99)
    sd = np.sqrt(N_MC * 0.99 * 0.01)
    assert abs(count - 0.99 * N_MC) < 4.0 * sd, (count, 0.99 * N_MC, sd)
    # the CDF at other levels too
    for q in (0.5, 0.9):
        vq = st.dv_magnitude_quantile(p, q)
        c = np.count_nonzero(mag <= vq)
        assert abs(c - q * N_MC) < 4.0 * np.sqrt(N_MC * q * (1 - q)), (q, c)


def test_monte_carlo_negative_control():
    # the RMS (tr P)^{1/2} is not the mean; the MC resolves the difference by far
    p = _cov(CASES["elongated"], 11)
    rng = np.random.default_rng(5)
    lam, vec = np.linalg.eigh(p)
    mag = np.linalg.norm((rng.standard_normal((N_MC, 3)) * np.sqrt(np.clip(lam, 0, None))) @ vec.T, axis=1)
    se = mag.std(ddof=1) / np.sqrt(N_MC)
    assert abs(mag.mean() - st.rms_dv_magnitude(p)) > 40.0 * se
    # and the 1-D (χ₁) bracket end is not the 3-D quantile of the isotropic case
    pi = _cov(CASES["isotropic"], 2)
    wrong = np.sqrt(np.max(np.linalg.eigvalsh(pi))) * stats.chi.ppf(0.99, 1)
    assert st.dv_magnitude_quantile(pi) > 1.2 * wrong


def test_input_validation():
    with pytest.raises(ValueError):
        st.dv_magnitude_quantile(np.eye(3), 1.0)
