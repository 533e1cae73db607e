"""A third optimizer for TOM's problem: IPOPT (interior point, L-BFGS Hessian) through CasADi.

Optional: needs the ``casadi`` wheel (it bundles IPOPT with MUMPS), ``pip install 'fracas[ipopt]'``;
casadi is imported only when :func:`solve_ipopt` runs.  Not in the report (P-A9: "SQP would be an
extension"); like :mod:`fracas.tom.nlp` it is an independent check of the projected-gradient search.

The problem is :func:`fracas.tom.nlp.solve_nlp`'s, in the same scaled variables (digest §A.3):

* controls Ũ = D⁻¹U, D = diag(d) from WEIGHT (:func:`~fracas.tom.search.weights`) at the start
  point, held fixed for the whole run;
* objective −F(U)/ΔF_max (F the final mass, kg, maximized), gradient −D G/ΔF_max;
* equality constraints τ(U) = ΔT/ε = 0, Jacobian S̃ = E_ε⁻¹ S D (declared dense);
* the linear inequalities ``ineq_matrix @ U <= ineq_bound`` of the problem (switch order), in Ũ
  R (A D) Ũ ≤ R b with the row scaling R = diag(1/max_j |A_ij d_j|) (an O(1) gradient in Ũ), a
  constant sparse Jacobian with A's own nonzero pattern (casadi differentiates that block itself);
* bounds lower/d ≤ Ũ ≤ upper/d.

Values and derivatives come from ``problem.sensitivities`` (``given_S``/``given_G`` at the start
point when given) inside casadi ``Callback`` objects, cached per Ũ so that the objective, the
constraints and their Jacobians at one point cost one call.  A trajectory that fails (``ok``
False, P-A12) gives NaN objective and constraints (zero derivatives): IPOPT's line search treats a
non-finite trial value as an evaluation error and cuts the step back, so it never accepts such a
point.  Core module: arrays and callables in, arrays out; no printing (IPOPT's banner and output
and casadi's timings and evaluation warnings are switched off).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from typing import Any

import numpy as np

from fracas.tom.kernels import optimality_angle
from fracas.tom.scaled import ScaledPoints
from fracas.tom.search_support import _validated
from fracas.tom.search_types import Evaluation, IterationRecord, Problem, SearchResult, SearchSettings

_DEFAULT = SearchSettings()
_PointFn = Callable[[Evaluation, np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]
_ValueFn = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]
_SUCCESS = ("Solve_Succeeded", "Solved_To_Acceptable_Level")
# TOM's stall test, checked after every IPOPT iteration: the last STALL_ITERATIONS iterates all
# within tolerance (|τ| <= 1) with F spread over less than STALL_RTOL |F|, and FRACAS's TEST
# angle at the current iterate below θ_conv (an optimum, not a slow stretch).  IPOPT with L-BFGS on
# integrated trajectories reaches its optimum and then, with its barrier parameter at 1e-11,
# can take a wild quasi-Newton step and wander off (the Earth-Mars rendezvous: iterates 22-27
# within 4e-8 of 603.93993 kg, iterate 28 E_rms 5e4, never back); the stop is then certified
# by FRACAS's TEST angle at the returned point
STALL_ITERATIONS = 5
STALL_RTOL = 1e-7

# IPOPT options (overridable through ``options``); see :func:`solve_ipopt`.
IPOPT_OPTIONS: dict[str, object] = {
    "hessian_approximation": "limited-memory",
    "tol": 1e-8,
    "bound_relax_factor": 0.0,
    # IPOPT's own "acceptable" stop: 4 consecutive iterations with the objective changing by
    # < 1e-9 (relative), the targets within a tenth of their tolerances (τ = ΔT/ε) and the
    # complementarity below 1e-2; IPOPT's dual infeasibility is left out of it (acceptable_tol
    # 1e10): with L-BFGS on trajectories integrated to ~1e-11, and a control held a hair inside
    # a bound, it stalls at 1e-3..1 while F has converged to 1e-9 (the Earth-Mars rendezvous:
    # 48 iterations to 603.93993 kg, then 250 more wandering off without meeting tol).
    # Optimality is then checked by FRACAS's own TEST angle at the returned point (``finish``)
    "acceptable_tol": 1e10,
    "acceptable_obj_change_tol": 1e-9,
    "acceptable_constr_viol_tol": 0.1,
    "acceptable_iter": 4,
    "print_level": 0,
    "sb": "yes",
}


@functools.lru_cache(maxsize=1)
def _casadi() -> tuple[Any, type, type]:
    """casadi and the two Callback classes the solve builds (built once, on first use): the value
    callback (its Jacobian callback comes with it) and the iteration callback."""
    try:
        import casadi as ca
    except ImportError as exc:
        raise ImportError("optimizer = \"ipopt\" needs casadi: pip install 'fracas[ipopt]'") from exc
    return ca, _value_class(ca), _iteration_class(ca)


def _value_class(ca: Any) -> type:
    """casadi's Callback for a value with a dense Jacobian (``Value``, with ``Jacobian``)."""

    class Value(ca.Callback):
        """x (m,) -> value (rows,) of ``fn(x)[0]``; its Jacobian is ``fn(x)[1]`` (rows, m), dense."""

        def __init__(self, name: str, m: int, rows: int, fn: _ValueFn) -> None:
            ca.Callback.__init__(self)
            self.m, self.rows, self.fn = m, rows, fn
            self.construct(name, {})

        def get_n_in(self) -> int:
            return 1

        def get_n_out(self) -> int:
            return 1

        def get_sparsity_in(self, i: int) -> Any:
            return ca.Sparsity.dense(self.m, 1)

        def get_sparsity_out(self, i: int) -> Any:
            return ca.Sparsity.dense(self.rows, 1)

        def eval(self, arg: list) -> list:
            return [ca.DM(self.fn(np.array(arg[0], dtype=float).reshape(-1))[0])]

        def has_jacobian(self) -> bool:
            return True

        def get_jacobian(self, name: str, inames: list, onames: list, opts: dict) -> Any:
            self.jacobian_callback = Jacobian(name, self.m, self.rows, self.fn, opts)  # keep it alive
            return self.jacobian_callback

    class Jacobian(ca.Callback):
        """(x, nominal value) -> d value/dx (rows, m), dense."""

        def __init__(self, name: str, m: int, rows: int, fn: _ValueFn, opts: dict) -> None:
            ca.Callback.__init__(self)
            self.m, self.rows, self.fn = m, rows, fn
            self.construct(name, opts)

        def get_n_in(self) -> int:
            return 2

        def get_n_out(self) -> int:
            return 1

        def get_sparsity_in(self, i: int) -> Any:
            return ca.Sparsity.dense(self.m, 1) if i == 0 else ca.Sparsity.dense(self.rows, 1)

        def get_sparsity_out(self, i: int) -> Any:
            return ca.Sparsity.dense(self.rows, self.m)

        def eval(self, arg: list) -> list:
            return [ca.DM(self.fn(np.array(arg[0], dtype=float).reshape(-1))[1])]

    return Value


