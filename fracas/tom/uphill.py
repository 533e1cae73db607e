"""The iteration of TOM's projected-gradient search: FRACAS UPHILL's pass, one step at a time.

The state a search carries between iterations (:class:`_State`), what one run holds fixed
(:class:`_Run`), one iteration's linearization (:class:`_Point`, FEGS/WEIGHT/STEST) and a
submode's step (:class:`_Plan`, SIZE/DELU with the active bounds), then the steps of one pass:
TEST (submode and convergence), the P-A10 fallback, GENMIN on FUNCT (:class:`_LineSearch`, with
the T+O → T retry), STEP and the record.  :func:`fracas.tom.search.projected_gradient` drives
it; the notation and the choices made are in :mod:`fracas.tom.search`'s docstring.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from fracas.tom.kernels import (
    _angle,
    _Direction,
    _direction,
    _ill_conditioned,
    choose_submode,
    dependent_controls,
    funct,
    weights,
)
from fracas.tom.line_search import genmin
from fracas.tom.search_support import _better, _Counter, _names, feasible_point, result_of, wrap_periodic
from fracas.tom.search_types import RCOND, Evaluation, IterationRecord, Problem, SearchResult, SearchSettings, Trial

_TINY_STEP = 1e-3  # a T+O step below this γ counts as failed (retried as targeting only)
_ALPHA_BETA = {"T": (1.0, 0.0), "T+O": (1.0, 1.0), "O": (0.0, 1.0)}


# --------------------------------------------------------------------------- the search's state


@dataclass
class _Run:
    """What one UPHILL run holds fixed: the validated problem, the settings as given, the sizes,
    the target error, the counted calls and the history the records go to."""

    prob: Problem
    settings: SearchSettings
    n: int
    m: int
    err: Callable[[np.ndarray], np.ndarray]
    cnt: _Counter
    history: list[IterationRecord]
    on_iteration: Callable[[IterationRecord], None] | None

    def tau_of(self, ev: Evaluation) -> np.ndarray:
        """τ = ΔT/ε of a trajectory."""
        return np.asarray(self.err(ev.targets), dtype=float).reshape(self.n) / self.prob.tolerance

    def finish(self, u: np.ndarray, ev: Evaluation, reason: str, converged: bool) -> SearchResult:
        """The :class:`SearchResult` at U with this run's history and counters."""
        cnt = self.cnt
        return result_of(u, ev, self.history, reason, converged, cnt.n_eval, cnt.n_sens, cnt.t_sens, cnt.t_eval, cnt.t0)


@dataclass
class _State:
    """What UPHILL carries from one iteration to the next: the current point U (its trajectory,
    sensitivities and τ), the best point so far with its :func:`_key`, the stop verdict, and the
    performance request.  ΔF_max is the most an iteration may ask for (kg); the step asks for
    ``dfmax`` <= ΔF_max, twice the gain the last optimization step achieved (a line search from a
    5 kg request near an optimum with 0.1 kg left spends its trials shrinking), divided by 10 after
    an optimization line search finds no decrease, down to 1e-9 ΔF_max."""

    u: np.ndarray
    ev: Evaluation
    S: np.ndarray
    G: np.ndarray
    tau: np.ndarray
    best_u: np.ndarray
    best_ev: Evaluation
    best_key: tuple[bool, float, float]
    dfmax: float
    reason: str = ""
    converged: bool = False


@dataclass
class _Point:
    """One iteration's linearization at U (WEIGHT, the scaled S̃ and G̃_J, STEST) and its TEST
    figures; ``theta``/``free``: θ over the controls not held at a bound, from the first plan."""

    it: int
    s: SearchSettings  # the settings with this iteration's ΔF_max request
    E: float
    e_rms: float
    feasible: bool
    d: np.ndarray
    St: np.ndarray
    Gt: np.ndarray
    stest: tuple[int, ...]
    theta: float = math.nan
    free: list[int] = field(default_factory=list)


class _Plan(NamedTuple):
    """A submode's step at the point: α, β, the controls held at a bound (``active``), those kept
    in the step, the direction, and θ over the controls not held at a bound (``free``)."""

    label: str
    alpha: float
    beta: float
    active: list[int]
    kept: list[int]
    dr: _Direction
    theta: float
    free: list[int]


def _key(ev: Evaluation, tau: np.ndarray) -> tuple[bool, float, float]:
    """The best-point key (within tolerance, F, E) of :func:`_better`."""
    return (bool(np.all(np.abs(tau) <= 1.0)), ev.performance, float(tau @ tau))


def _dropped(pt: _Point, plan: _Plan) -> tuple[int, ...]:
    """The controls held at ΔU_j = 0: STEST first, then active bounds."""
    return tuple(pt.stest) + tuple(plan.active)


