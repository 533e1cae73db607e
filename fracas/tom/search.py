"""TOM's projected-gradient targeting / final-mass optimization search (FRACAS, NASA CR-112256 §5.2).

The numeric kernel of the routines UPHILL (driver), FEGS (through the caller's callbacks), TEST,
WEIGHT, STEST, SIZE, DELU, FUNCT, GENMIN, MINMUM, BUCKET and STEP, rebuilt as in the TOM digest
(``tom-tsim-guidance.md`` Part A, equations WEIGHT-1/2, STEST-1, TEST-1, DELU-1..4, SIZE-1..6,
MINMUM-1/2a/2b/2c/3, BUCKET-1 and pitfalls P-A1..P-A12).  Pure NumPy: arrays and callables in,
arrays out; no deck, no file, no printing.

Notation (digest §A.3).  Controls U (M,), targets T(U) (N,), ΔT = T − T0, tolerances ε (N,),
performance F = final mass (kg, maximized).  Internally the cost J = −F is minimized (P-A1).
Scaled variables: D = W^(1/2) = diag(d) from WEIGHT, Ũ = D⁻¹U, τ = ΔT/ε, S̃ = E_ε⁻¹ S D,
G̃_J = −D G.  In these variables the report's unweighted formulas apply (S̃⁺ = S̃ᵀ(S̃S̃ᵀ)⁻¹ at
full row rank; an SVD with a relative cutoff in general, P-A5) and P̃ = I − S̃⁺S̃.

Choices made here where the digest leaves one (each is repeated in the function it concerns):

* The linearity radius R and the step size act in scaled units.  Under sensitivity weighting
  (WEIGHT-1) one scaled unit of control j is the change that moves its most sensitive target by
  k_j tolerances, so R = 1 allows roughly one tolerance of target change per iteration (times
  γ_max); choose k_j or R accordingly when the start is far from the targets.
* W is recomputed every iteration (WEIGHT is inside the UPHILL loop).
* One line search along ΔU = α ΔU₂ + β ΔU₁ (SIZE-5).
* Bounds (P-A7): every trial and every STEP is clipped to [lower, upper]; a control at a bound
  whose step pushes outward is dropped (ΔU_j = 0) and the step recomputed, until no kept control
  pushes outward (an active set rebuilt every iteration, so controls come back when the step
  turns inward).  These controls and the STEST ones are reported in ``IterationRecord.dropped``.
* The gradient angle θ (SIZE-6) is computed over the controls not held at a bound (the STEST
  drop is a conditioning device for the step and does not count as a constraint), so two
  controls with parallel target columns but different mass gradients cannot fake convergence.
* TEST in ``auto``: TEST-1 picks T / T+O / O from E_rms; when it picks O, θ < θ_conv but some
  target is still outside its tolerance, the iteration runs T+O instead (O alone never corrects
  the targets and would stall).
* N = 0 (no targets): θ is undefined (nan); converged when the first-order gain reachable inside
  the linearity radius, R·|G̃_J| (kg), is at most θ_conv·ΔF_max.
* ``SearchResult.n_evaluations`` counts ``evaluate`` calls (line-search trials, plus the start when
  ``given_S`` is used); ``n_sensitivity_evaluations`` counts ``sensitivities`` calls (each also
  yields the nominal trajectory); ``IterationRecord.n_evaluations`` is their running sum.  The
  caller knows what one sensitivity call costs in trajectories.
* STEST is applied only when S̃ is ill-conditioned (σ_min/σ_max < sin θ_min), see
  :func:`dependent_controls`.
* A T+O line search that finds no decrease, or only a step γ < 1e-3, while a target is outside
  its tolerance is retried as targeting only (the curvature of the targets along ΔU₁ swamps F_T
  when ε is tight); O steps then do the optimizing and T steps restore the targets.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

#: Relative singular-value cutoff of the pseudo-inverse (P-A5): σ_i ≤ RCOND·σ_max counts as zero.
RCOND = 1e-10

SUBMODES = ("target", "target_optimize", "optimize", "auto")
WEIGHTINGS = ("sensitivity", "control")
_TINY_STEP = 1e-3  # a T+O step below this γ counts as failed (retried as targeting only)
_COINCIDE = 1e-3  # GENMIN: a fitted γ within this relative distance of a flown trial is that trial


# ----------------------------------------------------------------------------------------- data


class Evaluation(NamedTuple):
    """One trajectory (FRACAS FEGS, nominal only).

    ``targets``: (N,) achieved target values T(U), in the targets' units.  ``performance``: F, the
    final mass, kg (maximized).  ``ok``: False when the propagation failed or the target event was
    not reached; the search then treats F = −inf and E = +inf (P-A12).
    """

    targets: np.ndarray
    performance: float
    ok: bool


@dataclass(frozen=True)
class SearchSettings:
    """UPHILL/$DATA inputs of the search (digest §A.2).

    submode: "target" (targeting only), "target_optimize", "optimize" or "auto" (TEST-1 decides
    from E_rms each iteration).  max_performance_change: ΔF_max, kg.  correction_fraction: p, the
    fraction of τ removed per step (applied every iteration, P-A6).  linearity_radius: R, scaled
    control units.  max_scale_factor: γ_max.  curve_fit_tolerance: η (GENMIN acceptance).
    dependent_angle_rad: θ_min (STEST).  convergence_angle_rad: θ_conv (TEST).  targeting_threshold
    and optimization_threshold: T_up and T_low, compared with E_rms of ΔT_i/ε_i (P-A2).
    weighting: "sensitivity" (WEIGHT-1) or "control" (WEIGHT-2).  max_trials: GENMIN trials per
    line search.  min_performance_gain: kg; when > 0, optimization stops once the targets are within
    tolerance and the predicted gain K|P̃G̃_J|² of the next step is below it.
    """

    submode: str = "auto"
    max_iterations: int = 100
    max_performance_change: float = 5.0
    correction_fraction: float = 1.0
    linearity_radius: float = 1.0
    max_scale_factor: float = 4.0
    curve_fit_tolerance: float = 0.1
    dependent_angle_rad: float = 0.017453292519943295
    convergence_angle_rad: float = 1e-3
    targeting_threshold: float = 10.0
    optimization_threshold: float = 1.0
    weighting: str = "sensitivity"
    max_trials: int = 6
    min_performance_gain: float = 0.0
    optimization_step_limit: float = math.inf  # E_rms an O-mode trial may reach (inf: no limit; the adaptive
    # performance request made a finite one unnecessary on the examples, and it stalls tight-tolerance problems)

    def __post_init__(self) -> None:
        if self.submode not in SUBMODES:
            raise ValueError(f"submode must be one of {SUBMODES}, not {self.submode!r}")
        if self.weighting not in WEIGHTINGS:
            raise ValueError(f"weighting must be one of {WEIGHTINGS}, not {self.weighting!r}")
        if self.max_iterations < 0 or self.max_trials < 1:
            raise ValueError("max_iterations must be >= 0 and max_trials >= 1")
        positive = {
            "max_performance_change": self.max_performance_change,
            "correction_fraction": self.correction_fraction,
            "max_scale_factor": self.max_scale_factor,
            "curve_fit_tolerance": self.curve_fit_tolerance,
            "convergence_angle_rad": self.convergence_angle_rad,
        }
        for name, value in positive.items():
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be finite and > 0, not {value!r}")
        if not (self.linearity_radius > 0):  # math.inf: no radius (ΔF_max, p and GENMIN bound the step)
            raise ValueError(f"linearity_radius must be > 0 (inf for none), not {self.linearity_radius!r}")
        if not (0 <= self.dependent_angle_rad < math.pi / 2):
            raise ValueError("dependent_angle_rad must lie in [0, pi/2)")
        if self.optimization_threshold > self.targeting_threshold:
            raise ValueError("optimization_threshold (T_low) must not exceed targeting_threshold (T_up)")
        if self.min_performance_gain < 0:
            raise ValueError("min_performance_gain must be >= 0")


@dataclass
class Problem:
    """What the search needs; all arrays float64, controls in canonical units.

    ``evaluate(U) -> Evaluation``; ``sensitivities(U) -> (Evaluation, S (N, M) = dT/dU, G (M,) =
    dF/dU)`` (kg per control unit).  ``target_error(T) -> ΔT`` (default T − desired; lets angle
    targets wrap to (−π, π], P-A4).  ``given_S``/``given_G`` ($SMAG) replace the sensitivities at
    iteration 1 (``evaluate`` is still called for T and F).  ``scale``: k_j; ``floor``: U_floor of
    control weighting (WEIGHT-2), control units.
    """

    u0: np.ndarray
    desired: np.ndarray
    tolerance: np.ndarray
    scale: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    floor: np.ndarray
    evaluate: Callable[[np.ndarray], Evaluation]
    sensitivities: Callable[[np.ndarray], tuple[Evaluation, np.ndarray, np.ndarray]]
    target_error: Callable[[np.ndarray], np.ndarray] | None = None
    given_S: np.ndarray | None = None
    given_G: np.ndarray | None = None
    labels: tuple[str, ...] = ()
    target_labels: tuple[str, ...] = ()
    value_weighted: np.ndarray | None = None  # (M,) bool, see :func:`weights`
    # linear inequality constraints ineq_matrix @ U <= ineq_bound (K, M) and (K,): the thrust arcs'
    # switch order t_on[k] <= t_off[k] <= t_on[k+1] (None: none)
    ineq_matrix: np.ndarray | None = None
    ineq_bound: np.ndarray | None = None
    # (M,) bool: unbounded angle controls (rad) that are periodic (an in-plane angle, a right
    # ascension): the search wraps them to (-pi, pi] after each step so they cannot drift
    periodic: np.ndarray | None = None


@dataclass
class Trial:
    """One FUNCT trial of GENMIN: γ, the line-search function F(γ) (dimensionless, +inf when the
    trajectory failed), the trial's final mass (kg), its error index E and whether it flew."""

    gamma: float
    cost: float
    performance: float
    error_index: float
    ok: bool


