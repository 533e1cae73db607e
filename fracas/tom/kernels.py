"""The pure kernels of TOM's projected-gradient search (FRACAS WEIGHT, STEST, TEST, PINV, DELU,
SIZE and FUNCT; digest equations WEIGHT-1/2, STEST-1, TEST-1, DELU-1..4, SIZE-1..6).

Arrays in, arrays out.  Also the search's direction on the retained controls (SIZE + DELU,
embedded back into all M), the gradient angle θ of SIZE-6, TEST's angle for an NLP solver's
answer (:func:`optimality_angle`) and the STEST gate.  Re-exported by :mod:`fracas.tom.search`,
whose docstring gives the notation and the choices made.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from fracas.tom.search_types import RCOND, WEIGHTINGS, Problem, SearchSettings


def weights(
    S: np.ndarray,
    tol: np.ndarray,
    u: np.ndarray,
    scale: np.ndarray,
    floor: np.ndarray,
    kind: str = "sensitivity",
    value_weighted: np.ndarray | None = None,
) -> np.ndarray:
    """FRACAS WEIGHT: the diagonal d of D = W^(1/2), in control units (so Ũ = U/d is dimensionless).

    ``value_weighted`` (M,) bool: where False, control weighting uses the floor alone (W_jj =
    k_j² U_floor,j²): for angles and epochs, whose size says nothing about their scale (a right
    ascension of 177 deg is not 177 times more "room" than one of 1 deg).  Default: all True.

    * ``"sensitivity"`` (WEIGHT-1): W_jj = k_j² / max_i(|S_ij|/ε_i)², i.e. d_j = k_j / max_i |S_ij|/ε_i.
      A column with no target sensitivity (all zero, or N = 0) falls back to control weighting.
    * ``"control"`` (WEIGHT-2): W_jj = k_j² max(U_j², U_floor,j²).  Where that is 0 (U_j = 0 and no
      floor), d_j = k_j (the control's own unit).

    S is (N, M) in target units per control unit, ``tol`` (N,) ε in target units.
    """
    S = np.asarray(S, dtype=float)
    u = np.asarray(u, dtype=float)
    scale = np.asarray(scale, dtype=float)
    floor = np.abs(np.asarray(floor, dtype=float))
    size = np.maximum(np.abs(u), floor)
    if value_weighted is not None:
        size = np.where(np.asarray(value_weighted, bool), size, floor)
    control = scale * size
    control = np.where(control > 0, control, scale)
    if kind == "control":
        return control
    if kind != "sensitivity":
        raise ValueError(f"weighting must be one of {WEIGHTINGS}, not {kind!r}")
    if S.shape[0] == 0:
        return control
    peak = np.max(np.abs(S) / np.asarray(tol, dtype=float)[:, None], axis=0)
    ok = np.isfinite(peak) & (peak > 0)
    return np.where(ok, scale / np.where(ok, peak, 1.0), control)


def dependent_controls(S_scaled: np.ndarray, theta_min: float) -> tuple[int, ...]:
    """FRACAS STEST: controls to drop this iteration because their target columns are nearly parallel.

    STEST-1: P_IJ = |s̃_I·s̃_J| / (|s̃_I||s̃_J|) over the columns s̃ of S̃; I and J are dependent when
    1 − ε < P_IJ ≤ 1 with ε = 1 − cos θ_min.  Rule (report L1372): for each dependent pair in order
    (I < J, neither already dropped) drop I, unless J appears in another still-live dependent pair;
    then drop J.  Zero columns (no sensitivity) are never dependent.  Returns the indices in drop
    order.  Pairwise only: three-way dependencies are left to the SVD cutoff (P-A5).
    :func:`projected_gradient` applies it only when S̃ is ill-conditioned (σ_min/σ_max < sin θ_min):
    with N = 1 all columns are parallel, and a parallel pair next to spare independent columns
    costs no rank, so dropping would only remove optimization freedom.
    """
    S = np.asarray(S_scaled, dtype=float)
    if S.ndim != 2 or S.shape[0] == 0 or S.shape[1] < 2:
        return ()
    norms = np.linalg.norm(S, axis=0)
    valid = norms > 0
    unit = S / np.where(valid, norms, 1.0)
    P = np.abs(unit.T @ unit)
    threshold = math.cos(theta_min)  # 1 − ε
    m = S.shape[1]
    pairs = [(i, j) for i in range(m) for j in range(i + 1, m) if valid[i] and valid[j] and P[i, j] > threshold]
    dropped: list[int] = []
    for i, j in pairs:
        if i in dropped or j in dropped:
            continue
        live = [pr for pr in pairs if pr != (i, j) and pr[0] not in dropped and pr[1] not in dropped]
        dropped.append(j if any(j in pr for pr in live) else i)
    return tuple(dropped)


def choose_submode(error_rms: float, settings: SearchSettings) -> str:
    """FRACAS TEST (TEST-1): the submode of this iteration, "T", "T+O" or "O".

    With ``settings.submode == "auto"``: E_rms > T_up → "T" (α = 1, β = 0); T_low < E_rms ≤ T_up →
    "T+O" (α = β = 1); E_rms ≤ T_low → "O" (α = 0, β = 1).  E_rms = (Σ τ_i²/N)^(1/2) with τ = ΔT/ε
    (P-A2).  A fixed submode maps to "T", "T+O" or "O".
    """
    fixed = {"target": "T", "target_optimize": "T+O", "optimize": "O"}
    if settings.submode in fixed:
        return fixed[settings.submode]
    if error_rms > settings.targeting_threshold:
        return "T"
    if error_rms > settings.optimization_threshold:
        return "T+O"
    return "O"


def _svd_parts(S: np.ndarray, rcond: float) -> tuple[np.ndarray, np.ndarray, int]:
    """(S⁺ (M, N), P = I − S⁺S (M, M), rank) of S (N, M) by SVD with a relative cutoff."""
    S = np.asarray(S, dtype=float)
    n, m = S.shape
    if n == 0 or m == 0:
        return np.zeros((m, n)), np.eye(m), 0
    U, s, Vt = np.linalg.svd(S, full_matrices=False)
    keep = s > rcond * s[0] if s.size and s[0] > 0 else np.zeros(s.shape, dtype=bool)
    r = int(np.count_nonzero(keep))
    Ur, sr, Vr = U[:, :r], s[:r], Vt[:r].T
    pinv = (Vr / sr) @ Ur.T
    proj = np.eye(m) - Vr @ Vr.T
    return pinv, proj, r


def pseudo_inverse(S_scaled: np.ndarray, rcond: float = RCOND) -> np.ndarray:
    """FRACAS PINV (used by SIZE/DELU): S̃⁺ (M, N) by SVD, singular values ≤ rcond·σ_max set to zero.

    Equals S̃ᵀ(S̃S̃ᵀ)⁻¹ for N ≤ M at full rank and (S̃ᵀS̃)⁻¹S̃ᵀ for N > M at full rank (P-A5).
    """
    return _svd_parts(S_scaled, rcond)[0]


def null_projector(S_scaled: np.ndarray, rcond: float = RCOND) -> np.ndarray:
    """P̃ = I − S̃⁺S̃ (M, M), the projector onto the null space of S̃, from the SVD basis (P-A5)."""
    return _svd_parts(S_scaled, rcond)[1]


class Delu(NamedTuple):
    """DELU's scaled steps: ``du2`` ΔŨ₂ (targeting), ``du1`` ΔŨ₁ (optimization), ``K`` (scaled units² per kg)."""

    du2: np.ndarray
    du1: np.ndarray
    K: float


def delu(
    S_scaled: np.ndarray,
    G_scaled: np.ndarray,
    tau: np.ndarray,
    *,
    p: float = 1.0,
    radius: float = 1.0,
    max_performance_change: float = 5.0,
    alpha: float = 1.0,
    rcond: float = RCOND,
) -> Delu:
    """FRACAS DELU: the scaled targeting and optimization steps (DELU-1..3).

    * DELU-1: ΔŨ₂ = −p S̃⁺τ (minimum-norm targeting correction); if |ΔŨ₂| > R it is scaled back to R.
    * DELU-2: ΔŨ₁ = −K P̃ G̃_J (projected gradient of the cost J = −F, so S̃ΔŨ₁ = 0).
    * DELU-3: K = min(ΔF_max / (G̃_JᵀP̃G̃_J), [max(R² − |αΔŨ₂|², 0)]^(1/2) / |P̃G̃_J|): the predicted
      gain K|P̃G̃_J|² is at most ΔF_max (kg) and the combined step stays inside R.  The radius budget
      counts ΔŨ₂ only when it is used (α = 1; choice made here).  K = 0 when P̃G̃_J = 0.

    ``S_scaled`` S̃ (N, M), ``G_scaled`` G̃_J = −D G (M,, kg per scaled unit), ``tau`` (N,).  Pass the
    columns of the retained controls only (DELU-4: dropped controls are removed before S̃⁺).
    """
    S = np.asarray(S_scaled, dtype=float)
    g = np.asarray(G_scaled, dtype=float)
    pinv, proj, _ = _svd_parts(S, rcond)
    du2 = -p * (pinv @ np.asarray(tau, dtype=float))
    n2 = float(np.linalg.norm(du2))
    if n2 > radius:
        du2 = du2 * (radius / n2)
        n2 = radius
    pg = proj @ g
    npg = float(np.linalg.norm(pg))
    if npg == 0.0 or not math.isfinite(npg):
        return Delu(du2, np.zeros_like(g), 0.0)
    budget = math.sqrt(max(radius**2 - (alpha * n2) ** 2, 0.0))
    K = min(max_performance_change / npg**2, budget / npg)
    return Delu(du2, -K * pg, K)


def predicted_slope(
    S_scaled: np.ndarray,
    G_scaled: np.ndarray,
    tau: np.ndarray,
    du_scaled: np.ndarray,
    *,
    alpha: float,
    beta: float,
    max_performance_change: float,
    rcond: float = RCOND,
) -> float:
    """FRACAS SIZE (SIZE-3..5): F'(0) = α F_T'(0) + β F_O'(0) along ΔŨ (dimensionless per unit γ).

    F_T'(0) = 2τᵀS̃ΔŨ and F_O'(0) = G̃_JᵀP̃ΔŨ / ΔF_max (which is G̃_JᵀΔŨ₁/ΔF_max on the combined
    step, since P̃ΔŨ₂ = 0).  Arguments as in :func:`delu` (retained columns only).
    """
    S = np.asarray(S_scaled, dtype=float)
    du = np.asarray(du_scaled, dtype=float)
    g = np.asarray(G_scaled, dtype=float)
    pinv, _, _ = _svd_parts(S, rcond)
    sdu = S @ du
    slope_t = 2.0 * float(np.asarray(tau, dtype=float) @ sdu)
    slope_o = float(g @ du - (pinv.T @ g) @ sdu) / max_performance_change
    return alpha * slope_t + beta * slope_o


def funct(
    tau_trial: np.ndarray,
    performance_trial: float,
    performance_nominal: float,
    restoration: np.ndarray,
    *,
    alpha: float,
    beta: float,
    max_performance_change: float,
) -> float:
    """FRACAS FUNCT (SIZE-2..4): the line-search function F(γ) of one trial, dimensionless.

    F(γ) = α F_T + β F_O with F_T = ‖τ(U + γΔU)‖² and F_O = {J(U+γΔU) − J(U) + G̃_Jᵀ[−S̃⁺τ(U+γΔU)]}/ΔF_max,
    J = −F (kg).  ``restoration`` is (S̃⁺)ᵀG̃_J (N,), so the bracket's last term is −restoration·τ.
    The division by ΔF_max (kg) makes F_O dimensionless like F_T (digest SIZE-4).
    """
    tau_trial = np.asarray(tau_trial, dtype=float)
    f_t = float(tau_trial @ tau_trial)
    f_o = (-(performance_trial - performance_nominal) - float(np.asarray(restoration) @ tau_trial)) / (
        max_performance_change
    )
    return alpha * f_t + beta * f_o


class _Direction(NamedTuple):
    du: np.ndarray  # (M,) scaled, α ΔŨ₂ + β ΔŨ₁ embedded
    du1: np.ndarray
    du2: np.ndarray
    K: float
    slope: float
    restoration: np.ndarray  # (N,) (S̃⁺)ᵀG̃_J on the kept columns
    rank: int
    gain: float  # predicted K|P̃G̃_J|², kg


def _direction(
    St: np.ndarray,
    Gt: np.ndarray,
    tau: np.ndarray,
    kept: list[int],
    alpha: float,
    beta: float,
    s: SearchSettings,
) -> _Direction:
    """SIZE + DELU on the retained controls, embedded back into all M (DELU-4)."""
    m = St.shape[1]
    Sk, Gk = St[:, kept], Gt[kept]
    step = delu(
        Sk,
        Gk,
        tau,
        p=s.correction_fraction,
        radius=s.linearity_radius,
        max_performance_change=s.max_performance_change,
        alpha=alpha,
    )
    pinv, proj, rank = _svd_parts(Sk, RCOND)
    duk = alpha * step.du2 + beta * step.du1
    slope = predicted_slope(Sk, Gk, tau, duk, alpha=alpha, beta=beta, max_performance_change=s.max_performance_change)
    pg = proj @ Gk
    full = lambda x: _embed(x, kept, m)
    return _Direction(
        full(duk), full(step.du1), full(step.du2), step.K, slope, pinv.T @ Gk, rank, step.K * float(pg @ pg)
    )


def _embed(x: np.ndarray, kept: list[int], m: int) -> np.ndarray:
    out = np.zeros(m)
    out[kept] = x
    return out


def _angle(St: np.ndarray, Gt: np.ndarray) -> float:
    """SIZE-6: θ with sin θ = |P̃G̃_J|/|G̃_J| (rad); 0 when G̃_J = 0; nan when N = 0 (P-A5)."""
    if St.shape[0] == 0:
        return math.nan
    ng = float(np.linalg.norm(Gt))
    if ng == 0.0:
        return 0.0
    _, proj, _ = _svd_parts(St, RCOND)
    return math.asin(min(1.0, float(np.linalg.norm(proj @ Gt)) / ng))


def optimality_angle(problem: Problem, u: np.ndarray, S: np.ndarray, G: np.ndarray, weighting: str) -> float:
    """TEST's θ at U for an NLP solver's answer (FRACAS's optimality test, SIZE-6), over the
    controls not held at a bound and with the active switch-order rows counted as constraints:
    sin θ = |P̃ G̃| / |G̃| with P̃ the projector off the rows of [S̃; Ã_active] on the free controls.
    A control is at a bound when within 1e-4 of its floor unit (an interior-point solver stops a
    hair inside: IPOPT left a burn's start 0.06 s after t = 0), a row active when within 1e-4 of
    the floor of its controls.  No free control: 0.  No targets and no active row: nan."""
    u = np.asarray(u, float)
    near = 1e-4 * np.maximum(problem.floor, 1e-300)
    at_bound = (np.abs(u - problem.lower) <= near) | (np.abs(u - problem.upper) <= near)
    free = np.flatnonzero(~at_bound)
    if free.size == 0:
        return 0.0
    d = weights(S, problem.tolerance, u, problem.scale, problem.floor, weighting, problem.value_weighted)
    rows = [S * d[None, :] / problem.tolerance[:, None]] if S.shape[0] else []
    if problem.ineq_matrix is not None:
        A, b = problem.ineq_matrix, problem.ineq_bound
        slack = 1e-4 * np.array([np.max(problem.floor[row != 0.0]) for row in A])
        active = A @ u >= b - slack
        if np.any(active):
            Ad = A[active] * d[None, :]
            rows.append(Ad / np.maximum(np.abs(Ad).max(axis=1, keepdims=True), 1e-300))
    if not rows:
        return math.nan
    St = np.vstack(rows)
    return _angle(St[:, free], (-d * G)[free])


def _ill_conditioned(St: np.ndarray, theta_min: float) -> bool:
    """Gate of STEST in the search: drop dependent controls only when S̃ itself is ill-conditioned,
    σ_min(N, M)/σ_max < sin θ_min.  With N = 1 every pair of columns is parallel, and with spare
    independent columns a parallel pair costs no rank; dropping there would only remove the
    optimization freedom, so STEST is skipped (choice made here)."""
    if St.shape[0] == 0 or St.shape[1] < 2:
        return False
    sv = np.linalg.svd(St, compute_uv=False)
    return bool(sv[0] > 0 and sv[-1] < math.sin(theta_min) * sv[0])