def _iteration_class(ca: Any) -> type:
    """casadi's Callback for nlpsol's ``iteration_callback`` (``Iteration``)."""

    class Iteration(ca.Callback):
        """nlpsol's ``iteration_callback``: the nlpsol outputs at each IPOPT iterate -> 0 (go on) or 1 (stop)."""

        def __init__(self, nx: int, ng: int, fn: Callable[[np.ndarray], bool]) -> None:
            ca.Callback.__init__(self)
            self.nx, self.ng, self.fn = nx, ng, fn
            self.construct("tom_ipopt_iteration", {})

        def get_n_in(self) -> int:
            return ca.nlpsol_n_out()

        def get_n_out(self) -> int:
            return 1

        def get_name_in(self, i: int) -> str:
            return ca.nlpsol_out(i)

        def get_name_out(self, i: int) -> str:
            return "stop"

        def get_sparsity_in(self, i: int) -> Any:
            name = ca.nlpsol_out(i)
            if name == "f":
                return ca.Sparsity.scalar()
            if name in ("x", "lam_x"):
                return ca.Sparsity.dense(self.nx)
            if name in ("g", "lam_g"):
                return ca.Sparsity.dense(self.ng)
            return ca.Sparsity(0, 0)

        def eval(self, arg: list) -> list:
            return [ca.DM(1.0 if self.fn(np.array(arg[0], dtype=float).reshape(-1)) else 0.0)]

    return Iteration


