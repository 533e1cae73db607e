"""Monte Carlo statistics (fracas.tsim.statistics) against references this code did not produce.

References: numpy's one-pass mean and covariance of the whole sample (np.cov), closed forms of
χ² and binomial distributions (scipy.stats), and seeded Gaussian samples (numpy default_rng,
fixed seeds, so every test is deterministic).

Tolerances:
* merging: exact in arithmetic; rounding of sums of ~10³ terms of O(1) is ~1e-14 relative,
  so 1e-12 leaves margin.
* calibration of p-values: a Kolmogorov–Smirnov test against U(0, 1) with threshold 1e-3
  (false-alarm probability 1e-3 for a correct test, a fixed seed makes it a fixed outcome) and
  the fraction of p-values below 0.05 within 5 binomial SE (false alarm ~6e-7).
* coverage and other Monte Carlo fractions: 5 binomial SE (two-sided false alarm 6e-7 each).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from fracas.tsim import statistics as ts


def _cov(sigmas, seed):
    rng = np.random.default_rng(seed)
    q, r = np.linalg.qr(rng.standard_normal((len(sigmas), len(sigmas))))
    q = q * np.sign(np.diag(r))
    return q @ np.diag(np.square(sigmas)) @ q.T


SIGMA0 = _cov((3.0, 1.0, 0.2), 7)  # km², a correlated 3×3 covariance


def test_merge_of_blocks_equals_whole():
    """Merged block moments vs numpy's mean and np.cov of the whole sample (independent
    one-shot computation), 1e-12 relative; random uneven splits incl. empty and 1-row blocks,
    and every merge order/tree shape (left fold, pairwise tree) agrees."""
    rng = np.random.default_rng(11)
    x = rng.standard_normal((1000, 4)) @ np.diag([1.0, 10.0, 1e-3, 5.0]) + np.array([7e3, -2.0, 0.5, 1e4])
    cuts = np.sort(rng.choice(np.arange(1, 1000), size=12, replace=False))
    cuts = np.concatenate([[0, 0], cuts[:6], [cuts[6], cuts[6] + 1], cuts[7:], [1000]])  # empty & 1-row blocks
    blocks = [ts.moments_of(x[a:b]) for a, b in zip(cuts[:-1], cuts[1:])]
    assert any(b.count == 0 for b in blocks) and any(b.count == 1 for b in blocks)
    whole = ts.merge_all(blocks)
    assert whole.count == 1000
    np.testing.assert_allclose(whole.mean, x.mean(axis=0), rtol=1e-12)
    np.testing.assert_allclose(ts.covariance(whole), np.cov(x.T), rtol=1e-12, atol=1e-12 * np.abs(np.cov(x.T)).max())
    direct = ts.moments_of(x)
    np.testing.assert_allclose(whole.m2, direct.m2, rtol=1e-12, atol=1e-12 * np.abs(direct.m2).max())
    # a pairwise tree gives the same
    level = blocks
    while len(level) > 1:
        level = [ts.merge(*level[i : i + 2]) if i + 1 < len(level) else level[i] for i in range(0, len(level), 2)]
    np.testing.assert_allclose(level[0].m2, direct.m2, rtol=1e-12, atol=1e-12 * np.abs(direct.m2).max())


def test_empty_and_small_moments():
    """Edge cases by definition: empty blocks are identities of merge, n < 2 has no covariance."""
    empty = ts.moments_of(np.zeros((0, 3)))
    assert empty.count == 0 and empty.mean.shape == (3,) and not empty.m2.any()
    one = ts.moments_of(np.array([[1.0, 2.0, 3.0]]))
    assert ts.merge(empty, one).count == 1 and ts.merge(one, empty).count == 1
    np.testing.assert_array_equal(ts.merge(empty, one).mean, one.mean)
    assert np.isnan(ts.covariance(one)).all() and ts.covariance(one).shape == (3, 3)
    assert ts.merge(empty, empty).count == 0
    with pytest.raises(ValueError):
        ts.merge_all([])


def test_from_covariance_round_trip():
    """A block read back from (count, mean, covariance) merges like the original block: M2 =
    C (n − 1) is the definition of C, so the round trip is exact to rounding (1e-12)."""
    rng = np.random.default_rng(3)
    x = rng.standard_normal((300, 3))
    a, b = ts.moments_of(x[:120]), ts.moments_of(x[120:])
    back = ts.from_covariance(a.count, a.mean, ts.covariance(a))
    np.testing.assert_allclose(back.m2, a.m2, rtol=1e-12)
    np.testing.assert_allclose(ts.covariance(ts.merge(back, b)), np.cov(x.T), rtol=1e-12)


def _sample_sets(cov, n_sets, n, seed):
    rng = np.random.default_rng(seed)
    chol = np.linalg.cholesky(cov) if np.all(np.linalg.eigvalsh(cov) > 0) else None
    if chol is None:
        lam, vec = np.linalg.eigh(cov)
        chol = vec * np.sqrt(np.clip(lam, 0.0, None))
    z = rng.standard_normal((n_sets, n, cov.shape[0]))
    return z @ chol.T + np.array([5.0, -1.0, 2.0])[: cov.shape[0]]  # unknown (nonzero) mean


def _calibrated(pvals):
    """p-values uniform: KS p > 1e-3 and fraction below 0.05 within 5 binomial SE."""
    n = len(pvals)
    assert stats.kstest(pvals, "uniform").pvalue > 1e-3
    assert abs(np.mean(pvals < 0.05) - 0.05) < 5.0 * np.sqrt(0.05 * 0.95 / n)


def test_covariance_test_is_calibrated_and_rejects():
    """Reference: under H0 the p-value of an exact-size test is U(0, 1); Box's correction makes
    the LR test accurate to O(ν⁻²) (Anderson §10.8), negligible at N = 200 for 400 sets.
    Power: σ 1.3× larger along one eigen-axis of Σ0 with N = 2000 gives E[λ] ≈ ν(1.69 − ln
    1.69 − 1) ≈ 330 on 6 dof, so p < 1e-6 is certain."""
    sets = _sample_sets(SIGMA0, 400, 200, seed=21)
    pvals = np.array([ts.covariance_test(np.cov(s.T), 200, SIGMA0)[2] for s in sets])
    _calibrated(pvals)
    stat, dof, _ = ts.covariance_test(np.cov(sets[0].T), 200, SIGMA0)
    assert dof == 6 and stat > 0
    lam, vec = np.linalg.eigh(SIGMA0)
    scale = np.ones(3)
    scale[1] = 1.3**2
    wrong = (vec * (lam * scale)) @ vec.T
    big = _sample_sets(wrong, 1, 2000, seed=22)[0]
    assert ts.covariance_test(np.cov(big.T), 2000, SIGMA0)[2] < 1e-6


def test_covariance_test_closed_form_one_dimension():
    """p = 1: λ = ν(s²/σ² − ln(s²/σ²) − 1), ρ = 1 − 4/(12ν) (the formula written out by hand)."""
    nu = 49
    s2, sig2 = 1.7, 1.2
    r = s2 / sig2
    expected = (1.0 - 4.0 / (12.0 * nu)) * nu * (r - np.log(r) - 1.0)
    stat, dof, p = ts.covariance_test([[s2]], nu + 1, [[sig2]])
    assert stat == pytest.approx(expected, rel=1e-13) and dof == 1
    assert p == pytest.approx(stats.chi2.sf(expected, 1), rel=1e-12)


def test_covariance_test_singular_prediction_uses_range():
    """Σ0 of rank 2 in 3-D (a component not dispersed): samples from it give calibrated
    p-values on dof = 2·3/2 = 3 (the range), same bounds as the full-rank case."""
    sig = np.zeros((3, 3))
    sig[:2, :2] = [[2.0, 0.6], [0.6, 1.0]]
    sets = _sample_sets(sig, 400, 200, seed=31)
    res = [ts.covariance_test(np.cov(s.T), 200, sig) for s in sets]
    assert {r[1] for r in res} == {3}
    _calibrated(np.array([r[2] for r in res]))
    # a sample singular on the range (ν < p) is rejected outright
    assert ts.covariance_test(np.cov(sets[0][:2].T), 2, sig)[2] == 0.0


def test_mean_test_is_calibrated_and_rejects():
    """Reference: N x̄ᵀΣ0⁻¹x̄ ~ χ²(p) exactly for Gaussian samples of N(0, Σ0): p-values
    uniform (bounds as above).  Power: a mean of 0.3 σ along one axis with N = 2000 gives a
    noncentrality of 180 on 3 dof: p < 1e-6 is certain."""
    rng = np.random.default_rng(41)
    chol = np.linalg.cholesky(SIGMA0)
    z = rng.standard_normal((400, 200, 3)) @ chol.T
    pvals = np.array([ts.mean_test(s.mean(axis=0), 200, SIGMA0)[2] for s in z])
    _calibrated(pvals)
    assert ts.mean_test(z[0].mean(axis=0), 200, SIGMA0)[1] == 3
    lam, vec = np.linalg.eigh(SIGMA0)
    shift = 0.3 * np.sqrt(lam[0]) * vec[:, 0]
    x = rng.standard_normal((2000, 3)) @ chol.T + shift
    assert ts.mean_test(x.mean(axis=0), 2000, SIGMA0)[2] < 1e-6


@pytest.mark.parametrize(
    "p, expected",
    [
        (2, (1.0 - np.exp(-0.5), 1.0 - np.exp(-2.0), 1.0 - np.exp(-4.5))),  # Rayleigh: 0.3935, 0.8647, 0.9889
        (3, (0.198748, 0.738536, 0.970709)),  # χ²(3) cdf at 1, 4, 9 (tables)
    ],
)
def test_ellipse_coverage(p, expected):
    """Expected fractions against the closed form (p = 2: 1 − exp(−k²/2)) or χ²(3) tables
    (6 digits, so 1e-6); observed fractions of N = 20000 Gaussian samples within 5 binomial SE
    of the expected (false alarm 6e-7 each)."""
    cov = _cov((2.0, 0.5, 0.1)[:p], 51)
    rng = np.random.default_rng(52 + p)
    x = rng.standard_normal((20000, p)) @ np.linalg.cholesky(cov).T
    res = ts.ellipse_coverage(x, cov)
    assert [r[0] for r in res] == [1, 2, 3]
    assert [round(r[2], 4) for r in res] == [round(e, 4) for e in expected]
    for (_, obs, exp, se), ref in zip(res, expected):
        assert exp == pytest.approx(ref, abs=1e-6)
        assert se == pytest.approx(np.sqrt(ref * (1 - ref) / 20000), rel=1e-5)
        assert abs(obs - exp) < 5.0 * se


def test_nees_identity_and_singular():
    """NEES with Σ = I is the squared norm (definition); with a singular Σ only the range
    counts (components outside it are dropped)."""
    x = np.array([[1.0, 2.0, 2.0], [0.0, 0.0, 0.0]])
    np.testing.assert_allclose(ts.nees(x, np.eye(3)), [9.0, 0.0], rtol=1e-14)
    sig = np.diag([4.0, 1.0, 0.0])
    np.testing.assert_allclose(ts.nees(x, sig), [1.0 / 4.0 + 4.0, 0.0], rtol=1e-13)


def test_axis_ratios_and_their_standard_error():
    """Ratios by definition; the SE 1/sqrt(2ν) against the observed spread of sample-σ ratios
    over 4000 sets of N = 200 (p = 1): the spread's own relative SE is ~1/sqrt(2·4000) = 1.1 %,
    and the O(1/ν) bias of the asymptotic formula ~0.5 %, so a 8 % tolerance is > 5 SE."""
    ratio, se = ts.axis_ratios(np.diag([4.0, 1.0]), np.diag([1.0, 4.0]), 101)
    np.testing.assert_allclose(ratio, [2.0, 0.5], rtol=1e-15)
    np.testing.assert_allclose(se, 1.0 / np.sqrt(200.0), rtol=1e-15)
    rng = np.random.default_rng(61)
    x = 3.0 * rng.standard_normal((4000, 200))
    r = np.array([ts.axis_ratios([[np.var(s, ddof=1)]], [[9.0]], 200)[0][0] for s in x])
    assert np.std(r) == pytest.approx(1.0 / np.sqrt(2.0 * 199), rel=0.08)


def test_percentiles():
    """numpy's linear percentile by hand: 0..100 gives q itself, [0, 1, 2, 3] gives 1.5 at 50;
    an empty sample gives NaN."""
    assert ts.percentiles(np.arange(101.0)) == {50: 50.0, 90: 90.0, 99: 99.0}
    assert ts.percentiles([3.0, 0.0, 2.0, 1.0], q=(50, 25)) == {50: 1.5, 25: 0.75}
    out = ts.percentiles(np.array([]))
    assert set(out) == {50, 90, 99} and all(np.isnan(v) for v in out.values())
