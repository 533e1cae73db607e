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

from collections.abc import Callable

import numpy as np

from fracas.tom.kernels import (
    Delu,
    _svd_parts,
    choose_submode,
    delu,
    dependent_controls,
    funct,
    null_projector,
    optimality_angle,
    predicted_slope,
    pseudo_inverse,
    weights,
)
from fracas.tom.line_search import Fit, bracket_min, bucket, cubic_min, genmin, quadratic_min
from fracas.tom.search_support import _better, _clean, _Counter, _validated, feasible_point, result_of, wrap_periodic
from fracas.tom.search_types import (
    RCOND,
    SUBMODES,
    WEIGHTINGS,
    Evaluation,
    IterationRecord,
    Problem,
    SearchResult,
    SearchSettings,
    Trial,
)
from fracas.tom.uphill import _iteration, _key, _Run, _State

# the search's names live in the modules above; imported from here by the NLP solvers, the
# modes and the tests
__all__ = [
    "RCOND",
    "SUBMODES",
    "WEIGHTINGS",
    "Delu",
    "Evaluation",
    "Fit",
    "IterationRecord",
    "Problem",
    "SearchResult",
    "SearchSettings",
    "Trial",
    "_better",
    "_clean",
    "_svd_parts",
    "_validated",
    "bracket_min",
    "bucket",
    "choose_submode",
    "cubic_min",
    "delu",
    "dependent_controls",
    "feasible_point",
    "funct",
    "genmin",
    "null_projector",
    "optimality_angle",
    "predicted_slope",
    "projected_gradient",
    "pseudo_inverse",
    "quadratic_min",
    "result_of",
    "weights",
    "wrap_periodic",
]

_DEFAULT = SearchSettings()


# --------------------------------------------------------------------------------- the driver


def projected_gradient(
    problem: Problem,
    settings: SearchSettings = _DEFAULT,
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
    prob = _validated(problem)
    m, n = prob.u0.size, prob.desired.size
    if n == 0 and settings.submode in ("target", "target_optimize"):
        raise ValueError(f"submode {settings.submode!r} needs targets; the problem has none")
    desired = prob.desired
    err = prob.target_error or (lambda T: T - desired)
    run = _Run(prob, settings, n, m, err, _Counter(prob), [], on_iteration)
    u = prob.u0.copy()
    if prob.given_S is not None:
        ev = run.cnt.evaluate(u, n)
        S, G = prob.given_S, prob.given_G
    else:
        ev, S, G = run.cnt.sensitivities(u, n, m)
    if not ev.ok:
        return run.finish(u, ev, "trajectory failed at the starting controls", False)
    tau = run.tau_of(ev)
    if not np.all(np.isfinite(tau)):
        return run.finish(u, ev, "target error not finite at the starting controls", False)
    st = _State(u, ev, S, G, tau, u.copy(), ev, _key(ev, tau), dfmax=settings.max_performance_change)
    for it in range(1, settings.max_iterations + 2):
        if _iteration(run, st, it):
            break
    if st.converged:
        return run.finish(st.u, st.ev, st.reason, True)
    return run.finish(st.best_u, st.best_ev, st.reason, False)