def _guarded(pts: ScaledPoints, error: list[BaseException], fn: _PointFn, rows: int) -> _ValueFn:
    """fn(x) -> (value, Jacobian); NaN values / zero Jacobian for a failed trajectory, and after
    an exception (kept in ``error`` for re-raising once IPOPT returns)."""
    at, m = pts.at, pts.m

    def run(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if not error:
            try:
                ev, S, G = at(x)
                if ev.ok:
                    return fn(ev, S, G)
            except BaseException as exc:  # noqa: B036 - re-raised after the solve
                error.append(exc)
        return np.full(rows, math.nan), np.zeros((rows, m))

    return run


def _value_callbacks(Value: type, pts: ScaledPoints, d: np.ndarray, error: list[BaseException]) -> tuple[Any, Any]:
    """The objective −F/ΔF_max (gradient −D G/ΔF_max) and the τ rows (Jacobian S̃; None without
    targets) as casadi callbacks on Ũ."""
    m, n, tol, tau_of = pts.m, pts.n, pts.prob.tolerance, pts.tau
    dfm = pts.settings.max_performance_change
    f_cb = Value(
        "tom_objective",
        m,
        1,
        _guarded(pts, error, lambda ev, S, G: (np.array([-ev.performance / dfm]), (-d * G / dfm)[None, :]), 1),
    )
    tau_cb = (
        Value(
            "tom_targets", m, n, _guarded(pts, error, lambda ev, S, G: (tau_of(ev), S * d[None, :] / tol[:, None]), n)
        )
        if n
        else None
    )
    return f_cb, tau_cb


def _stall_test(
    pts: ScaledPoints,
    d: np.ndarray,
    error: list[BaseException],
    on_iteration: Callable[[IterationRecord], None] | None,
) -> tuple[Callable[[np.ndarray], bool], list[int]]:
    """The iteration callback (x -> stop?): records each IPOPT iterate but the start and applies
    TOM's stall test (``STALL_ITERATIONS``); and the list it appends to when the test stops IPOPT."""
    prob, s, n, at, history = pts.prob, pts.settings, pts.n, pts.at, pts.history
    calls = [0]  # iteration callbacks so far (the first is IPOPT's iteration 0)
    stalled: list[int] = []

    def iteration(x: np.ndarray) -> bool:
        calls[0] += 1
        if error:
            return True
        if calls[0] == 1:  # IPOPT's iteration 0: the (possibly bound-pushed) start
            return False
        try:
            x = np.asarray(x, float)
            pts.record(x, on_iteration)
            recent = history[-STALL_ITERATIONS:]
            if n and len(recent) == STALL_ITERATIONS and all(np.all(np.abs(r.tau) <= 1.0) for r in recent):
                perf = [r.performance for r in recent]
                if max(perf) - min(perf) <= STALL_RTOL * max(abs(p) for p in perf):
                    _, S, G = at(x)
                    if optimality_angle(prob, x * d, S, G, s.weighting) < s.convergence_angle_rad:
                        stalled.append(len(history))
                        return True
        except BaseException as exc:  # noqa: B036 - re-raised after the solve
            error.append(exc)
            return True
        return False

    return iteration, stalled


def _constraints(ca: Any, xs: Any, tau_cb: Any, prob: Problem, d: np.ndarray) -> tuple[Any, list, list]:
    """(g(Ũ), its lower and upper bounds): the τ rows = 0, then the switch-order rows."""
    m, n = prob.u0.size, prob.desired.size
    A, b = prob.ineq_matrix, prob.ineq_bound
    k = 0 if A is None else A.shape[0]
    parts, lbg, ubg = [], [], []
    if n:
        parts.append(tau_cb(xs))
        lbg.append(np.zeros(n))
        ubg.append(np.zeros(n))
    if k:
        # row i scaled by r_i = 1/max_j |A_ij d_j|: an O(1) gradient in Ũ (IPOPT's gradient-based
        # scaling only scales down; a row of size d ~ 1e-10 made its multiplier ~1e10 and stopped it early)
        Ad = A * d[None, :]
        peak = np.max(np.abs(Ad), axis=1)
        r = 1.0 / np.where(peak > 0, peak, 1.0)
        rows, cols = np.nonzero(A)
        scaled = ca.DM(ca.Sparsity.triplet(k, m, rows.tolist(), cols.tolist()), (Ad[rows, cols] * r[rows]).tolist())
        parts.append(ca.mtimes(scaled, xs))
        lbg.append(np.full(k, -np.inf))
        ubg.append(b * r)
    g = ca.vertcat(*parts) if parts else ca.MX(0, 1)
    return g, lbg, ubg


def _ipopt_options(pts: ScaledPoints, d: np.ndarray, options: dict | None) -> dict:
    """IPOPT's options: ``IPOPT_OPTIONS`` and ``obj_scaling_factor``, then ``options`` on top,
    then ``max_iter``.

    Scaling: ``obj_scaling_factor = 1/‖D G/ΔF_max‖∞`` at the start point (1 when that gradient
    is zero or not finite; ``options`` may override it), so IPOPT sees an O(1) objective gradient.
    Without it, sensitivity weighting with tight tolerances (one scaled unit = k_j tolerances of
    target change) gives objective gradients ~1e-9 in Ũ, below IPOPT's ``tol``: it then stops as
    soon as the targets are met (on the 2×4 projection problem with ε = 1e-8: 0.84 from the optimum,
    like SLSQP, see :func:`~fracas.tom.nlp.solve_nlp`; with the factor, 1e-8).  IPOPT's own
    gradient-based scaling (default) only scales *down* functions whose gradient exceeds 100 (the
    τ rows under control weighting with tight tolerances).  Re-verify the answer regardless.
    """
    s = pts.settings
    dfm = s.max_performance_change
    g_max = float(np.max(np.abs(d * pts.G0))) / dfm if pts.m else 0.0
    obj_scaling = 1.0 / g_max if math.isfinite(g_max) and g_max > 0 else 1.0
    return {
        **IPOPT_OPTIONS,
        "obj_scaling_factor": obj_scaling,
        **(options or {}),
        "max_iter": int(s.max_iterations),
    }


def _answer(pts: ScaledPoints, solver: Any, sol: dict, stalled: list[int], d: np.ndarray) -> SearchResult:
    """The result of IPOPT's return: its status (or the stall test's stop) and end point, handed to
    :meth:`ScaledPoints.answer` (the best point evaluated when that is not IPOPT's last iterate)."""
    history = pts.history
    info = solver.stats()
    status = str(info["return_status"])
    converged = status in _SUCCESS or bool(stalled)
    x_end = np.array(sol["x"], dtype=float).reshape(-1)
    if stalled:  # the iterate the stall test passed on (after a user stop IPOPT's x can be another point)
        x_end = history[-1].u / d
    reason = f"IPOPT: {status} after {int(info['iter_count'])} iterations"
    if stalled:
        reason = (
            f"IPOPT stopped by TOM's stall test after {int(info['iter_count'])} iterations "
            f"(the last {STALL_ITERATIONS} within tolerance, F spread < {STALL_RTOL:.0e} |F|, TEST angle < θ_conv)"
        )
    inf_du = info.get("iterations", {}).get("inf_du", [])
    optimality = float(inf_du[-1]) if len(inf_du) and not stalled else math.nan
    return pts.answer(
        x_end, reason, converged, "returned the best point evaluated, not IPOPT's last iterate", optimality
    )


def solve_ipopt(
    problem: Problem,
    settings: SearchSettings = _DEFAULT,
    on_iteration: Callable[[IterationRecord], None] | None = None,
    options: dict | None = None,
) -> SearchResult:
    """Maximize the final mass subject to τ(U) = 0, the linear inequalities and the bounds with IPOPT.

    IPOPT options (``IPOPT_OPTIONS`` and ``obj_scaling_factor``, see :func:`_ipopt_options`, then
    ``options`` on top, then ``max_iter``):
    ``hessian_approximation = "limited-memory"`` (only first derivatives exist), ``max_iter =
    settings.max_iterations``, ``tol = 1e-8`` on IPOPT's (internally scaled) optimality error of
    the scaled problem, ``bound_relax_factor = 0`` (IPOPT's default 1e-8 relaxation would let
    iterates, and the answer, sit up to 1e-8·max(1, |b|) outside the bounds and the switch-order
    inequalities: trajectories are never flown outside the bounds and an active inequality is met
    within the 1e-9 relative slack of the feasibility rule below), ``print_level = 0`` and ``sb =
    "yes"`` (no banner); casadi's ``print_time`` and ``show_eval_warnings`` are off.

    Returned point: the best point *evaluated* (every trial, not only IPOPT's iterates) by the
    rule of the projected-gradient search (``search._better``): a feasible point (all |τ| ≤ 1,
    the linear inequalities met to 1e-9·(1 + |b|) and within the bounds) beats an infeasible one;
    among feasible points the higher F, among infeasible ones the lower E = Σ τ²; on a tie, IPOPT's
    last iterate.  With target
    tolerances not much smaller than the solution's precision that point can be a trial inside the
    tolerance band with a slightly higher F than IPOPT's τ = 0 optimum; ``stop_reason`` says so
    whenever the returned point is not IPOPT's last iterate.  ``search_converged`` is IPOPT's own
    verdict: return status Solve_Succeeded or Solved_To_Acceptable_Level (named in
    ``stop_reason``; re-verify either).  ``first_order_optimality``: IPOPT's dual infeasibility
    (inf_du) at its last iterate when that is the returned point, else nan.

    One ``IterationRecord`` per IPOPT iteration (submode "IPOPT"; IPOPT's iteration 0, the start,
    is not recorded): the iterate after the iteration, ``gamma``/``predicted_slope`` nan, ``du``
    the change since the previous record, ``du1``/``du2`` zero, ``trials`` empty, ``angle_rad`` θ
    of SIZE-6 at the point.  ``time_line_search_s`` is 0 unless ``given_S`` is used (every value
    comes from ``sensitivities``).  An exception raised by ``sensitivities`` or ``on_iteration``
    stops IPOPT and is re-raised here.

    Scaling: the objective is scaled to an O(1) gradient at the start (:func:`_ipopt_options`).
    """
    ca, Value, Iteration = _casadi()
    s = settings
    prob = _validated(problem)
    m, n = prob.u0.size, prob.desired.size
    A = prob.ineq_matrix
    k = 0 if A is None else A.shape[0]
    pts = ScaledPoints(prob, s, "IPOPT")
    if not pts.ev0.ok:
        return pts.finish(pts.u0, pts.ev0, "trajectory failed at the starting controls", False)
    d = pts.set_scale()
    x0 = pts.u0 / d
    error: list[BaseException] = []  # the first exception raised inside a casadi callback
    f_cb, tau_cb = _value_callbacks(Value, pts, d, error)
    iteration, stalled = _stall_test(pts, d, error, on_iteration)
    xs = ca.MX.sym("x", m)
    g, lbg, ubg = _constraints(ca, xs, tau_cb, prob, d)
    it_cb = Iteration(m, n + k, iteration)
    solver = ca.nlpsol(
        "tom_ipopt",
        "ipopt",
        {"x": xs, "f": f_cb(xs), "g": g},
        {
            "ipopt": _ipopt_options(pts, d, options),
            "print_time": False,
            "show_eval_warnings": False,
            "error_on_fail": False,
            "iteration_callback": it_cb,
        },
    )
    sol = solver(
        x0=x0,
        lbx=prob.lower / d,
        ubx=prob.upper / d,
        lbg=np.concatenate(lbg) if lbg else np.zeros(0),
        ubg=np.concatenate(ubg) if ubg else np.zeros(0),
    )
    if error:
        raise error[0]
    return _answer(pts, solver, sol, stalled, d)