@dataclass
class IterationRecord:
    """The per-iteration summary of UPHILL (digest §A.5).

    ``u``, ``targets``, ``tau`` (ΔT/ε), ``performance`` (kg), ``error_index`` (E = Σ τ²),
    ``error_rms`` and ``angle_rad`` (θ, nan when undefined) describe the point at the start of the
    iteration; ``gamma`` is the accepted step factor (0 when no step was taken), ``du`` the search
    direction D(αΔŨ₂ + βΔŨ₁) and ``du1``/``du2`` its optimization/targeting parts, all in control
    units (the step taken is clip(u + γ du) − u); ``dropped`` the controls held at ΔU_j = 0 (STEST
    first, then active bounds); ``predicted_slope`` F'(0); ``n_evaluations`` the cumulative
    ``evaluate`` + ``sensitivities`` calls.
    """

    iteration: int
    submode: str
    u: np.ndarray
    targets: np.ndarray
    tau: np.ndarray
    performance: float
    error_index: float
    error_rms: float
    angle_rad: float
    gamma: float
    du: np.ndarray
    du1: np.ndarray
    du2: np.ndarray
    dropped: tuple[int, ...]
    trials: list[Trial] = field(default_factory=list)
    predicted_slope: float = math.nan
    n_evaluations: int = 0


