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

import math
import time
import warnings
from collections import OrderedDict
from collections.abc import Callable

import numpy as np
from scipy.optimize import BFGS, Bounds, NonlinearConstraint, minimize

from fracas.tom.search import (
    Evaluation,
    IterationRecord,
    Problem,
    SearchResult,
    SearchSettings,
    _angle,
    _clean,
    _validated,
    result_of,
    weights,
)

METHODS = ("slsqp", "trust_constr")
_FAIL = 1e30


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
    ``search_converged`` is SciPy's success flag (re-verify it).  ``result.u`` is SciPy's final point.
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
    m, n = prob.u0.size, prob.desired.size
    desired, tol = prob.desired, prob.tolerance
    err = prob.target_error or (lambda T: T - desired)
    t_start = time.perf_counter()
    stats = {"n_sens": 0, "n_eval": 0, "t_sens": 0.0, "t_eval": 0.0}
    cache: OrderedDict[bytes, tuple[Evaluation, np.ndarray, np.ndarray]] = OrderedDict()

    def call(u: np.ndarray):
        t = time.perf_counter()
        try:
            ev, S, G = prob.sensitivities(u.copy())
        finally:
            stats["t_sens"] += time.perf_counter() - t
            stats["n_sens"] += 1
        S = np.array(S, dtype=float).reshape(n, m) if n else np.zeros((0, m))
        return _clean(ev, n), S, np.array(G, dtype=float).reshape(m)

    u0 = prob.u0.copy()
    if prob.given_S is not None:
        t = time.perf_counter()
        ev0 = _clean(prob.evaluate(u0.copy()), n)
        stats["t_eval"] += time.perf_counter() - t
        stats["n_eval"] += 1
        first = (ev0, prob.given_S, prob.given_G)
    else:
        first = call(u0)
    ev0, S0, _ = first
    history: list[IterationRecord] = []

    def finish(u, ev, reason, ok):
        return result_of(
            u, ev, history, reason, ok, stats["n_eval"], stats["n_sens"], stats["t_sens"], stats["t_eval"], t_start
        )

    if not ev0.ok:
        return finish(u0, ev0, "trajectory failed at the starting controls", False)
    d = weights(S0, tol, u0, prob.scale, prob.floor, s.weighting, prob.value_weighted)
    dfm = s.max_performance_change

    x0 = u0 / d
    cache[x0.tobytes()] = first

    def at(x: np.ndarray):
        """(Evaluation, S, G) at U = D Ũ, one `sensitivities` call per distinct Ũ (LRU of 256)."""
        x = np.asarray(x, dtype=float)
        key = x.tobytes()
        if key in cache:
            cache.move_to_end(key)
        else:
            cache[key] = call(x * d)
            if len(cache) > 256:
                cache.popitem(last=False)
        return cache[key]

    def tau_of(ev: Evaluation) -> np.ndarray:
        return np.asarray(err(ev.targets), dtype=float).reshape(n) / tol

    def fun(x):
        ev, _, _ = at(x)
        return -ev.performance / dfm if ev.ok else _FAIL

    def jac(x):
        ev, _, G = at(x)
        return -d * G / dfm if ev.ok else np.zeros(m)

    def con(x):
        ev, _, _ = at(x)
        return tau_of(ev) if ev.ok else np.full(n, _FAIL)

    def con_jac(x):
        ev, S, _ = at(x)
        return S * d[None, :] / tol[:, None] if ev.ok else np.zeros((n, m))

    last = {"u": u0.copy(), "k": 0}

    def callback(intermediate_result):
        x = np.asarray(intermediate_result.x, dtype=float)
        u = x * d
        ev, S, G = at(x)
        tau = tau_of(ev) if ev.ok else np.full(n, math.inf)
        E = float(tau @ tau)
        last["k"] += 1
        rec = IterationRecord(
            iteration=last["k"],
            submode="NLP",
            u=u.copy(),
            targets=ev.targets.copy(),
            tau=tau,
            performance=ev.performance,
            error_index=E,
            error_rms=math.sqrt(E / n) if n else 0.0,
            angle_rad=_angle(S * d[None, :] / tol[:, None], -d * G) if ev.ok else math.nan,
            gamma=math.nan,
            du=u - last["u"],
            du1=np.zeros(m),
            du2=np.zeros(m),
            dropped=(),
            trials=[],
            predicted_slope=math.nan,
            n_evaluations=stats["n_sens"] + stats["n_eval"],
        )
        last["u"] = u.copy()
        history.append(rec)
        if on_iteration is not None:
            on_iteration(rec)

    bounds = Bounds(prob.lower / d, prob.upper / d)
    has_bounds = bool(np.any(np.isfinite(prob.lower)) or np.any(np.isfinite(prob.upper)))
    with warnings.catch_warnings():
        if method == "slsqp":
            constraints = [{"type": "eq", "fun": con, "jac": con_jac}] if n else []
            res = minimize(
                fun,
                x0,
                jac=jac,
                method="SLSQP",
                bounds=bounds if has_bounds else None,
                constraints=constraints,
                callback=callback,
                options={"maxiter": max(s.max_iterations, 1), "ftol": 1e-12},
            )
        else:
            # BFGS updates warn "delta_grad == 0.0" on linear constraints; harmless, so silenced here.
            warnings.filterwarnings("ignore", message="delta_grad == 0.0", category=UserWarning)
            constraints = [NonlinearConstraint(con, np.zeros(n), np.zeros(n), jac=con_jac, hess=BFGS())] if n else []
            res = minimize(
                fun,
                x0,
                jac=jac,
                hess=BFGS(),
                method="trust-constr",
                bounds=bounds if has_bounds else None,
                constraints=constraints,
                callback=callback,
                options={"maxiter": max(20 * s.max_iterations, 1), "gtol": 1e-10, "xtol": 1e-12},
            )
    x = np.asarray(res.x, dtype=float)
    ev, _, _ = at(x)
    if method == "slsqp":
        return finish(x * d, ev, f"SLSQP: {res.message}", bool(res.success))
    optimality = float(res.optimality)
    reason = f"trust-constr: {res.message} (‖∇ₓL‖∞ {optimality:.1e}, violation {float(res.constr_violation):.1e})"
    out = finish(x * d, ev, reason, bool(res.success))
    out.first_order_optimality = optimality
    return out