# ------------------------------------------------------------------------- the steps of UPHILL


def _linearize(run: _Run, st: _State, it: int) -> _Point | None:
    """FEGS (the sensitivities at U after the first iteration), WEIGHT, the scaled S̃ and G̃_J and
    STEST; None when the search stops here (``st.reason`` set)."""
    n, m, prob = run.n, run.m, run.prob
    s = dataclasses.replace(run.settings, max_performance_change=st.dfmax)
    if it > 1:
        st.ev, st.S, st.G = run.cnt.sensitivities(st.u, n, m)
        if not st.ev.ok:
            st.reason = f"trajectory failed at the accepted controls of iteration {it - 1} (sensitivity call)"
            return None
        st.tau = run.tau_of(st.ev)
    if not (np.all(np.isfinite(st.S)) and np.all(np.isfinite(st.G)) and np.all(np.isfinite(st.tau))):
        st.reason = f"sensitivities not finite at iteration {it}"
        return None
    tau, tol = st.tau, prob.tolerance
    E = float(tau @ tau)
    e_rms = math.sqrt(E / n) if n else 0.0
    feasible = bool(np.all(np.abs(tau) <= 1.0))
    d = weights(st.S, tol, st.u, prob.scale, prob.floor, s.weighting, prob.value_weighted)
    St = st.S * d[None, :] / tol[:, None]
    Gt = -d * st.G
    stest = dependent_controls(St, s.dependent_angle_rad) if _ill_conditioned(St, s.dependent_angle_rad) else ()
    return _Point(it, s, E, e_rms, feasible, d, St, Gt, stest)


def _plan(run: _Run, st: _State, pt: _Point, label: str) -> _Plan:
    """SIZE/DELU for submode ``label`` with the active bounds (P-A7): a control at a bound whose
    step pushes outward is dropped and the step recomputed, until no kept control pushes outward."""
    m, lower, upper, u = run.m, run.prob.lower, run.prob.upper, st.u
    alpha, beta = _ALPHA_BETA[label]
    active: list[int] = []
    while True:
        kept = [j for j in range(m) if j not in pt.stest and j not in active]
        dr = _direction(pt.St, pt.Gt, st.tau, kept, alpha, beta, pt.s)
        du = dr.du * pt.d
        out = [j for j in kept if (u[j] <= lower[j] and du[j] < 0) or (u[j] >= upper[j] and du[j] > 0)]
        if not out:
            break
        active.extend(out)
    free = [j for j in range(m) if j not in active]
    theta = _angle(pt.St[:, free], pt.Gt[free]) if free else (math.nan if run.n == 0 else 0.0)
    return _Plan(label, alpha, beta, active, kept, dr, theta, free)


def _first_plan(run: _Run, st: _State, pt: _Point) -> _Plan:
    """TEST-1's submode and its plan; in ``auto``, an O pass with θ < θ_conv but a target outside
    its tolerance runs T+O instead (O alone never corrects the targets)."""
    s, n = pt.s, run.n
    label = choose_submode(pt.e_rms, s) if n else "O"
    plan = _plan(run, st, pt, label)
    if s.submode == "auto" and n and label == "O" and not pt.feasible and plan.theta < s.convergence_angle_rad:
        plan = _plan(run, st, pt, "T+O")
    return plan


def _converged_why(run: _Run, pt: _Point, plan: _Plan) -> str:
    """TEST: the convergence message, or "" when the point has not converged."""
    s, theta = pt.s, pt.theta
    why = ""
    if run.n == 0:
        radius = s.linearity_radius if math.isfinite(s.linearity_radius) else 1.0
        reach = radius * float(np.linalg.norm(pt.Gt[pt.free]))
        if reach <= s.convergence_angle_rad * s.max_performance_change:
            why = (
                f"converged: no targets and first-order gain within the linearity radius {reach:.1e} kg"
                f" <= {s.convergence_angle_rad * s.max_performance_change:.1e} kg"
            )
    elif pt.feasible and plan.label == "T" and s.submode == "target":
        why = "converged: targets within tolerance (targeting only)"
    elif pt.feasible and plan.beta:
        if theta < s.convergence_angle_rad:
            why = (
                f"converged: targets within tolerance and gradient angle {theta:.1e} rad"
                f" < {s.convergence_angle_rad:.1e}"
            )
        elif s.min_performance_gain > 0 and plan.dr.gain < s.min_performance_gain:
            why = (
                f"converged: targets within tolerance and predicted performance gain {plan.dr.gain:.1e} kg"
                f" < {s.min_performance_gain:.1e} kg"
            )
    return why