@dataclass
class SearchResult:
    """Outcome of the search.  ``u``/``evaluation``: the best iterate (the converged one when
    ``search_converged``).  ``search_converged`` is the algorithm's own test; re-verify it.
    ``time_*``: wall seconds in ``sensitivities`` calls, in ``evaluate`` calls, and in the rest.
    ``first_order_optimality``: the NLP solvers' own measure at the returned point where they
    report one (trust-constr: ‖∇ₓL‖∞ of the Lagrangian in scaled controls Ũ, objective −F/ΔF_max);
    nan where the search has none."""

    u: np.ndarray
    evaluation: Evaluation
    history: list[IterationRecord]
    stop_reason: str
    search_converged: bool
    n_evaluations: int
    n_sensitivity_evaluations: int
    time_sensitivities_s: float
    time_line_search_s: float
    time_bookkeeping_s: float
    first_order_optimality: float = math.nan


# ------------------------------------------------------------------------------ pure kernels


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


# ------------------------------------------------------------------------------ the search


class _Direction(NamedTuple):
    du: np.ndarray  # (M,) scaled, α ΔŨ₂ + β ΔŨ₁ embedded
    du1: np.ndarray
    du2: np.ndarray
    K: float
    slope: float
    restoration: np.ndarray  # (N,) (S̃⁺)ᵀG̃_J on the kept columns
    rank: int
    gain: float  # predicted K|P̃G̃_J|², kg


def _direction(St, Gt, tau, kept, alpha, beta, s: SearchSettings) -> _Direction:
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


def _names(idx: Sequence[int], labels: Sequence[str], kind: str) -> str:
    return ", ".join(repr(labels[i]) if i < len(labels) else f"{kind} {i}" for i in idx)


def _as_vector(x, n: int, name: str) -> np.ndarray:
    a = np.array(x, dtype=float).reshape(-1)
    if a.shape != (n,):
        raise ValueError(f"{name} has shape {np.shape(x)}, expected ({n},)")
    return a


