"""What the NLP solvers (SciPy's in :mod:`fracas.tom.nlp`, IPOPT in :mod:`fracas.tom.ipopt`) share
around TOM's :class:`~fracas.tom.search.Problem`: the points they ask for in scaled controls
Ũ = U/d, the best point seen, the iteration records and the verdict at the end.

* one ``sensitivities`` call per distinct point (LRU of 256), with the search's counters;
* the best point by the projected-gradient search's rule (``search._better``): within tolerance
  (|τ| ≤ 1, the bounds and the switch-order rows met to 1e-9 relative: U = D Ũ of a bound-active
  control can land ~1e-12 relative outside) beats not; then the higher F, else the lower E;
* :meth:`ScaledPoints.answer`: the solver's own end point when it converged there within
  tolerance, else the best point seen (saying so); :meth:`ScaledPoints.finish`: FRACAS's TEST
  at the returned point (θ over the free controls below θ_conv) before convergence is claimed.

Arrays and callables in, a :class:`~fracas.tom.search.SearchResult` out; no printing.
"""

from __future__ import annotations

import math
import time
from collections import OrderedDict
from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike

from fracas.tom.kernels import optimality_angle, weights
from fracas.tom.search_support import _better, _clean, result_of
from fracas.tom.search_types import Evaluation, IterationRecord, Problem, SearchResult, SearchSettings

_SLACK = 1e-9  # relative slack of the bounds and switch-order rows in the best-point rule


