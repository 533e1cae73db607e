"""The third optimizer (fracas.tom.ipopt): IPOPT through casadi on TOM's scaled problem, against
closed-form answers, against SLSQP, and its best-feasible-point and failed-trajectory rules."""

from __future__ import annotations

import dataclasses
import sys

import numpy as np
import pytest

pytest.importorskip("casadi")

from fracas.tom import ipopt as ipopt_module  # noqa: E402
from fracas.tom.ipopt import solve_ipopt  # noqa: E402
from fracas.tom.nlp import solve_nlp  # noqa: E402
from fracas.tom.search import SearchSettings, _better  # noqa: E402
from tests.tom.test_search import bound_problem, circle_problem, isotonic_problem, make_problem, unit_weights  # noqa: E402

# max −(u − c)ᵀQ(u − c) s.t. a·u = t (one target) and h₁·u ≤ β₁ (active), h₂·u ≤ β₂ (inactive)
Q = np.array([[2.0, 0.5, 0.0, 0.0], [0.5, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.2], [0.0, 0.0, 0.2, 3.0]])
C_OPT = np.array([2.0, 0.0, 1.0, -1.0])
A_TGT = np.array([1.0, 1.0, 1.0, 1.0])
T_TGT = 1.0
H = np.array([[1.0, -1.0, 0.0, 0.0], [0.0, 0.0, 1.0, -1.0]])  # u0 ≤ u1 and u2 ≤ u3 + 5: two nonzeros a row
BETA = np.array([0.0, 5.0])


def quadratic_problem(tol=1e-9, ineq=True, weighting_kw=None, log=None):
    prob = make_problem(
        np.zeros(4),
        lambda u: np.array([A_TGT @ u]),
        lambda u: A_TGT[None, :],
        lambda u: -float((u - C_OPT) @ Q @ (u - C_OPT)),
        lambda u: -2.0 * Q @ (u - C_OPT),
        T_TGT,
        tol,
        log=log,
        **(weighting_kw or unit_weights(4)),
    )
    if ineq:
        prob = dataclasses.replace(prob, ineq_matrix=H.copy(), ineq_bound=BETA.copy())
    return prob


def kkt_answer(rows):
    """Equality-constrained minimum of (u − c)ᵀQ(u − c) on C u = r: stationarity 2Q(u − c) + Cᵀμ = 0
    gives u = c − ½Q⁻¹Cᵀμ with μ = 2(CQ⁻¹Cᵀ)⁻¹(Cc − r)."""
    C = np.vstack([A_TGT] + [H[i] for i in rows])
    r = np.concatenate([[T_TGT], BETA[list(rows)]])
    Qi_Ct = np.linalg.solve(Q, C.T)
    mu = 2.0 * np.linalg.solve(C @ Qi_Ct, C @ C_OPT - r)
    return C_OPT - 0.5 * Qi_Ct @ mu, mu


@pytest.mark.parametrize("weighting", ["sensitivity", "control"])
def test_quadratic_with_target_and_switch_order_matches_kkt(weighting, capfd):
    """Reference: the KKT point of max −(u − c)ᵀQ(u − c) s.t. a·u = t, h₁·u ≤ β₁, h₂·u ≤ β₂ in closed
    form (active set {target, h₁}, checked here: μ₁ > 0, h₂ slack > 0).  Tolerance 1e-7: the target
    tolerance is 1e-9, so any point of the within-tolerance band the best-point rule may return is
    ~1e-9 from the KKT point, and IPOPT's tol 1e-8 on the O(1)-scaled problem leaves ~1e-9 more.
    Also (c): the inequality is honored, on its boundary within the 1e-9 relative slack."""
    u_star, mu = kkt_answer([0])
    assert mu[1] > 0.1 and H[1] @ u_star < BETA[1] - 1.0  # the active set of the reference
    seen = []
    res = solve_ipopt(quadratic_problem(), SearchSettings(weighting=weighting), on_iteration=seen.append)
    assert res.search_converged, res.stop_reason
    # IPOPT's own success, or TOM's stall test (the last 5 iterates within tolerance, F flat to 1e-7,
    # TEST angle below θ_conv): either way the point must be the KKT point below
    assert res.stop_reason.startswith("IPOPT: Solve_Succeeded") or "stall test" in res.stop_reason
    np.testing.assert_allclose(res.u, u_star, atol=1e-7)
    assert res.history and all(h.submode == "IPOPT" for h in res.history) and seen == res.history
    assert res.evaluation.ok and abs(A_TGT @ res.u - T_TGT) <= 1e-9
    assert H[0] @ res.u <= BETA[0] + 1e-9 and abs(H[0] @ res.u - BETA[0]) < 1e-8  # (c): on the boundary
    out, err = capfd.readouterr()
    assert out == "" and err == ""  # IPOPT / casadi print nothing


def test_inequalities_are_honored_isotonic_projection():
    """Reference: max −‖u − c‖² s.t. u₀ ≤ u₁ ≤ u₂ ≤ u₃ (switch order, three rows of two nonzeros,
    no targets) is the isotonic regression of c, by pool-adjacent-violators: c = (3, 1, 2, 0)
    pools to its mean, (1.5, 1.5, 1.5, 1.5).  Without the rows the answer would be c itself."""
    prob, c, A = isotonic_problem()
    res = solve_ipopt(dataclasses.replace(prob, ineq_matrix=A, ineq_bound=np.zeros(3)))
    assert res.search_converged, res.stop_reason
    np.testing.assert_allclose(res.u, np.full(4, 1.5), atol=1e-7)
    assert np.all(A @ res.u <= 1e-9)
    free = solve_ipopt(prob)
    np.testing.assert_allclose(free.u, c, atol=1e-7)