def _record(run: _Run, st: _State, pt: _Point, plan: _Plan, gamma: float, trials: list[Trial]) -> None:
    """The iteration's :class:`IterationRecord` (of the point at its start), to the history and
    ``on_iteration``."""
    s, d, dr_ = pt.s, pt.d, plan.dr
    rec = IterationRecord(
        # the limit's final test of the last point belongs to the last iteration (a run with a
        # limit of 200 reports 200 iterations, not 201)
        iteration=min(pt.it, max(s.max_iterations, 1)),
        submode=plan.label,
        u=st.u.copy(),
        targets=st.ev.targets.copy(),
        tau=st.tau.copy(),
        performance=st.ev.performance,
        error_index=pt.E,
        error_rms=pt.e_rms,
        angle_rad=pt.theta,
        gamma=gamma,
        du=dr_.du * d,
        du1=dr_.du1 * d,
        du2=dr_.du2 * d,
        dropped=_dropped(pt, plan),
        trials=trials,
        predicted_slope=dr_.slope,
        n_evaluations=run.cnt.n_eval + run.cnt.n_sens,
    )
    run.history.append(rec)
    if run.on_iteration is not None:
        run.on_iteration(rec)


def _descent_fallback(run: _Run, st: _State, pt: _Point, plan: _Plan) -> _Plan:
    """P-A10: a non-descent direction with optimization active falls back to targeting only."""
    if not plan.dr.slope < 0 and plan.beta and run.n and not np.all(st.tau == 0):
        plan_t = _plan(run, st, pt, "T")
        if plan_t.dr.slope < 0:
            return plan_t
    return plan


def _singular_note(run: _Run, pt: _Point, plan: _Plan) -> str:
    """Why the targets cannot be corrected, when S̃ on the kept controls lacks the rank ("" else)."""
    n, kept = run.n, plan.kept
    if not n or pt.feasible or not plan.alpha:
        return ""
    r = plan.dr.rank
    if r >= min(n, len(kept)) and len(kept) >= n:
        return ""
    Sk = pt.St[:, kept]
    rownorm = np.linalg.norm(Sk, axis=1)
    dead = np.flatnonzero(rownorm <= RCOND * max(float(rownorm.max(initial=0.0)), 1e-300))
    msg = f"sensitivity matrix singular: rank {r} of the {len(kept)} retained controls < {n} targets"
    if dead.size:
        msg += f"; no control authority over target {_names(dead, run.prob.target_labels, 'target')}"
    if pt.stest:
        msg += f"; dropped as dependent (STEST): {_names(pt.stest, run.prob.labels, 'control')}"
    return msg


@dataclass
class _LineSearch:
    """GENMIN on FUNCT along one plan's ΔU = D(αΔŨ₂ + βΔŨ₁) from U: the trials it flies
    (``trials``) and every flown trajectory by γ (``flown``, shared with a retry)."""

    run: _Run
    st: _State
    pt: _Point
    plan: _Plan
    du: np.ndarray
    f_nom: float
    flown: dict[float, Evaluation]
    trials: list[Trial] = field(default_factory=list)

    def step_to(self, gamma: float) -> np.ndarray:
        """STEP: U + γΔU clipped to the bounds and projected onto the arcs' switch order."""
        prob = self.run.prob
        return feasible_point(self.st.u + gamma * self.du, prob.lower, prob.upper, prob.ineq_matrix, prob.ineq_bound)

    def cost(self, gamma: float) -> float:
        """FUNCT at γ (+inf for a failed trajectory), flown and recorded as a :class:`Trial`."""
        run, s, alpha, n = self.run, self.pt.s, self.plan.alpha, self.run.n
        ut = self.step_to(gamma)
        evt = run.cnt.evaluate(ut, n)
        self.flown[gamma] = evt
        if not evt.ok:
            self.trials.append(Trial(gamma, math.inf, -math.inf, math.inf, False))
            return math.inf
        taut = run.tau_of(evt)
        if alpha == 0.0 and n and math.sqrt(float(taut @ taut) / n) > s.optimization_step_limit:
            # optimization only: a trial that leaves the region E_rms <= optimization_step_limit is
            # no decrease, whatever FUNCT's linear restoration estimate says (it is blind
            # to a step that large; seen on the Hohmann test, an O step to E_rms 1e5)
            self.trials.append(Trial(gamma, math.inf, evt.performance, float(taut @ taut), False))
            return math.inf
        c = funct(
            taut,
            evt.performance,
            self.f_nom,
            self.plan.dr.restoration,
            alpha=alpha,
            beta=self.plan.beta,
            max_performance_change=s.max_performance_change,
        )
        c = c if math.isfinite(c) else math.inf
        self.trials.append(Trial(gamma, c, evt.performance, float(taut @ taut), bool(math.isfinite(c))))
        return c

    def minimize(self, f_start: float) -> float:
        """GENMIN's γ* from F(0) = ``f_start`` along the plan's F'(0)."""
        s = self.pt.s
        return genmin(
            self.cost,
            f_start,
            self.plan.dr.slope,
            gamma_max=s.max_scale_factor,
            eta=s.curve_fit_tolerance,
            max_trials=s.max_trials,
            first=1.0,
        )[0]


