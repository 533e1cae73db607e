"""The data of TOM's projected-gradient search (FRACAS UPHILL's inputs and outputs, digest §A.2/§A.5).

:class:`Evaluation` (one FEGS trajectory), :class:`SearchSettings` (UPHILL/$DATA), :class:`Problem`
(what the search needs), :class:`Trial` (one FUNCT trial of GENMIN), :class:`IterationRecord`
(UPHILL's per-iteration summary) and :class:`SearchResult`, with the constants they check against.
Re-exported by :mod:`fracas.tom.search`, whose docstring gives the notation.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

#: Relative singular-value cutoff of the pseudo-inverse (P-A5): σ_i ≤ RCOND·σ_max counts as zero.
RCOND = 1e-10

SUBMODES = ("target", "target_optimize", "optimize", "auto")
WEIGHTINGS = ("sensitivity", "control")


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
