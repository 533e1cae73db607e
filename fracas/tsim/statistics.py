"""Statistics of TSIM Monte Carlo samples (FRACAS TSIM; digest item STAT-1), host numpy/scipy.

* Running moments (count, mean, co-moment sum M2) of blocks of samples, merged exactly
  (Chan, Golub & LeVeque's pairwise update, STAT-1): a run split into batches, workers or
  restarts gives the statistics of the whole up to rounding, whatever the split.
* Consistency of a Monte Carlo sample with a predicted (linear-covariance, TEAM/TOM) model:
  per-axis σ ratios, the likelihood-ratio (Wishart) test of a covariance, the χ² test of a
  zero mean, NEES and the coverage of the k-σ ellipsoids.
* Percentiles of a scalar sample.

Not jitted; callers pass only valid rows (no NaN handling).  Units are those of the samples.

Singular predictions.  A predicted covariance Σ0 may be singular or ill-conditioned (a state
component not dispersed, a rank-deficient linear map).  The tests then work in its range:
Σ0 = V Λ Vᵀ, eigenvalues below 1e-12 × the largest are dropped, the samples are projected on
the kept eigenvectors and whitened by Λ^{-1/2}, and p is the rank.  (The eigen-decomposition is
that of Σ0's correlation form, so the threshold is unit-free; components of zero variance are
outside the range.)  Spread of the sample
outside the range of Σ0 is not tested.
"""

from __future__ import annotations

from collections.abc import Iterable
from functools import reduce
from typing import NamedTuple

import numpy as np
from scipy import stats

__all__ = [
    "Moments",
    "moments_of",
    "merge",
    "merge_all",
    "covariance",
    "from_covariance",
    "axis_ratios",
    "covariance_test",
    "mean_test",
    "nees",
    "ellipse_coverage",
    "percentiles",
]

_RANGE_RTOL = 1.0e-12


class Moments(NamedTuple):
    """Running statistics of a block of samples of a p-vector: ``count`` samples, their
    ``mean`` (p,) and co-moment sum ``m2`` (p×p) = Σ (x − x̄)(x − x̄)ᵀ."""

    count: int
    mean: np.ndarray
    m2: np.ndarray


def moments_of(x) -> Moments:
    """Moments of the rows of x (N×p), two-pass (mean, then centred outer products).
    N = 0 gives count 0 and zero mean and M2."""
    x = np.asarray(x, dtype=np.float64)
    if x.ndim != 2:
        raise ValueError(f"moments_of: x must be (N, p), got shape {x.shape}")
    n, p = x.shape
    if n == 0:
        return Moments(0, np.zeros(p), np.zeros((p, p)))
    mean = x.mean(axis=0)
    dx = x - mean
    return Moments(int(n), mean, dx.T @ dx)


def merge(a: Moments, b: Moments) -> Moments:
    """Moments of the union of two blocks (STAT-1): n = n_a + n_b, δ = x̄_b − x̄_a,
    x̄ = x̄_a + δ n_b/n, M2 = M2_a + M2_b + δδᵀ n_a n_b/n.  Either block may be empty."""
    if b.count == 0:
        return Moments(int(a.count), np.array(a.mean, dtype=np.float64), np.array(a.m2, dtype=np.float64))
    if a.count == 0:
        return Moments(int(b.count), np.array(b.mean, dtype=np.float64), np.array(b.m2, dtype=np.float64))
    na, nb = int(a.count), int(b.count)
    n = na + nb
    mean_a = np.asarray(a.mean, dtype=np.float64)
    delta = np.asarray(b.mean, dtype=np.float64) - mean_a
    mean = mean_a + delta * (nb / n)
    m2 = (
        np.asarray(a.m2, dtype=np.float64) + np.asarray(b.m2, dtype=np.float64) + np.outer(delta, delta) * (na * nb / n)
    )
    return Moments(n, mean, m2)


def merge_all(blocks: Iterable[Moments]) -> Moments:
    """Left fold of :func:`merge` over ``blocks`` in the given order (at least one block)."""
    blocks = list(blocks)
    if not blocks:
        raise ValueError("merge_all: no blocks to merge")
    return reduce(merge, blocks)


def covariance(m: Moments) -> np.ndarray:
    """Sample covariance M2/(n − 1) (p×p); a NaN matrix when n < 2."""
    m2 = np.asarray(m.m2, dtype=np.float64)
    if m.count < 2:
        return np.full(m2.shape, np.nan)
    return m2 / (m.count - 1)


def from_covariance(count: int, mean, cov) -> Moments:
    """Moments of a block known by its count, mean and sample covariance (M2 = C (n − 1)): how
    a punched a-priori (earlier run) is read back and merged.  n < 2 gives M2 = 0."""
    mean = np.asarray(mean, dtype=np.float64)
    cov = np.asarray(cov, dtype=np.float64)
    count = int(count)
    m2 = cov * (count - 1) if count >= 2 else np.zeros(cov.shape)
    return Moments(count, mean, m2)


def axis_ratios(sample_cov, predicted_cov, count: int) -> tuple[np.ndarray, np.ndarray]:
    """Per-axis σ ratios sqrt(diag S / diag Σ) (p,) of a sample covariance S of ``count``
    samples to a predicted Σ, and their standard errors ≈ 1/sqrt(2(count − 1)) (p,), the
    large-sample SE of a sample σ over the true σ of a Gaussian (ratio 1 expected)."""
    s = np.diag(np.asarray(sample_cov, dtype=np.float64))
    sig = np.diag(np.asarray(predicted_cov, dtype=np.float64))
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.sqrt(s / sig)
    nu = int(count) - 1
    se = np.full(ratio.shape, 1.0 / np.sqrt(2.0 * nu) if nu > 0 else np.inf)
    return ratio, se


