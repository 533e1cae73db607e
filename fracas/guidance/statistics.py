"""Statistics of |ΔV| for a zero-mean Gaussian ΔV with covariance P_ΔV (GUIDM §5.3.6).

FRACAS printed an approximate mean ΔV "by the Hoffman-Young formula" (report L1704); that
formula is lost from the scan.  The digest (``tom-tsim-guidance.md`` (G-9), P-B8) replaces it
with exact values, computed here in float64 with numpy/scipy (host code, not jit-able: these
are per-event summaries, not inner-loop kernels).  Units follow P_ΔV: km²/s² in, km/s out.

Write ΔV = P^{1/2} g, g ~ N(0, I₃), and g = ρ n with ρ = |g| ~ χ(3) independent of the unit
vector n, uniform on the sphere.  Then |ΔV| = ρ · s(n)^{1/2} with s(n) = nᵀ Λ n, Λ = the
eigenvalues of P_ΔV (negative rounding clipped to 0).

* **Mean** (digest (G-9)): E|ΔV| = E[ρ] · E_n[s^{1/2}] = 2(2/π)^{1/2} R_G(λ₁, λ₂, λ₃), with
  R_G Carlson's symmetric elliptic integral (the sphere average of s^{1/2}), evaluated by
  ``scipy.special.elliprg`` (relative accuracy ~1e-15).
* **Quantile**: P(|ΔV| ≤ v) = E_n[F_χ₃(v / s(n)^{1/2})], a smooth function on the sphere even
  when eigenvalues vanish (F_χ₃(v/√s) → 1 with all derivatives as s → 0).  It is integrated
  with Gauss–Legendre in z = cos θ and the (spectrally accurate, periodic) trapezoid rule in
  the azimuth; 96 × 96 nodes give the CDF to ~1e-13 for eigenvalue ratios up to 1e6 (the
  tests check against closed forms and against doubling the nodes).  The quantile is the
  root (``scipy.optimize.brentq``, xtol 1e-14 relative) inside the bracket
  [√λ_max χ₁⁻¹(q), √λ_max χ₃⁻¹(q)], which always holds it since λ_max g₁² ≤ |ΔV|² ≤
  λ_max |g|².  This is equivalent to Imhof's (1961) inversion for a weighted sum of χ²₁ but
  has no oscillatory integrand.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from scipy import optimize, special, stats

if TYPE_CHECKING:
    import numpy.typing as npt

__all__ = ["dv_eigenvalues", "mean_dv_magnitude", "rms_dv_magnitude", "dv_magnitude_cdf", "dv_magnitude_quantile"]

_NODES = 96


def dv_eigenvalues(p_dv: npt.ArrayLike) -> np.ndarray:
    """Eigenvalues of the symmetric part of P_ΔV (3×3, km²/s²), ascending, clipped at 0."""
    p = np.asarray(p_dv, dtype=np.float64)
    lam = np.linalg.eigvalsh(0.5 * (p + p.T))
    return np.clip(lam, 0.0, None)


def mean_dv_magnitude(p_dv: npt.ArrayLike) -> float:
    """E|ΔV| = 2(2/π)^{1/2} R_G(λ₁, λ₂, λ₃) (digest (G-9), exact; replaces Hoffman–Young), km/s.

    Isotropic σ²I gives the Maxwell mean 2σ(2/π)^{1/2}; one eigenvalue σ² gives σ(2/π)^{1/2}.
    Means of separate events add (digest P-B8); RMS values do not.
    """
    lam = dv_eigenvalues(p_dv)
    return float(2.0 * np.sqrt(2.0 / np.pi) * special.elliprg(*lam))


def rms_dv_magnitude(p_dv: npt.ArrayLike) -> float:
    """(E|ΔV|²)^{1/2} = (tr P_ΔV)^{1/2}, km/s."""
    return float(np.sqrt(np.sum(dv_eigenvalues(p_dv))))


def _sphere_rule(nodes: int) -> tuple[np.ndarray, np.ndarray]:
    z, wz = np.polynomial.legendre.leggauss(nodes)
    phi = 2.0 * np.pi * np.arange(2 * nodes) / (2 * nodes)
    sin_t = np.sqrt(1.0 - z * z)
    n = np.stack(
        [np.outer(sin_t, np.cos(phi)), np.outer(sin_t, np.sin(phi)), np.outer(z, np.ones_like(phi))], axis=-1
    ).reshape(-1, 3)
    w = np.outer(wz, np.full(phi.shape, 1.0 / (2 * nodes))).reshape(-1) / 2.0  # sums to 1
    return n, w


def _cdf_scaled(v: float, lam_scaled: np.ndarray, n: np.ndarray, w: np.ndarray) -> float:
    s = (n * n) @ lam_scaled
    with np.errstate(divide="ignore"):
        arg = np.where(s > 0.0, v / np.sqrt(np.where(s > 0.0, s, 1.0)), np.inf)
    return float(w @ stats.chi.cdf(arg, 3))


def dv_magnitude_cdf(p_dv: npt.ArrayLike, v: float, nodes: int = _NODES) -> float:
    """P(|ΔV| ≤ v) for ΔV ~ N(0, P_ΔV) by the sphere quadrature of the module docstring."""
    lam = dv_eigenvalues(p_dv)
    lmax = lam[-1]
    if lmax <= 0.0:
        return 1.0 if v >= 0.0 else 0.0
    n, w = _sphere_rule(nodes)
    return _cdf_scaled(v / np.sqrt(lmax), lam / lmax, n, w)


def dv_magnitude_quantile(p_dv: npt.ArrayLike, q: float = 0.99, nodes: int = _NODES) -> float:
    """The q-quantile of |ΔV| (default 0.99, the "99 % ΔV"), km/s, exact to ~1e-12 relative.

    Method in the module docstring (quadrature over directions of the χ(3) CDF, root by
    Brent).  A zero covariance gives 0.
    """
    if not 0.0 < q < 1.0:
        raise ValueError("q must lie in (0, 1)")
    lam = dv_eigenvalues(p_dv)
    lmax = lam[-1]
    if lmax <= 0.0:
        return 0.0
    lam_s = lam / lmax
    n, w = _sphere_rule(nodes)
    lo = stats.chi.ppf(q, 1) * (1.0 - 1e-9)
    hi = stats.chi.ppf(q, 3) * (1.0 + 1e-9)
    root = optimize.brentq(lambda v: _cdf_scaled(v, lam_s, n, w) - q, lo, hi, xtol=1e-14, rtol=1e-14)
    return float(root * np.sqrt(lmax))
