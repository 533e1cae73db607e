"""The second optimizer (fracas.tom.nlp): SciPy SLSQP / trust-constr on TOM's scaled problem,
against the closed-form answers and against the projected-gradient search."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from fracas.tom.nlp import solve_nlp
from fracas.tom.search import SearchSettings, _better, projected_gradient, weights
from tests.tom.test_search import circle_problem, isotonic_problem, make_problem, projection_problem, unit_weights

METHODS = ["slsqp", "trust_constr"]


@pytest.mark.parametrize("method", METHODS)
def test_projection_problem_closed_form(method):
    """Reference: max −½‖U − a‖² s.t. AU = b → U* = a − Aᵀ(AAᵀ)⁻¹(Aa − b) (KKT, linear algebra).

    Tolerance, from each solver's own stopping rule:
    * SLSQP stops on ftol 1e-12 on −F/ΔF_max; for this quadratic (curvature 1 in U) that leaves
      ‖U − U*‖ ~ √(2·1e-12·ΔF_max) ≈ 3e-6 at worst; 1e-6 holds with margin at its usual overshoot.
    * trust-constr stops on gtol (‖∇ₓL‖∞ < 1e-10) or, more often here, on xtol (the trust radius
      collapsed), which promises nothing by itself.  What it does promise is the ‖∇ₓL‖∞ it reports
      at the returned point.  The Lagrangian's Hessian in U is I, so on the constraint's null space
      ‖P(U − U*)‖₂ = ‖P ∇_U L‖₂ ≤ √m ‖∇_U L‖∞ ≤ √m · ΔF_max · ‖∇ₓL‖∞ / min d (x = U/d, objective
      −F/ΔF_max).  The test asserts that bound (×2 for rounding) and that it is ≤ 1e-6, i.e. the
      solver's options are tight enough for 1e-6.  (scipy 1.17 with xtol = 1e-10 stopped at
      ‖∇ₓL‖∞ 1.2e-6, 6.2e-6 away; the solver now runs to xtol = 1e-12.)
    """
    prob, answer, A = projection_problem(tol=1e-8, **unit_weights(4))
    seen = []
    settings = SearchSettings(weighting="control")
    res = solve_nlp(prob, method, settings, on_iteration=seen.append)
    assert res.search_converged, res.stop_reason
    assert res.history and all(h.submode == "NLP" for h in res.history) and seen == res.history
    assert res.stop_reason.startswith("SLSQP:" if method == "slsqp" else "trust-constr:")
    # the range-space part is fixed by the constraint (met to tol 1e-8 / σ_min(A))
    range_part = A.T @ np.linalg.solve(A @ A.T, A @ (res.u - answer))
    assert np.linalg.norm(range_part) < 1e-7
    if method == "slsqp":
        np.testing.assert_allclose(res.u, answer, atol=1e-6)
        return
    d = weights(np.zeros((2, 4)), np.full(2, 1e-8), prob.u0, prob.scale, prob.floor, "control", prob.value_weighted)
    bound = 2.0 * np.sqrt(4) * settings.max_performance_change * res.first_order_optimality / d.min()
    assert np.isfinite(bound) and bound <= 1e-6, (bound, res.stop_reason)
    assert np.linalg.norm(res.u - answer) <= bound + np.linalg.norm(range_part), res.stop_reason


@pytest.mark.parametrize("method", METHODS)
def test_circle_lagrange_point(method):
    """Reference: max u1 + u2 on u1² + u2² = 1 → (1/√2, 1/√2) (Lagrange); 1e-6 as above."""
    prob, answer = circle_problem(tol=1e-8, **unit_weights(2))
    res = solve_nlp(prob, method, SearchSettings(weighting="control"))
    assert res.search_converged, res.stop_reason
    np.testing.assert_allclose(res.u, answer, atol=1e-6)


@pytest.mark.parametrize("method", METHODS)
def test_bound_active_optimum(method):
    """Reference: max −½‖U − (2, 0, 0)‖² s.t. Σu = 1, u0 ≤ 0.5 → (0.5, 0.25, 0.25) (KKT with the
    bound active); 1e-6 as above."""
    a = np.array([2.0, 0.0, 0.0])
    prob = make_problem(
        np.array([0.0, 0.5, 0.5]),
        lambda u: np.array([u.sum()]),
        lambda u: np.ones((1, 3)),
        lambda u: -0.5 * float((u - a) @ (u - a)),
        lambda u: -(u - a),
        1.0,
        1e-8,
        upper=[0.5, np.inf, np.inf],
        **unit_weights(3),
    )
    res = solve_nlp(prob, method, SearchSettings(weighting="control"))
    assert res.search_converged, res.stop_reason
    np.testing.assert_allclose(res.u, [0.5, 0.25, 0.25], atol=1e-6)


def _nonlinear(**kw):
    """max F = 10 − (u0 − 1)² − 2(u1 + 0.5)² + u2 on the sphere |U|² = 4 (no closed form used)."""
    return make_problem(
        np.array([1.0, 0.5, 1.5]),
        lambda u: np.array([u @ u]),
        lambda u: 2.0 * u[None, :],
        lambda u: 10.0 - (u[0] - 1) ** 2 - 2 * (u[1] + 0.5) ** 2 + u[2],
        lambda u: np.array([-2 * (u[0] - 1), -4 * (u[1] + 0.5), 1.0]),
        4.0,
        1e-8,
        **kw,
    )


def test_projected_gradient_agrees_with_slsqp():
    """Reference: SLSQP (an independent SQP method) on a nonlinear problem without a closed form.
    The projected-gradient optimum must agree to 1e-5: its own stop (θ_conv = 1e-7, ε = 1e-8)
    bounds its error near 1e-7 times the curvature ratio, SLSQP's near 1e-6."""
    ref = solve_nlp(_nonlinear(**unit_weights(3)), "slsqp", SearchSettings(weighting="control"))
    assert ref.search_converged, ref.stop_reason
    pg = projected_gradient(
        _nonlinear(**unit_weights(3)),
        SearchSettings(weighting="control", convergence_angle_rad=1e-7, max_performance_change=0.5),
    )
    assert pg.search_converged, pg.stop_reason
    np.testing.assert_allclose(pg.u, ref.u, atol=1e-5)
    assert pg.evaluation.performance == pytest.approx(ref.evaluation.performance, abs=1e-8)
    tc = solve_nlp(_nonlinear(**unit_weights(3)), "trust_constr", SearchSettings(weighting="control"))
    np.testing.assert_allclose(tc.u, ref.u, atol=1e-5)