def _validated(problem: Problem) -> Problem:
    u0 = np.array(problem.u0, dtype=float).reshape(-1)
    m = u0.size
    if m == 0:
        raise ValueError("the problem has no controls (u0 is empty)")
    desired = np.array(problem.desired, dtype=float).reshape(-1)
    n = desired.size
    tol = _as_vector(problem.tolerance, n, "tolerance")
    if not np.all(np.isfinite(tol) & (tol > 0)):
        bad = np.flatnonzero(~(np.isfinite(tol) & (tol > 0)))
        raise ValueError(
            f"tolerance must be finite and > 0; not for target {_names(bad, problem.target_labels, 'target')}"
        )
    scale = _as_vector(problem.scale, m, "scale")
    if not np.all(np.isfinite(scale) & (scale > 0)):
        raise ValueError("scale (control weightings k_j) must be finite and > 0")
    lower = _as_vector(problem.lower, m, "lower")
    upper = _as_vector(problem.upper, m, "upper")
    floor = _as_vector(problem.floor, m, "floor")
    if np.any(floor < 0) or not np.all(np.isfinite(floor)):
        raise ValueError("floor must be finite and >= 0")
    if problem.labels and len(problem.labels) != m:
        raise ValueError(f"{len(problem.labels)} control labels for {m} controls")
    if problem.target_labels and len(problem.target_labels) != n:
        raise ValueError(f"{len(problem.target_labels)} target labels for {n} targets")
    bad = np.flatnonzero(lower > upper)
    if bad.size:
        raise ValueError(f"lower > upper for control {_names(bad, problem.labels, 'control')}")
    bad = np.flatnonzero(~np.isfinite(u0) | (u0 < lower) | (u0 > upper))
    if bad.size:
        raise ValueError(
            f"u0 is outside its bounds (or not finite) for control {_names(bad, problem.labels, 'control')}"
        )
    given_S = given_G = None
    if problem.given_S is not None or problem.given_G is not None:
        if problem.given_S is None or problem.given_G is None:
            raise ValueError("given_S and given_G ($SMAG) must be given together")
        if n and np.shape(problem.given_S) != (n, m):
            raise ValueError(f"given_S has shape {np.shape(problem.given_S)}, expected ({n}, {m})")
        given_S = np.array(problem.given_S, dtype=float) if n else np.zeros((0, m))
        given_G = _as_vector(problem.given_G, m, "given_G")
    ineq_matrix = ineq_bound = None
    if problem.ineq_matrix is not None and np.size(problem.ineq_matrix):
        ineq_matrix = np.array(problem.ineq_matrix, dtype=float).reshape(-1, m)
        ineq_bound = _as_vector(problem.ineq_bound, ineq_matrix.shape[0], "ineq_bound")
        if np.any(ineq_matrix @ u0 > ineq_bound + 1e-9 * (1.0 + np.abs(ineq_bound))):
            raise ValueError("u0 violates the switch-order constraints (an arc inverted or overlapping the next)")
    return Problem(
        u0=u0,
        desired=desired,
        tolerance=tol,
        scale=scale,
        lower=lower,
        upper=upper,
        floor=floor,
        evaluate=problem.evaluate,
        sensitivities=problem.sensitivities,
        target_error=problem.target_error,
        given_S=given_S,
        given_G=given_G,
        labels=tuple(problem.labels),
        target_labels=tuple(problem.target_labels),
        value_weighted=problem.value_weighted,
        ineq_matrix=ineq_matrix,
        ineq_bound=ineq_bound,
        periodic=None if problem.periodic is None else np.asarray(problem.periodic, bool).reshape(m),
    )


def wrap_periodic(u: np.ndarray, periodic: np.ndarray | None) -> np.ndarray:
    """U with its periodic angle controls (rad) wrapped to (-pi, pi] (the same trajectory)."""
    if periodic is None or not np.any(periodic):
        return u
    out = np.array(u, dtype=float, copy=True)
    out[periodic] = -np.remainder(-out[periodic] + np.pi, 2.0 * np.pi) + np.pi
    return out


