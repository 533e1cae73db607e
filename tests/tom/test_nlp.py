"""The second optimizer (fracas.tom.nlp): SciPy SLSQP / trust-constr on TOM's scaled problem,
against the closed-form answers and against the projected-gradient search."""

from __future__ import annotations

import numpy as np
import pytest

from fracas.tom.nlp import solve_nlp
from fracas.tom.search import SearchSettings, projected_gradient
from tests.tom.test_search import circle_problem, make_problem, projection_problem, unit_weights

METHODS = ["slsqp", "trust_constr"]


@pytest.mark.parametrize("method", METHODS)
def test_projection_problem_closed_form(method):
    """Reference: max −½‖U − a‖² s.t. AU = b → U* = a − Aᵀ(AAᵀ)⁻¹(Aa − b) (KKT, linear algebra).
    Tolerance 1e-6: the SciPy stopping tolerances (ftol 1e-12 on −F/ΔF_max, gtol 1e-10)."""
    prob, answer, _ = projection_problem(tol=1e-8, **unit_weights(4))
    seen = []
    res = solve_nlp(prob, method, SearchSettings(weighting="control"), on_iteration=seen.append)
    assert res.search_converged, res.stop_reason
    np.testing.assert_allclose(res.u, answer, atol=1e-6)
    assert res.history and all(h.submode == "NLP" for h in res.history) and seen == res.history
    assert res.stop_reason.startswith("SLSQP:" if method == "slsqp" else "trust-constr:")


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
