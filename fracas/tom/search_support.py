"""The bookkeeping around TOM's searches (UPHILL and the NLP solvers): the problem's validation,
FRACAS STEP's feasible point (bounds and the arcs' switch order) and the periodic-angle wrap, the
best-point rule, the counted and timed calls of ``evaluate``/``sensitivities`` and the
:class:`~fracas.tom.search_types.SearchResult` of a finished search.  Re-exported by
:mod:`fracas.tom.search`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from fracas.tom.search_types import Evaluation, IterationRecord, Problem, SearchResult


def _names(idx: Sequence[int], labels: Sequence[str], kind: str) -> str:
    return ", ".join(repr(labels[i]) if i < len(labels) else f"{kind} {i}" for i in idx)


def _as_vector(x: ArrayLike, n: int, name: str) -> np.ndarray:
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


def feasible_point(
    x: ArrayLike,
    lower: np.ndarray,
    upper: np.ndarray,
    ineq_matrix: np.ndarray | None = None,
    ineq_bound: np.ndarray | None = None,
) -> np.ndarray:
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
    def __init__(self, problem: Problem) -> None:
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

    def sensitivities(self, u: np.ndarray, n: int, m: int) -> tuple[Evaluation, np.ndarray, np.ndarray]:
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


def result_of(
    u: np.ndarray,
    ev: Evaluation,
    history: list[IterationRecord],
    reason: str,
    converged: bool,
    n_eval: int,
    n_sens: int,
    t_sens: float,
    t_eval: float,
    t_start: float,
) -> SearchResult:
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