def feasible_point(x, lower, upper, ineq_matrix=None, ineq_bound=None) -> np.ndarray:
    """The nearest point to x (Euclidean, control units) within the bounds and the linear
    constraints ineq_matrix @ U <= ineq_bound (the arcs' switch order): clip(x) when that
    already satisfies them, else the small QP solved by SciPy's SLSQP.  A trial step of the
    projected-gradient search goes through this, so an arc can close (start = end) but never
    invert or overlap the next one."""
    y = np.clip(np.asarray(x, float), lower, upper)
    if ineq_matrix is None:
        return y
    slack = 1e-12 * (1.0 + np.abs(ineq_bound))
    if np.all(ineq_matrix @ y <= ineq_bound + slack):
        return y
    from scipy.optimize import Bounds, LinearConstraint, minimize

    moved = np.flatnonzero(np.any(ineq_matrix != 0.0, axis=0))
    # one common scale (the distance stays Euclidean in U; the QP is O(1))
    scale = np.full(moved.size, max(float(np.max(np.abs(y[moved]))), 1.0))
    a = ineq_matrix[:, moved] * scale[None, :]
    rest = ineq_bound - ineq_matrix @ np.where(np.isin(np.arange(y.size), moved), 0.0, y)
    z0 = y[moved] / scale
    res = minimize(
        lambda z: 0.5 * float((z - z0) @ (z - z0)),
        z0,
        jac=lambda z: z - z0,
        method="SLSQP",
        bounds=Bounds(lower[moved] / scale, upper[moved] / scale),
        constraints=[LinearConstraint(a, -np.inf, rest)],
        options={"ftol": 1e-15, "maxiter": 200},
    )
    y[moved] = np.clip(res.x * scale, lower[moved], upper[moved])
    # SLSQP leaves the active rows satisfied to its tolerance: close the remaining gap exactly by
    # pulling each violated pair to its midpoint (rows are t_a - t_b <= c with one control each side)
    for _ in range(3):
        viol = ineq_matrix @ y - ineq_bound
        if np.all(viol <= slack):
            break
        for k in np.flatnonzero(viol > slack):
            row = ineq_matrix[k]
            nz = np.flatnonzero(row)
            y[nz] -= viol[k] * row[nz] / float(row @ row)
    return y


def _better(a: tuple[bool, float, float], b: tuple[bool, float, float]) -> bool:
    """Is point a = (within tolerance, F, E) better than b?  Feasible beats infeasible; among
    feasible points the higher F; among infeasible ones the lower E."""
    if a[0] != b[0]:
        return a[0]
    return a[1] > b[1] if a[0] else a[2] < b[2]


class _Counter:
    def __init__(self, problem: Problem):
        self.problem = problem
        self.n_eval = 0
        self.n_sens = 0
        self.t_eval = 0.0
        self.t_sens = 0.0
        self.t0 = time.perf_counter()

    def evaluate(self, u: np.ndarray, n: int) -> Evaluation:
        t = time.perf_counter()
        try:
            ev = self.problem.evaluate(u.copy())
        finally:
            self.t_eval += time.perf_counter() - t
            self.n_eval += 1
        return _clean(ev, n)

    def sensitivities(self, u: np.ndarray, n: int, m: int):
        t = time.perf_counter()
        try:
            ev, S, G = self.problem.sensitivities(u.copy())
        finally:
            self.t_sens += time.perf_counter() - t
            self.n_sens += 1
        S = np.array(S, dtype=float).reshape(n, m) if n else np.zeros((0, m))
        return _clean(ev, n), S, np.array(G, dtype=float).reshape(m)


def _clean(ev: Evaluation, n: int) -> Evaluation:
    targets = np.array(ev.targets, dtype=float).reshape(-1)
    ok = bool(ev.ok) and targets.shape == (n,) and np.all(np.isfinite(targets)) and math.isfinite(ev.performance)
    return Evaluation(targets, float(ev.performance), bool(ok))


def result_of(u, ev, history, reason, converged, n_eval, n_sens, t_sens, t_eval, t_start) -> SearchResult:
    """The :class:`SearchResult` of a finished search (wall time split: sensitivities, line
    search, and the rest as bookkeeping, from ``t_start`` = time.perf_counter() at the start)."""
    total = time.perf_counter() - t_start
    return SearchResult(
        u=np.array(u, dtype=float, copy=True),
        evaluation=ev,
        history=history,
        stop_reason=reason,
        search_converged=converged,
        n_evaluations=n_eval,
        n_sensitivity_evaluations=n_sens,
        time_sensitivities_s=t_sens,
        time_line_search_s=t_eval,
        time_bookkeeping_s=max(total - t_sens - t_eval, 0.0),
    )