def test_agrees_with_slsqp_on_the_equality_only_problem():
    """Reference: the closed-form KKT point of the same quadratic without the inequalities (active
    set {target}), and SLSQP's answer on it: IPOPT within 1e-7 of the answer, and of SLSQP within
    1e-5 (SLSQP's own accuracy: it stops at |Δf| < 1e-8 ΔF_max with Σ|τ| < 0.1, measured 1.8e-6)."""
    u_star, _ = kkt_answer([])
    settings = SearchSettings(weighting="control")
    res = solve_ipopt(quadratic_problem(ineq=False), settings)
    ref = solve_nlp(quadratic_problem(ineq=False), "slsqp", settings)
    assert res.search_converged and ref.search_converged, (res.stop_reason, ref.stop_reason)
    np.testing.assert_allclose(res.u, u_star, atol=1e-7)
    np.testing.assert_allclose(res.u, ref.u, atol=1e-5)
    assert res.evaluation.performance >= ref.evaluation.performance - 1e-9


def test_returns_best_feasible_point_not_the_last_iterate():
    """Reference: the best-point rule of search._better over every point evaluated (logged here).
    On the circle u₁² + u₂² = 1 from (1, 0) (on the circle, |τ| = 0) with ε = 1e-6 and two IPOPT
    iterations, the last iterate (≈ (0.75, 0.75)) has a higher F but |τ| ≫ 1: the start, feasible,
    must come back, and stop_reason must say it is not IPOPT's last iterate."""
    log = []
    prob, _ = circle_problem(tol=1e-6, u0=(1.0, 0.0), **unit_weights(2))
    prob = dataclasses.replace(prob, sensitivities=lambda u, f=prob.sensitivities: (log.append(np.array(u)), f(u))[1])
    res = solve_ipopt(prob, SearchSettings(weighting="control", max_iterations=2))
    assert not res.search_converged and "Maximum_Iterations_Exceeded" in res.stop_reason
    assert "not IPOPT's last iterate" in res.stop_reason
    last = res.history[-1]
    assert np.max(np.abs(last.tau)) > 1.0 and last.performance > res.evaluation.performance
    np.testing.assert_array_equal(res.u, [1.0, 0.0])

    def key(u):
        tau = (u @ u - 1.0) / 1e-6
        return (abs(tau) <= 1.0, float(u.sum()), tau * tau)

    best = log[0]
    for u in log[1:]:
        if _better(key(u), key(best)):
            best = u
    np.testing.assert_array_equal(res.u, best)
    assert res.n_sensitivity_evaluations == len(log) == len({u.tobytes() for u in log})  # one call a point


def test_failed_trajectories_do_not_raise_and_are_never_returned(capfd):
    """Reference: max −½‖U − (2, 0, 0)‖² s.t. Σu = 1, u₀ ≤ 0.5 has its optimum (0.5, 0.25, 0.25)
    (KKT, bound active); trajectories with u₀ > 0.3 fail (ok False).  The flyable optimum is
    (0.3, 0.35, 0.35) (KKT with u₀ ≤ 0.3 active): IPOPT, cutting back every step that lands in the
    failed region, gets there within 1e-3 without raising or printing, and the returned point flew."""
    prob = bound_problem(1e-6, fails=lambda u: u[0] > 0.3)
    res = solve_ipopt(prob, SearchSettings(weighting="control", max_iterations=40))
    assert res.evaluation.ok and res.u[0] <= 0.3
    assert abs(res.u.sum() - 1.0) <= 1e-6
    np.testing.assert_allclose(res.u, [0.3, 0.35, 0.35], atol=1e-3)
    out, err = capfd.readouterr()
    assert out == "" and err == ""


def test_failed_start_and_exceptions():
    """Reference: solve_nlp's contract: a start that fails returns at once (not converged); an
    exception from sensitivities or on_iteration stops IPOPT and reaches the caller unchanged."""
    prob = quadratic_problem(ineq=False)
    failed = make_problem(
        np.zeros(2), lambda u: u[:1], lambda u: np.eye(1, 2), lambda u: 0.0, lambda u: np.zeros(2), 0.0, 1.0,
        fails=lambda u: True,
    )  # fmt: skip
    res = solve_ipopt(failed)
    assert not res.search_converged and res.stop_reason == "trajectory failed at the starting controls"

    calls = []

    def sensitivities(u, f=prob.sensitivities):
        calls.append(1)
        if len(calls) == 3:
            raise RuntimeError("propagator exploded")
        return f(u)

    with pytest.raises(RuntimeError, match="propagator exploded"):
        solve_ipopt(dataclasses.replace(prob, sensitivities=sensitivities))

    def stop(rec):
        raise KeyError("stop here")

    with pytest.raises(KeyError, match="stop here"):
        solve_ipopt(prob, on_iteration=stop)


def test_missing_casadi_names_the_extra(monkeypatch):
    """Reference: the install hint of the brief, `pip install 'fracas[ipopt]'`."""
    ipopt_module._casadi.cache_clear()
    monkeypatch.setitem(sys.modules, "casadi", None)
    try:
        with pytest.raises(ImportError, match=r"needs casadi: pip install 'fracas\[ipopt\]'"):
            solve_ipopt(quadratic_problem())
    finally:
        ipopt_module._casadi.cache_clear()