def test_sensitivities_are_cached_per_point():
    """Reference: the caching contract: objective, constraints and Jacobians at one point cost one
    `sensitivities` call, so no control vector is propagated twice."""
    log = []
    prob, _ = circle_problem(tol=1e-8, log=log, **unit_weights(2))
    res = solve_nlp(prob, "slsqp", SearchSettings(weighting="control"))
    points = [u.tobytes() for kind, u in log if kind == "sens"]
    assert len(points) == len(set(points)) == res.n_sensitivity_evaluations


def test_start_failure_and_bad_method():
    """Reference: the contract: a failed start returns at once with a reason; an unknown method
    is a ValueError."""
    prob, _ = circle_problem(fails=lambda u: True)
    res = solve_nlp(prob)
    assert res.stop_reason == "trajectory failed at the starting controls" and not res.search_converged
    with pytest.raises(ValueError):
        solve_nlp(prob, "nelder_mead")


def test_slsqp_honors_the_switch_order_rows():
    """Reference: max −‖u − c‖² s.t. u₀ ≤ u₁ ≤ u₂ ≤ u₃ (three switch-order rows, no targets) is
    the isotonic regression of c by pool-adjacent-violators: c = (3, 1, 2, 0) pools to
    (1.5, 1.5, 1.5, 1.5).  Tolerance 1e-6 (SLSQP's accuracy on this scaled problem)."""
    prob, _, A = isotonic_problem()
    res = solve_nlp(dataclasses.replace(prob, ineq_matrix=A, ineq_bound=np.zeros(3)), "slsqp")
    assert res.search_converged, res.stop_reason
    np.testing.assert_allclose(res.u, np.full(4, 1.5), atol=1e-6)
    assert np.all(A @ res.u <= 1e-9)


def test_slsqp_returns_the_best_feasible_point_not_its_last():
    """Reference: the best-point rule (search._better) over every point SLSQP evaluated.  On the
    circle u₁² + u₂² = 1 from (1, 0) (on it: |τ| = 0) with ε = 1e-6 and one SLSQP iteration, the
    last point has a higher F off the circle (|τ| ≫ 1): the feasible start comes back, and the
    stop reason says it is not SciPy's last point."""
    log = []
    prob, _ = circle_problem(tol=1e-6, u0=(1.0, 0.0), **unit_weights(2))
    prob = dataclasses.replace(prob, sensitivities=lambda u, f=prob.sensitivities: (log.append(np.array(u)), f(u))[1])
    res = solve_nlp(prob, "slsqp", SearchSettings(weighting="control", max_iterations=1))
    assert not res.search_converged
    assert "returned the best point seen, not the last" in res.stop_reason, res.stop_reason

    def key(u):
        tau = (u @ u - 1.0) / 1e-6
        return (abs(tau) <= 1.0, float(u.sum()), tau * tau)

    best = log[0]
    for u in log[1:]:
        if _better(key(u), key(best)):
            best = u
    np.testing.assert_array_equal(res.u, best)
