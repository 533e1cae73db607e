"""The line search of TOM's projected-gradient search: FRACAS GENMIN with MINMUM (cases 1-3) and
BUCKET (digest equations MINMUM-1/2a/2b/2c/3, BUCKET-1).

Pure functions of γ and F(γ); the line-search function itself is the caller's ``cost``.
Re-exported by :mod:`fracas.tom.search`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import NamedTuple

import numpy as np

_COINCIDE = 1e-3  # GENMIN: a fitted γ within this relative distance of a flown trial is that trial


class Fit(NamedTuple):
    """A MINMUM fit: the minimizer γ* (nan when the fit has none), the predicted F(γ*), and the
    polynomial coefficients (a0, a1, a2[, a3]) in increasing powers of γ."""

    gamma: float
    predicted: float
    coeffs: tuple[float, ...]


def _poly(coeffs: Sequence[float], g: float) -> float:
    return float(sum(c * g**k for k, c in enumerate(coeffs)))


def quadratic_min(f0: float, slope: float, g0: float, f_g0: float) -> Fit:
    """FRACAS MINMUM case 1: quadratic through F(0), F'(0) and F(γ₀).

    MINMUM-1: a₀ = F(0), a₁ = F'(0), a₂ = [F(γ₀) − a₀ − a₁γ₀]/γ₀², γ* = −a₁/(2a₂), valid only when
    a₂ > 0.  The OCR of the report prints a₂ as "F(γ₀) − a₀/γ₀² + a₁/γ₀", which is garbled (wrong
    for any quadratic with a₀ ≠ 0 or γ₀ ≠ 1); this is the rebuilt form.
    """
    a0, a1 = float(f0), float(slope)
    a2 = (float(f_g0) - a0 - a1 * g0) / g0**2
    coeffs = (a0, a1, a2)
    if not (math.isfinite(a2) and a2 > 0):
        return Fit(math.nan, math.nan, coeffs)
    g = -a1 / (2.0 * a2)
    return Fit(g, _poly(coeffs, g), coeffs)


def cubic_min(f0: float, slope: float, g0: float, f_g0: float, g1: float, f_g1: float) -> Fit:
    """FRACAS MINMUM case 2: cubic through F(0), F'(0), F(γ₀) and F(γ₁).

    With λ = max(γ₀, γ₁) and α = min(γ₀, γ₁)/λ:

    * MINMUM-2a: a₂ = {[F(αλ) − α³F(λ)]/(1−α) − λα(1+α)a₁ − (1+α+α²)a₀}/(λ²α²)
    * MINMUM-2b: a₃ = {[α²F(λ) − F(αλ)]/(1−α) + (1+α)a₀ + λαa₁}/(λ³α²)
    * MINMUM-2c: γ* = [−a₂ + (a₂² − 3a₁a₃)^(1/2)]/(3a₃), coded as −a₁/[a₂ + (a₂² − 3a₁a₃)^(1/2)]
      (the same root, without cancellation as a₃ → 0, where it tends to case 1).

    The OCR of the report drops the α² on F(λ) in a₃ (2b); the printed form is wrong for a general
    cubic and this is the rebuilt one.  The fit is rejected (γ* = nan) when the discriminant is
    negative, the minimizer is not positive, or γ₀ = γ₁.
    """
    lam, small = (g1, g0) if g1 >= g0 else (g0, g1)
    f_lam, f_small = (f_g1, f_g0) if g1 >= g0 else (f_g0, f_g1)
    a0, a1 = float(f0), float(slope)
    if not (lam > 0 and 0 < small < lam):
        return Fit(math.nan, math.nan, (a0, a1, math.nan, math.nan))
    al = small / lam
    a2 = ((f_small - al**3 * f_lam) / (1 - al) - lam * al * (1 + al) * a1 - (1 + al + al**2) * a0) / (lam**2 * al**2)
    a3 = ((al**2 * f_lam - f_small) / (1 - al) + (1 + al) * a0 + lam * al * a1) / (lam**3 * al**2)
    coeffs = (a0, a1, a2, a3)
    disc = a2**2 - 3 * a1 * a3
    if not (math.isfinite(disc) and disc >= 0):
        return Fit(math.nan, math.nan, coeffs)
    den = a2 + math.sqrt(disc)
    g = -a1 / den if den != 0 else math.nan
    if not (math.isfinite(g) and g > 0):
        return Fit(math.nan, math.nan, coeffs)
    return Fit(g, _poly(coeffs, g), coeffs)


def bracket_min(gammas: Sequence[float], values: Sequence[float]) -> Fit:
    """FRACAS MINMUM case 3: quadratic (Lagrange form) through a bracket γ₂ < γ₃ < γ₄.

    MINMUM-3, with b_jk = γ_jγ_k, c_jk = γ_j + γ_k, d_ij = γ_i − γ_j and the sums over the cyclic
    (i, j, k): a₀ = Σ b_jk F(γ_i)/(d_ij d_ik), a₁ = −Σ c_jk F(γ_i)/(d_ij d_ik), a₂ = Σ F(γ_i)/(d_ij d_ik),
    γ* = −a₁/(2a₂), valid when a₂ > 0.  Correct as printed in the report.
    """
    g = [float(x) for x in gammas]
    f = [float(x) for x in values]
    a0 = a1 = a2 = 0.0
    for i, j, k in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
        w = f[i] / ((g[i] - g[j]) * (g[i] - g[k]))
        a0 += g[j] * g[k] * w
        a1 -= (g[j] + g[k]) * w
        a2 += w
    coeffs = (a0, a1, a2)
    if not (math.isfinite(a2) and a2 > 0):
        return Fit(math.nan, math.nan, coeffs)
    gs = -a1 / (2 * a2)
    return Fit(gs, _poly(coeffs, gs), coeffs)


def bucket(gammas: Sequence[float], values: Sequence[float]) -> int:
    """FRACAS BUCKET (BUCKET-1): find a bracketed minimum among the trials.

    Sorts the pairs (γ_i, F_i) by γ and returns the index k *in the sorted order* with
    F_{k−1} > F_k < F_{k+1} (the lowest such F_k when there are several), or 0 when there is none.
    """
    order = np.argsort(np.asarray(gammas, dtype=float), kind="stable")
    f = np.asarray(values, dtype=float)[order]
    best, k_best = math.inf, 0
    for k in range(1, len(f) - 1):
        if f[k - 1] > f[k] < f[k + 1] and f[k] < best:
            best, k_best = float(f[k]), k
    return k_best


def _next_trial(pts: list[tuple[float, float]], f0: float, slope: float, gamma_max: float) -> tuple[float, float]:
    """GENMIN's choice of the next γ (and the fit's prediction there, nan when no fit) or (nan, nan)."""
    g = np.array([0.0] + [p[0] for p in pts])
    f = np.array([f0] + [p[1] for p in pts])
    order = np.argsort(g, kind="stable")
    g, f = g[order], f[order]
    k = bucket(g, f)
    if k > 0:
        lo, mid, hi = g[k - 1], g[k], g[k + 1]
        if np.all(np.isfinite(f[k - 1 : k + 2])):
            fit = bracket_min(g[k - 1 : k + 2], f[k - 1 : k + 2])
            if math.isfinite(fit.gamma) and lo < fit.gamma < hi:
                return fit.gamma, fit.predicted
        return (0.5 * (mid + hi), math.nan) if not math.isfinite(f[k + 1]) else (0.5 * (lo + mid), math.nan)
    finite = [(gi, fi) for gi, fi in pts if math.isfinite(fi)]
    failed = [gi for gi, fi in pts if not math.isfinite(fi)]
    g_fail = min(failed) if failed else math.inf
    if not finite:
        return 0.5 * min(p[0] for p in pts), math.nan
    two = sorted(finite, key=lambda p: p[1])[:2]
    if len(two) == 2:
        fit = cubic_min(f0, slope, two[0][0], two[0][1], two[1][0], two[1][1])
        if not math.isfinite(fit.gamma):
            fit = quadratic_min(f0, slope, two[0][0], two[0][1])
    else:
        fit = quadratic_min(f0, slope, two[0][0], two[0][1])
    g_new, pred, coeffs = fit
    if not math.isfinite(g_new) or g_new <= 0:
        # No usable fit: expand when the trials keep decreasing, else shrink below the smallest trial.
        g_top = max(gi for gi, _ in finite)
        f_top = dict(finite)[g_top]
        if f_top < f0 and g_top < min(gamma_max, g_fail):
            g_new = min(2.0 * g_top, gamma_max)
            if g_new >= g_fail:
                g_new = 0.5 * (g_top + g_fail)
            return g_new, math.nan
        return 0.5 * min(gi for gi, _ in pts), math.nan
    if g_new >= g_fail:
        below = [gi for gi, _ in finite if gi < g_fail]
        g_new = 0.5 * ((max(below) if below else 0.0) + g_fail)
        pred = _poly(coeffs, g_new)
    if g_new > gamma_max:
        g_new = gamma_max
        pred = _poly(coeffs, g_new)
    return g_new, pred


def genmin(
    cost: Callable[[float], float],
    f0: float,
    slope: float,
    *,
    gamma_max: float = 4.0,
    eta: float = 0.1,
    max_trials: int = 6,
    first: float = 1.0,
) -> tuple[float, float, list[tuple[float, float]]]:
    """FRACAS GENMIN: line search on γ for the line-search function F(γ) = ``cost(γ)``.

    Requires F'(0) = ``slope`` < 0, else returns γ* = 0 at once (the caller falls back, P-A10).
    The first trial is γ₀ = ``first`` (the full p-step, P-A6), clamped to γ_max.  After each trial
    the next γ comes from BUCKET/MINMUM: a bracket (including (0, F(0))) → case 3; otherwise case 2
    on the two best finite trials (case 1 with one, or when the cubic has no minimum); no usable fit
    → double γ while the trials keep decreasing (up to γ_max) or halve it.  A failed trial
    (F = +inf, P-A12) caps γ below it.  A trial is accepted when F(γ) < F(0) and
    |F(γ) − P(γ)| ≤ η|F(0) − P(γ)|, P being the last fit's prediction; when a fit lands within
    0.1 % of a flown trial, that trial is taken as is.  At most ``max_trials`` calls to ``cost``.

    Returns (γ*, F(γ*), [(γ, F)...]) with γ* the best trial, or (0, F(0), trials) when no trial is
    below F(0) (the result is never worse than F(0)).
    """
    pts: list[tuple[float, float]] = []
    if not (math.isfinite(slope) and slope < 0 and math.isfinite(f0)):
        return 0.0, f0, pts
    g, pred = min(first, gamma_max), math.nan
    for _ in range(max_trials):
        fg = float(cost(g))
        if not math.isfinite(fg):
            fg = math.inf
        pts.append((g, fg))
        if fg < f0 and math.isfinite(pred) and abs(fg - pred) <= eta * abs(f0 - pred):
            break
        g_next, pred = _next_trial(pts, f0, slope, gamma_max)
        if not (math.isfinite(g_next) and g_next > 0):
            break
        if any(abs(gi - g_next) <= _COINCIDE * gi for gi, _ in pts):
            break
        g = g_next
    g_best, f_best = min(pts, key=lambda p: p[1])
    if f_best < f0:
        return g_best, f_best, pts
    return 0.0, f0, pts
