"""A second optimizer for TOM's problem: SciPy's SLSQP or trust-constr on the same scaled problem.

Not in the report (P-A9: "SQP would be an extension"): it serves as an independent check of
:func:`fracas.tom.search.projected_gradient` and as a faster alternative near the optimum.

The problem is the projected-gradient search's, in its scaled variables (digest §A.3):

* controls Ũ = D⁻¹U, D = diag(d) from WEIGHT (:func:`~fracas.tom.search.weights`) at the start
  point, held fixed for the whole run;
* objective −F(U)/ΔF_max (dimensionless; F the final mass, kg), gradient −D G/ΔF_max;
* equality constraints τ(U) = ΔT/ε = 0, Jacobian S̃ = E_ε⁻¹ S D;
* bounds lower/d ≤ Ũ ≤ upper/d.

Values and derivatives come from ``problem.sensitivities`` (``given_S``/``given_G`` at the start
point when given), cached per Ũ so the objective, constraints and their Jacobians at one point
cost one call.  A trajectory that fails (``ok`` False, P-A12) returns a large objective (1e30) and
constraint values, with zero derivatives; the optimizer usually backs off or fails with a message.
Core module: arrays and callables in, arrays out; no printing.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable

import numpy as np
from scipy.optimize import BFGS, Bounds, LinearConstraint, NonlinearConstraint, OptimizeResult, minimize

from fracas.tom.scaled import ScaledPoints
from fracas.tom.search_support import _validated
from fracas.tom.search_types import IterationRecord, Problem, SearchResult, SearchSettings

METHODS = ("slsqp", "trust_constr")
_FAIL = 1e30
# SLSQP's ftol on the objective −F/ΔF_max: Kraft's test is |Δf| < ftol (or a step below it) AND the
# constraint violation < ftol.  1e-8 ΔF_max (5e-8 kg for ΔF_max = 5 kg) is far below any difference
# that matters and above the ~1e-11 relative noise of an integrated trajectory's F (1e-12 and
# 1e-10 left SLSQP iterating at the optimum to maxiter: the Earth-Mars rendezvous, 300 iterations)
SLSQP_FTOL = 1e-8
_NOT_LAST = "returned the best point seen, not the last"
SLSQP_TAU_OK = 0.1  # Σ|τ| at which SLSQP's own test counts the targets as met (a tenth of a tolerance)


_DEFAULT = SearchSettings()


def solve_nlp(
    problem: Problem,
    method: str = "slsqp",
    settings: SearchSettings = _DEFAULT,
    on_iteration: Callable[[IterationRecord], None] | None = None,
) -> SearchResult:
    """Maximize the final mass subject to τ(U) = 0 and the bounds with ``scipy.optimize.minimize``.

    ``method``: "slsqp" (``maxiter = settings.max_iterations``, ``ftol = 1e-12`` on −F/ΔF_max) or
    "trust_constr" (BFGS Hessian approximations of objective and constraints, ``maxiter =
    20·max_iterations`` since its iterations are small, ``gtol = 1e-10``, ``xtol = 1e-12``).
    trust-constr stops either on ``gtol`` (‖∇ₓL‖∞ and the constraint violation below it) or on
    ``xtol`` (its trust radius collapsed): only the first promises optimality, so the final
    ‖∇ₓL‖∞ is returned (``first_order_optimality``) and quoted in ``stop_reason`` either way.
    With BFGS Hessians on constraints scaled by 1/ε the radius usually collapses first, with
    ‖∇ₓL‖∞ ~ 1e-8 (xtol 1e-10 left ~1e-6; 1e-12 costs ~60 more cheap iterations).  One
    ``IterationRecord`` per SciPy callback (submode "NLP"; ``gamma``/``predicted_slope`` nan,
    ``du`` the change since the previous record, ``du1``/``du2`` zero, ``trials`` empty,
    ``angle_rad`` θ of SIZE-6 at the point).  ``stop_reason`` carries SciPy's message;
    ``search_converged`` is SciPy's success flag (re-verify it).  ``result.u`` is SciPy's final
    point when it converged within tolerance, else the best point seen (rule of
    ``search._better``).  The switch-order rows ``ineq_matrix @ U <= ineq_bound`` are linear
    inequality constraints.  SLSQP's ``ftol`` is ``SLSQP_FTOL`` (1e-8 of ΔF_max).
    ``time_line_search_s`` is 0 (every value comes from ``sensitivities``).

    Scaling caveat: SciPy's quasi-Newton start (identity Hessian) assumes an O(1) objective gradient
    in Ũ, i.e. |D G|/ΔF_max ≈ 1.  Under sensitivity weighting with tight tolerances (one scaled unit
    = k_j tolerances of target change) that gradient can be ~1e-9 and SLSQP then reports success
    after a negligible step; use control weighting, or k_j making one scaled unit a sizeable control
    change, and always re-verify the answer.
    """
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, not {method!r}")
    s = settings
    prob = _validated(problem)
    pts = ScaledPoints(prob, s, "NLP")
    if not pts.ev0.ok:
        return pts.finish(pts.u0, pts.ev0, "trajectory failed at the starting controls", False)
    d = pts.set_scale()
    x0 = pts.u0 / d
    fns = _Scaled(pts, d)

    def callback(intermediate_result: OptimizeResult) -> None:
        pts.record(intermediate_result.x, on_iteration)

    bounds = Bounds(prob.lower / d, prob.upper / d)
    has_bounds = bool(np.any(np.isfinite(prob.lower)) or np.any(np.isfinite(prob.upper)))
    with warnings.catch_warnings():
        solve = _slsqp if method == "slsqp" else _trust_constr
        res = solve(fns, x0, bounds if has_bounds else None, callback)
    if method == "slsqp":
        return pts.answer(res.x, f"SLSQP: {res.message} after {int(res.nit)} iterations", bool(res.success), _NOT_LAST)
    optimality = float(res.optimality)
    reason = f"trust-constr: {res.message} (‖∇ₓL‖∞ {optimality:.1e}, violation {float(res.constr_violation):.1e})"
    return pts.answer(res.x, reason, bool(res.success), _NOT_LAST, optimality)


class _Scaled:
    """The scaled problem's functions of Ũ for SciPy: the objective −F/ΔF_max and its gradient,
    the τ rows and their Jacobian S̃ (``_FAIL`` values and zero derivatives for a failed
    trajectory); ``A``/``b`` the switch-order rows in U (None without)."""

    def __init__(self, pts: ScaledPoints, d: np.ndarray) -> None:
        self.pts, self.d = pts, d
        self.m, self.n = pts.m, pts.n
        self.tol = pts.prob.tolerance
        self.dfm = pts.settings.max_performance_change
        self.A, self.b = pts.prob.ineq_matrix, pts.prob.ineq_bound
        self.maxiter = pts.settings.max_iterations

    def fun(self, x: np.ndarray) -> float:
        ev, _, _ = self.pts.at(x)
        return -ev.performance / self.dfm if ev.ok else _FAIL

    def jac(self, x: np.ndarray) -> np.ndarray:
        ev, _, G = self.pts.at(x)
        return -self.d * G / self.dfm if ev.ok else np.zeros(self.m)

    def con(self, x: np.ndarray) -> np.ndarray:
        ev, _, _ = self.pts.at(x)
        return self.pts.tau(ev) if ev.ok else np.full(self.n, _FAIL)

    def con_jac(self, x: np.ndarray) -> np.ndarray:
        ev, S, _ = self.pts.at(x)
        return S * self.d[None, :] / self.tol[:, None] if ev.ok else np.zeros((self.n, self.m))


def _slsqp(fns: _Scaled, x0: np.ndarray, bounds: Bounds | None, callback: Callable) -> OptimizeResult:
    """SLSQP on the scaled problem (``maxiter = max_iterations``, ``ftol = SLSQP_FTOL``)."""
    # Kraft's SLSQP stops when |Δf| < ftol AND the summed constraint violation < ftol: with τ
    # (targets / tolerance) as the constraints that asks Σ|τ| < 1e-10, which integrated
    # trajectories never give (τ carries ~1e-4 of noise), so SLSQP ran to maxiter at the
    # optimum.  Its rows are scaled by ftol/SLSQP_TAU_OK: converged means Σ|τ| < 0.1 (equality
    # rows are scale-invariant in its QP, its multipliers take the inverse scale)
    kappa = SLSQP_FTOL / SLSQP_TAU_OK
    con, con_jac, A, b, d = fns.con, fns.con_jac, fns.A, fns.b, fns.d
    constraints = (
        [{"type": "eq", "fun": lambda x: kappa * con(x), "jac": lambda x: kappa * con_jac(x)}] if fns.n else []
    )
    if A is not None:
        Ad = A * d[None, :]
        constraints.append({"type": "ineq", "fun": lambda x: b - Ad @ x, "jac": lambda x: -Ad})
    return minimize(
        fns.fun,
        x0,
        jac=fns.jac,
        method="SLSQP",
        bounds=bounds,
        constraints=constraints,
        callback=callback,
        options={"maxiter": max(fns.maxiter, 1), "ftol": SLSQP_FTOL},
    )


def _trust_constr(fns: _Scaled, x0: np.ndarray, bounds: Bounds | None, callback: Callable) -> OptimizeResult:
    """trust-constr on the scaled problem (BFGS Hessians, ``maxiter = 20·max_iterations``)."""
    # BFGS updates warn "delta_grad == 0.0" on linear constraints; harmless, so silenced here.
    warnings.filterwarnings("ignore", message="delta_grad == 0.0", category=UserWarning)
    n, A, b, d = fns.n, fns.A, fns.b, fns.d
    constraints = [NonlinearConstraint(fns.con, np.zeros(n), np.zeros(n), jac=fns.con_jac, hess=BFGS())] if n else []
    if A is not None:
        constraints.append(LinearConstraint(A * d[None, :], -np.inf, b))
    return minimize(
        fns.fun,
        x0,
        jac=fns.jac,
        hess=BFGS(),
        method="trust-constr",
        bounds=bounds,
        constraints=constraints,
        callback=callback,
        options={"maxiter": max(20 * fns.maxiter, 1), "gtol": 1e-10, "xtol": 1e-12},
    )