def _whitener(predicted_cov) -> np.ndarray:
    """W (p×r) with Wᵀ Σ0 W = I_r on the range of Σ0 (module docstring).

    Σ0 is first scaled to its correlation form D⁻¹Σ0D⁻¹, D = sqrt(diag Σ0) (components with
    zero variance dropped), so that the 1e-12 threshold does not depend on units (km against
    km/s); the statistics are invariant under this scaling.
    """
    sig = np.asarray(predicted_cov, dtype=np.float64)
    sig = 0.5 * (sig + sig.T)
    diag = np.diag(sig)
    active = np.flatnonzero(diag > 0.0)
    if active.size == 0:
        raise ValueError("predicted covariance has no positive variance")
    d = np.sqrt(diag[active])
    corr = sig[np.ix_(active, active)] / np.outer(d, d)
    lam, vec = np.linalg.eigh(corr)
    keep = lam > _RANGE_RTOL * lam.max()
    w = np.zeros((sig.shape[0], int(keep.sum())))
    w[active] = vec[:, keep] / np.sqrt(lam[keep]) / d[:, None]
    return w


def covariance_test(sample_cov, count: int, predicted_cov) -> tuple[float, int, float]:
    """Likelihood-ratio test of H0: Σ = Σ0 for a Gaussian sample of ``count`` vectors with
    unknown mean, sample covariance S (divisor ν = count − 1).

    λ = ν [tr(Σ0⁻¹S) − ln det(Σ0⁻¹S) − p]; with Box's correction
    ρ = 1 − (2p² + 3p − 1)/(6ν(p + 1)), ρλ ~ χ²(p(p+1)/2) under H0 (Anderson, *An
    Introduction to Multivariate Statistical Analysis*, §10.8).  Returns (ρλ, dof, p-value).
    A singular or ill-conditioned Σ0 is handled in its range (module docstring): p = its rank.
    A sample covariance singular on that range (e.g. ν < p) gives λ = inf and p-value 0.
    """
    w = _whitener(predicted_cov)
    p = w.shape[1]
    nu = int(count) - 1
    if nu < 1:
        raise ValueError(f"covariance_test: need at least 2 samples, got {count}")
    a = w.T @ np.asarray(sample_cov, dtype=np.float64) @ w
    a = 0.5 * (a + a.T)
    sign, logdet = np.linalg.slogdet(a)
    dof = p * (p + 1) // 2
    if sign <= 0 or nu < p:  # S singular on the range (rank ≤ ν < p)
        return float("inf"), dof, 0.0
    lam = nu * (np.trace(a) - logdet - p)
    rho = 1.0 - (2.0 * p * p + 3.0 * p - 1.0) / (6.0 * nu * (p + 1.0))
    stat = float(rho * lam)
    return stat, dof, float(stats.chi2.sf(stat, dof))


def mean_test(mean, count: int, predicted_cov) -> tuple[float, int, float]:
    """χ² test of a zero mean: count x̄ᵀ Σ0⁻¹ x̄ ~ χ²(p) for the mean x̄ (p,) of ``count``
    samples of N(0, Σ0) (Σ0 known).  Returns (statistic, p, p-value); a singular Σ0 is
    handled in its range (p = rank)."""
    w = _whitener(predicted_cov)
    y = w.T @ np.asarray(mean, dtype=np.float64)
    stat = float(int(count) * np.dot(y, y))
    dof = w.shape[1]
    return stat, dof, float(stats.chi2.sf(stat, dof))


def nees(x, predicted_cov) -> np.ndarray:
    """Normalized estimation error squared xᵀ Σ⁻¹ x of each row of x (N×p), (N,); a singular
    Σ is handled in its range (χ²(rank) under N(0, Σ))."""
    w = _whitener(predicted_cov)
    y = np.asarray(x, dtype=np.float64) @ w
    return np.sum(y * y, axis=-1)


def ellipse_coverage(x, predicted_cov, k=(1, 2, 3)) -> list[tuple[float, float, float, float]]:
    """Fraction of the rows of x (N×p) inside the k-σ ellipsoids of Σ (NEES ≤ k²), for each k:
    a list of (k, observed fraction, expected fraction = χ²_p.cdf(k²), binomial SE
    sqrt(e(1 − e)/N)), p the rank of Σ."""
    e = nees(x, predicted_cov)
    dof = _whitener(predicted_cov).shape[1]
    n = e.shape[0]
    out = []
    for kk in k:
        expected = float(stats.chi2.cdf(float(kk) ** 2, dof))
        observed = float(np.mean(e <= float(kk) ** 2)) if n else float("nan")
        se = float(np.sqrt(expected * (1.0 - expected) / n)) if n else float("nan")
        out.append((kk, observed, expected, se))
    return out


def percentiles(x, q=(50, 90, 99)) -> dict:
    """Percentiles {q: value} of a scalar sample x (N,) (numpy, method "linear"); NaN values
    when x is empty."""
    x = np.asarray(x, dtype=np.float64).ravel()
    if x.size == 0:
        return {qq: float("nan") for qq in q}
    vals = np.percentile(x, list(q), method="linear")
    return {qq: float(v) for qq, v in zip(q, vals)}