class ScaledPoints:
    """The evaluated points of one NLP solve of a validated ``problem`` (module docstring).

    Construction evaluates the start (``given_S``/``given_G`` when given); :meth:`set_scale`
    fixes d from WEIGHT at the start, after which :meth:`at` takes scaled points."""

    def __init__(self, problem: Problem, settings: SearchSettings, submode: str) -> None:
        self.prob, self.settings, self.submode = problem, settings, submode
        self.m, self.n = problem.u0.size, problem.desired.size
        desired = problem.desired
        self._err = problem.target_error or (lambda T: T - desired)
        self.t_start = time.perf_counter()
        self.stats = {"n_sens": 0, "n_eval": 0, "t_sens": 0.0, "t_eval": 0.0}
        self._cache: OrderedDict[bytes, tuple[Evaluation, np.ndarray, np.ndarray]] = OrderedDict()
        self.history: list[IterationRecord] = []
        self.u0 = problem.u0.copy()
        if problem.given_S is not None:
            t = time.perf_counter()
            ev0 = _clean(problem.evaluate(self.u0.copy()), self.n)
            self.stats["t_eval"] += time.perf_counter() - t
            self.stats["n_eval"] += 1
            self._first = (ev0, problem.given_S, problem.given_G)
        else:
            self._first = self._call(self.u0)
        self.ev0, self.S0, self.G0 = self._first
        self.d = np.ones(self.m)
        self.best = {"u": self.u0.copy(), "ev": self.ev0, "key": self.key(self.u0, self.ev0)}
        self._last_u = self.u0.copy()

    # ------------------------------------------------------------------ points
    def _call(self, u: np.ndarray) -> tuple[Evaluation, np.ndarray, np.ndarray]:
        t = time.perf_counter()
        try:
            ev, S, G = self.prob.sensitivities(u.copy())
        finally:
            self.stats["t_sens"] += time.perf_counter() - t
            self.stats["n_sens"] += 1
        n, m = self.n, self.m
        S = np.array(S, dtype=float).reshape(n, m) if n else np.zeros((0, m))
        return _clean(ev, n), S, np.array(G, dtype=float).reshape(m)

    def set_scale(self) -> np.ndarray:
        """d from WEIGHT at the start point (held for the whole solve); returns it."""
        p = self.prob
        self.d = weights(self.S0, p.tolerance, self.u0, p.scale, p.floor, self.settings.weighting, p.value_weighted)
        self._cache[(self.u0 / self.d).tobytes()] = self._first
        return self.d

    def at(self, x: np.ndarray) -> tuple[Evaluation, np.ndarray, np.ndarray]:
        """(Evaluation, S, G) at U = D Ũ; every new point is a candidate for the best one."""
        x = np.asarray(x, dtype=float)
        key = x.tobytes()
        if key in self._cache:
            self._cache.move_to_end(key)
            return self._cache[key]
        u = x * self.d
        out = self._cache[key] = self._call(u)
        if len(self._cache) > 256:
            self._cache.popitem(last=False)
        k = self.key(u, out[0])
        if _better(k, self.best["key"]):
            self.best.update(u=u.copy(), ev=out[0], key=k)
        return out

    def tau(self, ev: Evaluation) -> np.ndarray:
        """τ = ΔT/ε (+inf when the trajectory failed)."""
        if not ev.ok:
            return np.full(self.n, math.inf)
        return np.asarray(self._err(ev.targets), dtype=float).reshape(self.n) / self.prob.tolerance

    def key(self, u: np.ndarray, ev: Evaluation) -> tuple[bool, float, float]:
        """(within tolerance, F, E) for ``search._better``."""
        if not ev.ok:
            return (False, -math.inf, math.inf)
        p = self.prob
        tau = self.tau(ev)
        lo = np.where(np.isfinite(p.lower), p.lower, 0.0)
        hi = np.where(np.isfinite(p.upper), p.upper, 0.0)
        inside = bool(np.all(u >= p.lower - _SLACK * (1.0 + np.abs(lo)))) and bool(
            np.all(u <= p.upper + _SLACK * (1.0 + np.abs(hi)))
        )
        feasible = inside and bool(np.all(np.abs(tau) <= 1.0))
        if feasible and p.ineq_matrix is not None:
            b = p.ineq_bound
            feasible = bool(np.all(p.ineq_matrix @ u <= b + _SLACK * (1.0 + np.abs(b))))
        return (feasible, ev.performance, float(tau @ tau))

    # ------------------------------------------------------------------ records and the end
    def record(self, x: np.ndarray, on_iteration: Callable[[IterationRecord], None] | None) -> IterationRecord:
        """One IterationRecord at the iterate x (Ũ): ``gamma``/``predicted_slope`` nan, ``du`` the
        change since the previous record, ``angle_rad`` TEST's θ there over the free controls (the
        angle that decides convergence: over every control a bound-active one keeps it at ~0.7 rad
        on Bryson & Ho at the optimum)."""
        d = self.d
        u = np.asarray(x, float) * d
        ev, S, G = self.at(x)
        tau = self.tau(ev)
        E = float(tau @ tau)
        m, n = self.m, self.n
        rec = IterationRecord(
            iteration=len(self.history) + 1,
            submode=self.submode,
            u=u.copy(),
            targets=ev.targets.copy(),
            tau=tau,
            performance=ev.performance,
            error_index=E,
            error_rms=math.sqrt(E / n) if n else 0.0,
            angle_rad=optimality_angle(self.prob, u, S, G, self.settings.weighting) if ev.ok else math.nan,
            gamma=math.nan,
            du=u - self._last_u,
            du1=np.zeros(m),
            du2=np.zeros(m),
            dropped=(),
            trials=[],
            predicted_slope=math.nan,
            n_evaluations=self.stats["n_sens"] + self.stats["n_eval"],
        )
        self._last_u = u.copy()
        self.history.append(rec)
        if on_iteration is not None:
            on_iteration(rec)
        return rec

    def finish(self, u: ArrayLike, ev: Evaluation, reason: str, ok: bool, optimality: float = math.nan) -> SearchResult:
        """The result at U (clipped to its bounds); a claimed convergence must pass FRACAS's TEST
        there (θ over the free controls, with the active switch-order rows, below θ_conv)."""
        p, s = self.prob, self.settings
        u = np.clip(np.asarray(u, float), p.lower, p.upper)
        if ok and ev.ok and self.n:
            _, S_u, G_u = self.at(u / self.d)
            theta = optimality_angle(p, u, S_u, G_u, s.weighting)
            reason = f"{reason}; TEST angle θ {theta:.1e} rad"
            if not theta < s.convergence_angle_rad:
                ok = False
                reason += f" >= θ_conv {s.convergence_angle_rad:.1e}: not an optimum"
        st = self.stats
        out = result_of(
            u, ev, self.history, reason, ok, st["n_eval"], st["n_sens"], st["t_sens"], st["t_eval"], self.t_start
        )
        out.first_order_optimality = optimality
        return out

    def answer(
        self, x_end: ArrayLike, reason: str, converged: bool, not_last: str, optimality: float = math.nan
    ) -> SearchResult:
        """The solver's end point x_end (Ũ) when it converged there within tolerance (its optimum, not
        a trial at the edge of the tolerance band that gains micrograms), or when no point seen is
        strictly better; else the best point seen, ``not_last`` and both points said in the reason."""
        x_end = np.asarray(x_end, float)
        ev_end = self.at(x_end)[0]
        u_end = x_end * self.d
        key_end = self.key(u_end, ev_end)
        if (converged and key_end[0]) or not _better(self.best["key"], key_end):
            return self.finish(u_end, ev_end, reason, converged, optimality)
        feasible, f_best, e_best = self.best["key"]
        f_end = ev_end.performance if ev_end.ok else math.nan
        reason += (
            f"; {not_last} (best: {'within' if feasible else 'not within'} tolerance, E = {e_best:.3e}, "
            f"F {f_best - f_end:+.3e} from the last; last: E = {key_end[2]:.3e}, F = {f_end:.12g})"
        )
        return self.finish(self.best["u"], self.best["ev"], reason, converged)