def projected_gradient(
    problem: Problem,
    settings: SearchSettings = SearchSettings(),
    on_iteration: Callable[[IterationRecord], None] | None = None,
) -> SearchResult:
    """FRACAS UPHILL: the projected-gradient targeting / final-mass optimization loop (digest §A.4).

    Per iteration: FEGS (``sensitivities``; ``given_S``/``given_G`` at iteration 1), WEIGHT, TEST
    (submode and convergence), STEST, active bounds, SIZE/DELU, GENMIN along ΔU = D(αΔŨ₂ + βΔŨ₁),
    STEP U ← clip(U + γ*ΔU).  F'(0) ≥ 0 with optimization active refuses the step and retries as
    targeting only (P-A10); so does a T+O line search that finds no decrease while a target is out
    of tolerance (that iteration then has two records: the failed T+O one with γ = 0, and the T one).
    Convergence (TEST): optimization active → every |ΔT_i| ≤ ε_i and
    θ < θ_conv; ``submode="target"`` → every |ΔT_i| ≤ ε_i; N = 0 → R·|G̃_J| ≤ θ_conv·ΔF_max (kg).
    Iteration ``max_iterations + 1`` only tests the last point.

    Never raises for numeric trouble: it returns the best iterate (feasible beats infeasible, then
    higher F, else lower E; the final point when converged) with a ``stop_reason``.  ValueError only
    for malformed inputs.  See the module docstring for the choices made.
    """
    s = settings
    prob = _validated(problem)
    m, n = prob.u0.size, prob.desired.size
    if n == 0 and s.submode in ("target", "target_optimize"):
        raise ValueError(f"submode {s.submode!r} needs targets; the problem has none")
    desired, tol, lower, upper = prob.desired, prob.tolerance, prob.lower, prob.upper
    err = prob.target_error or (lambda T: T - desired)
    cnt = _Counter(prob)
    history: list[IterationRecord] = []

    def tau_of(ev: Evaluation) -> np.ndarray:
        return np.asarray(err(ev.targets), dtype=float).reshape(n) / tol

    def finish(u, ev, reason, converged):
        return result_of(u, ev, history, reason, converged, cnt.n_eval, cnt.n_sens, cnt.t_sens, cnt.t_eval, cnt.t0)

    u = prob.u0.copy()
    if prob.given_S is not None:
        ev = cnt.evaluate(u, n)
        S, G = prob.given_S, prob.given_G
    else:
        ev, S, G = cnt.sensitivities(u, n, m)
    if not ev.ok:
        return finish(u, ev, "trajectory failed at the starting controls", False)
    tau = tau_of(ev)
    if not np.all(np.isfinite(tau)):
        return finish(u, ev, "target error not finite at the starting controls", False)

    def key(ev_, tau_):
        return (bool(np.all(np.abs(tau_) <= 1.0)), ev_.performance, float(tau_ @ tau_))

    best_u, best_ev, best_key = u.copy(), ev, key(ev, tau)
    reason, converged = "", False
    # ΔF_max is the most an iteration may ask for (kg); the step asks for dfmax <= ΔF_max,
    # twice the gain the last optimization step achieved (a line search from a 5 kg request
    # near an optimum with 0.1 kg left spends its trials shrinking), divided by 10 after an
    # optimization line search finds no decrease, down to 1e-9 ΔF_max.
    dfmax = settings.max_performance_change

    def iteration(it: int) -> bool:
        """One UPHILL pass; True when the search stops (``reason``/``converged`` set)."""
        nonlocal u, ev, S, G, tau, best_u, best_ev, best_key, reason, converged, s, dfmax
        s = dataclasses.replace(settings, max_performance_change=dfmax)
        if it > 1:
            ev, S, G = cnt.sensitivities(u, n, m)
            if not ev.ok:
                reason = f"trajectory failed at the accepted controls of iteration {it - 1} (sensitivity call)"
                return True
            tau = tau_of(ev)
        if not (np.all(np.isfinite(S)) and np.all(np.isfinite(G)) and np.all(np.isfinite(tau))):
            reason = f"sensitivities not finite at iteration {it}"
            return True
        E = float(tau @ tau)
        e_rms = math.sqrt(E / n) if n else 0.0
        feasible = bool(np.all(np.abs(tau) <= 1.0))
        d = weights(S, tol, u, prob.scale, prob.floor, s.weighting, prob.value_weighted)
        St = S * d[None, :] / tol[:, None]
        Gt = -d * G
        label = choose_submode(e_rms, s) if n else "O"
        stest = dependent_controls(St, s.dependent_angle_rad) if _ill_conditioned(St, s.dependent_angle_rad) else ()

        def plan(label_):
            alpha, beta = {"T": (1.0, 0.0), "T+O": (1.0, 1.0), "O": (0.0, 1.0)}[label_]
            active: list[int] = []
            while True:
                kept = [j for j in range(m) if j not in stest and j not in active]
                dr = _direction(St, Gt, tau, kept, alpha, beta, s)
                du = dr.du * d
                out = [j for j in kept if (u[j] <= lower[j] and du[j] < 0) or (u[j] >= upper[j] and du[j] > 0)]
                if not out:
                    break
                active.extend(out)
            free = [j for j in range(m) if j not in active]
            theta = _angle(St[:, free], Gt[free]) if free else (math.nan if n == 0 else 0.0)
            return alpha, beta, active, kept, dr, theta, free

        alpha, beta, active, kept, dr, theta, free = plan(label)
        if s.submode == "auto" and n and label == "O" and not feasible and theta < s.convergence_angle_rad:
            label = "T+O"
            alpha, beta, active, kept, dr, theta, free = plan(label)

        # TEST: convergence.
        why = ""
        if n == 0:
            radius = s.linearity_radius if math.isfinite(s.linearity_radius) else 1.0
            reach = radius * float(np.linalg.norm(Gt[free]))
            if reach <= s.convergence_angle_rad * s.max_performance_change:
                why = (
                    f"converged: no targets and first-order gain within the linearity radius {reach:.1e} kg"
                    f" <= {s.convergence_angle_rad * s.max_performance_change:.1e} kg"
                )
        elif feasible and label == "T" and s.submode == "target":
            why = "converged: targets within tolerance (targeting only)"
        elif feasible and beta:
            if theta < s.convergence_angle_rad:
                why = (
                    f"converged: targets within tolerance and gradient angle {theta:.1e} rad"
                    f" < {s.convergence_angle_rad:.1e}"
                )
            elif s.min_performance_gain > 0 and dr.gain < s.min_performance_gain:
                why = (
                    f"converged: targets within tolerance and predicted performance gain {dr.gain:.1e} kg"
                    f" < {s.min_performance_gain:.1e} kg"
                )

        def record(label_, gamma, dr_, trials, dropped):
            rec = IterationRecord(
                # the limit's final test of the last point belongs to the last iteration (a run with a
                # limit of 200 reports 200 iterations, not 201)
                iteration=min(it, max(s.max_iterations, 1)),
                submode=label_,
                u=u.copy(),
                targets=ev.targets.copy(),
                tau=tau.copy(),
                performance=ev.performance,
                error_index=E,
                error_rms=e_rms,
                angle_rad=theta,
                gamma=gamma,
                du=dr_.du * d,
                du1=dr_.du1 * d,
                du2=dr_.du2 * d,
                dropped=dropped,
                trials=trials,
                predicted_slope=dr_.slope,
                n_evaluations=cnt.n_eval + cnt.n_sens,
            )
            history.append(rec)
            if on_iteration is not None:
                on_iteration(rec)

        dropped = tuple(stest) + tuple(active)
        if why:
            converged, reason = True, why
            record(label, 0.0, dr, [], dropped)
            return True
        if it > s.max_iterations:
            reason = f"iteration limit ({s.max_iterations}) reached"
            record(label, 0.0, dr, [], dropped)
            return True

        # P-A10: a non-descent direction with optimization active falls back to targeting only.
        if not dr.slope < 0 and beta and n and not np.all(tau == 0):
            alpha_t, beta_t, active_t, kept_t, dr_t, _, _ = plan("T")
            if dr_t.slope < 0:
                label, alpha, beta, active, kept, dr = "T", alpha_t, beta_t, active_t, kept_t, dr_t
                dropped = tuple(stest) + tuple(active)

        def singular_note() -> str:
            if not n or feasible or not alpha:
                return ""
            r = dr.rank
            if r >= min(n, len(kept)) and len(kept) >= n:
                return ""
            Sk = St[:, kept]
            rownorm = np.linalg.norm(Sk, axis=1)
            dead = np.flatnonzero(rownorm <= RCOND * max(float(rownorm.max(initial=0.0)), 1e-300))
            msg = f"sensitivity matrix singular: rank {r} of the {len(kept)} retained controls < {n} targets"
            if dead.size:
                msg += f"; no control authority over target {_names(dead, prob.target_labels, 'target')}"
            if stest:
                msg += f"; dropped as dependent (STEST): {_names(stest, prob.labels, 'control')}"
            return msg

        if not dr.slope < 0:
            note = singular_note()
            reason = (note + "; " if note else "") + f"line search found no decrease (F'(0) = {dr.slope:.3e} >= 0)"
            record(label, 0.0, dr, [], dropped)
            return True

        def step_to(gamma: float) -> np.ndarray:
            """STEP: U + γΔU clipped to the bounds and projected onto the arcs' switch order."""
            return feasible_point(u + gamma * du, lower, upper, prob.ineq_matrix, prob.ineq_bound)

        # GENMIN on FUNCT.
        trials: list[Trial] = []
        flown: dict[float, Evaluation] = {}
        du = dr.du * d
        f_nom = ev.performance
        f0 = funct(
            tau,
            f_nom,
            f_nom,
            dr.restoration,
            alpha=alpha,
            beta=beta,
            max_performance_change=s.max_performance_change,
        )

        def cost(gamma: float) -> float:
            ut = step_to(gamma)
            evt = cnt.evaluate(ut, n)
            flown[gamma] = evt
            if not evt.ok:
                trials.append(Trial(gamma, math.inf, -math.inf, math.inf, False))
                return math.inf
            taut = tau_of(evt)
            if alpha == 0.0 and n and math.sqrt(float(taut @ taut) / n) > s.optimization_step_limit:
                # optimization only: a trial that leaves the region E_rms <= optimization_step_limit is
                # no decrease, whatever FUNCT's linear restoration estimate says (it is blind
                # to a step that large; seen on the Hohmann test, an O step to E_rms 1e5)
                trials.append(Trial(gamma, math.inf, evt.performance, float(taut @ taut), False))
                return math.inf
            c = funct(
                taut,
                evt.performance,
                f_nom,
                dr.restoration,
                alpha=alpha,
                beta=beta,
                max_performance_change=s.max_performance_change,
            )
            c = c if math.isfinite(c) else math.inf
            trials.append(Trial(gamma, c, evt.performance, float(taut @ taut), bool(math.isfinite(c))))
            return c

        def line_search(f_start, slope):
            return genmin(
                cost,
                f_start,
                slope,
                gamma_max=s.max_scale_factor,
                eta=s.curve_fit_tolerance,
                max_trials=s.max_trials,
                first=1.0,
            )[0]

        gamma = line_search(f0, dr.slope)
        if gamma < _TINY_STEP and alpha and beta and not feasible:
            # The combined step found no (or only a negligible) decrease: typically the curvature of
            # the targets along ΔU₁ swamps F_T.  Record it and retry this iteration as targeting only;
            # keep the T+O step if targeting alone finds nothing.
            alpha_t, beta_t, active_t, kept_t, dr_t, _, _ = plan("T")
            if dr_t.slope < 0:
                record(label, 0.0, dr, trials, dropped)
                saved = (label, alpha, beta, active, kept, dr, dropped, trials, du, gamma, flown.get(gamma))
                label, alpha, beta, active, kept, dr = "T", alpha_t, beta_t, active_t, kept_t, dr_t
                dropped = tuple(stest) + tuple(active)
                trials, du = [], dr.du * d
                f0 = funct(tau, f_nom, f_nom, dr.restoration, alpha=1.0, beta=0.0, max_performance_change=1.0)
                gamma = line_search(f0, dr.slope)
                if gamma == 0.0 and saved[9] > 0.0:
                    history.pop()
                    label, alpha, beta, active, kept, dr, dropped, trials, du, gamma, ev_saved = saved
                    flown[gamma] = ev_saved
        record(label, gamma, dr, trials, dropped)
        if gamma == 0.0 and beta and dfmax > 1e-9 * settings.max_performance_change:
            dfmax /= 10.0  # ask for less and try again from the same point
            return False
        if gamma > 0.0 and beta:
            gain = abs(flown[gamma].performance - f_nom)
            dfmax = min(settings.max_performance_change, max(2.0 * gain, 1e-9 * settings.max_performance_change))
        if gamma == 0.0:
            note = singular_note()
            reason = (note + "; " if note else "") + (
                f"line search found no decrease in {len(trials)} trials (F'(0) = {dr.slope:.3e})"
            )
            return True
        u = wrap_periodic(step_to(gamma), prob.periodic)
        ev = flown[gamma]
        tau = tau_of(ev)
        k_new = key(ev, tau)
        if _better(k_new, best_key):
            best_u, best_ev, best_key = u.copy(), ev, k_new
        return False

    for it in range(1, s.max_iterations + 2):
        if iteration(it):
            break

    if converged:
        return finish(u, ev, reason, True)
    return finish(best_u, best_ev, reason, False)