def _step_search(run: _Run, st: _State, pt: _Point, plan: _Plan) -> tuple[_Plan, float, _LineSearch]:
    """GENMIN on FUNCT along the plan: (the plan taken, γ*, its line search).  A T+O search that
    finds no (or only a negligible) decrease while a target is outside its tolerance is recorded
    and retried as targeting only; the T+O step is kept if targeting alone finds nothing."""
    f_nom = st.ev.performance
    ls = _LineSearch(run, st, pt, plan, plan.dr.du * pt.d, f_nom, {})
    f0 = funct(
        st.tau,
        f_nom,
        f_nom,
        plan.dr.restoration,
        alpha=plan.alpha,
        beta=plan.beta,
        max_performance_change=pt.s.max_performance_change,
    )
    gamma = ls.minimize(f0)
    if gamma < _TINY_STEP and plan.alpha and plan.beta and not pt.feasible:
        # The combined step found no (or only a negligible) decrease: typically the curvature of
        # the targets along ΔU₁ swamps F_T.  Record it and retry this iteration as targeting only;
        # keep the T+O step if targeting alone finds nothing.
        plan_t = _plan(run, st, pt, "T")
        if plan_t.dr.slope < 0:
            _record(run, st, pt, plan, 0.0, ls.trials)
            ev_saved = ls.flown.get(gamma)
            ls_t = _LineSearch(run, st, pt, plan_t, plan_t.dr.du * pt.d, f_nom, ls.flown)
            f0 = funct(st.tau, f_nom, f_nom, plan_t.dr.restoration, alpha=1.0, beta=0.0, max_performance_change=1.0)
            gamma_t = ls_t.minimize(f0)
            if gamma_t == 0.0 and gamma > 0.0:
                run.history.pop()
                ls.flown[gamma] = ev_saved
                return plan, gamma, ls
            return plan_t, gamma_t, ls_t
    return plan, gamma, ls


def _take_step(run: _Run, st: _State, pt: _Point, plan: _Plan, gamma: float, ls: _LineSearch) -> bool:
    """Record the iteration, adapt the performance request, and STEP to U + γ*ΔU (wrapped, the
    best point updated); True when the search stops (no decrease)."""
    settings = run.settings
    _record(run, st, pt, plan, gamma, ls.trials)
    if gamma == 0.0 and plan.beta and st.dfmax > 1e-9 * settings.max_performance_change:
        st.dfmax /= 10.0  # ask for less and try again from the same point
        return False
    if gamma > 0.0 and plan.beta:
        gain = abs(ls.flown[gamma].performance - ls.f_nom)
        st.dfmax = min(settings.max_performance_change, max(2.0 * gain, 1e-9 * settings.max_performance_change))
    if gamma == 0.0:
        note = _singular_note(run, pt, plan)
        st.reason = (note + "; " if note else "") + (
            f"line search found no decrease in {len(ls.trials)} trials (F'(0) = {plan.dr.slope:.3e})"
        )
        return True
    st.u = wrap_periodic(ls.step_to(gamma), run.prob.periodic)
    st.ev = ls.flown[gamma]
    st.tau = run.tau_of(st.ev)
    k_new = _key(st.ev, st.tau)
    if _better(k_new, st.best_key):
        st.best_u, st.best_ev, st.best_key = st.u.copy(), st.ev, k_new
    return False


def _iteration(run: _Run, st: _State, it: int) -> bool:
    """One UPHILL pass; True when the search stops (``st.reason``/``st.converged`` set)."""
    pt = _linearize(run, st, it)
    if pt is None:
        return True
    plan = _first_plan(run, st, pt)
    pt.theta, pt.free = plan.theta, plan.free
    why = _converged_why(run, pt, plan)
    if why:
        st.converged, st.reason = True, why
        _record(run, st, pt, plan, 0.0, [])
        return True
    if it > pt.s.max_iterations:
        st.reason = f"iteration limit ({pt.s.max_iterations}) reached"
        _record(run, st, pt, plan, 0.0, [])
        return True
    plan = _descent_fallback(run, st, pt, plan)
    if not plan.dr.slope < 0:
        note = _singular_note(run, pt, plan)
        st.reason = (note + "; " if note else "") + f"line search found no decrease (F'(0) = {plan.dr.slope:.3e} >= 0)"
        _record(run, st, pt, plan, 0.0, [])
        return True
    plan, gamma, ls = _step_search(run, st, pt, plan)
    return _take_step(run, st, pt, plan, gamma, ls)
