"""TOM projected-gradient kernel (fracas.tom.search): the pure routines against analytic
references, and the full search on problems with closed-form Kuhn–Tucker answers."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from fracas.tom.search import (
    Evaluation,
    Problem,
    SearchSettings,
    _validated,
    bracket_min,
    bucket,
    choose_submode,
    cubic_min,
    delu,
    dependent_controls,
    funct,
    genmin,
    optimality_angle,
    projected_gradient,
    pseudo_inverse,
    quadratic_min,
    weights,
)

# ------------------------------------------------------------------------------ analytic problems
# (closed-form answers; test_nlp.py imports these too)


def make_problem(
    u0,
    targets,
    jac,
    perf,
    grad,
    desired,
    tol,
    *,
    lower=None,
    upper=None,
    scale=None,
    floor=None,
    fails=None,
    labels=(),
    target_labels=(),
    log=None,
):
    """Problem from analytic T(U), S(U), F(U), G(U); ``fails(U)`` marks failing trajectories."""
    u0 = np.asarray(u0, dtype=float)
    m = u0.size
    desired = np.atleast_1d(np.asarray(desired, dtype=float))
    n = desired.size

    def _eval(u):
        if fails is not None and fails(u):
            return Evaluation(np.full(n, np.nan), float("nan"), False)
        return Evaluation(np.asarray(targets(u), dtype=float).reshape(n), float(perf(u)), True)

    def evaluate(u):
        if log is not None:
            log.append(("eval", np.array(u)))
        return _eval(u)

    def sensitivities(u):
        if log is not None:
            log.append(("sens", np.array(u)))
        return _eval(u), np.asarray(jac(u), dtype=float).reshape(n, m), np.asarray(grad(u), dtype=float).reshape(m)

    return Problem(
        u0=u0,
        desired=desired,
        tolerance=np.broadcast_to(np.asarray(tol, dtype=float), (n,)).copy(),
        scale=np.ones(m) if scale is None else np.asarray(scale, dtype=float),
        lower=np.full(m, -np.inf) if lower is None else np.asarray(lower, dtype=float),
        upper=np.full(m, np.inf) if upper is None else np.asarray(upper, dtype=float),
        floor=np.zeros(m) if floor is None else np.asarray(floor, dtype=float),
        evaluate=evaluate,
        sensitivities=sensitivities,
        labels=tuple(labels),
        target_labels=tuple(target_labels),
    )


def projection_problem(tol=1e-8, **kw):
    """Maximize F = −½‖U − a‖² subject to A U = b (A 2×4).  Answer: the Euclidean projection
    U* = a − Aᵀ(AAᵀ)⁻¹(Aa − b)."""
    A = np.array([[1.0, 2.0, -1.0, 0.5], [0.0, 1.0, 1.0, -1.0]])
    b = np.array([1.0, -0.5])
    a = np.array([0.8, -0.3, 0.4, 1.1])
    answer = a - A.T @ np.linalg.solve(A @ A.T, A @ a - b)
    prob = make_problem(
        np.zeros(4),
        lambda u: A @ u,
        lambda u: A,
        lambda u: -0.5 * float((u - a) @ (u - a)),
        lambda u: -(u - a),
        b,
        tol,
        **kw,
    )
    return prob, answer, A


def circle_problem(tol=1e-8, u0=(0.9, 0.1), **kw):
    """Maximize F = u1 + u2 on the circle u1² + u2² = 1.  Answer (1/√2, 1/√2) (Lagrange)."""
    prob = make_problem(
        u0,
        lambda u: np.array([u @ u]),
        lambda u: 2.0 * u[None, :],
        lambda u: float(u.sum()),
        lambda u: np.ones(2),
        1.0,
        tol,
        **kw,
    )
    return prob, np.full(2, 1 / np.sqrt(2))


def isotonic_problem():
    """(problem without its rows, c, A): max −‖u − c‖², c = (3, 1, 2, 0), from (0, 1, 2, 3), no
    targets; A the switch-order rows u₀ ≤ u₁ ≤ u₂ ≤ u₃ (b = 0).  With the rows the answer is the
    isotonic regression of c by pool-adjacent-violators, (1.5, 1.5, 1.5, 1.5); without, c."""
    c = np.array([3.0, 1.0, 2.0, 0.0])
    prob = make_problem(
        np.array([0.0, 1.0, 2.0, 3.0]),
        lambda u: np.zeros(0),
        lambda u: np.zeros((0, 4)),
        lambda u: -float((u - c) @ (u - c)),
        lambda u: -2.0 * (u - c),
        np.zeros(0),
        np.zeros(0),
        **unit_weights(4),
    )
    A = np.array([[1.0, -1.0, 0.0, 0.0], [0.0, 1.0, -1.0, 0.0], [0.0, 0.0, 1.0, -1.0]])
    return prob, c, A


def bound_problem(tol=1e-8, **kw):
    """max −½‖U − a‖², a = (2, 0, 0), s.t. u0 + u1 + u2 = 1 (tolerance ``tol``) and u0 ≤ 0.5, from
    (0, 0.5, 0.5): the KKT point is (0.5, 0.25, 0.25) with the bound active."""
    a = np.array([2.0, 0.0, 0.0])
    return make_problem(
        np.array([0.0, 0.5, 0.5]),
        lambda u: np.array([u.sum()]),
        lambda u: np.ones((1, 3)),
        lambda u: -0.5 * float((u - a) @ (u - a)),
        lambda u: -(u - a),
        1.0,
        tol,
        upper=[0.5, np.inf, np.inf],
        **kw,
        **unit_weights(3),
    )


def unit_weights(m, bound=10.0):
    """Control weighting with k = 1/bound and floor = bound: d_j = 1 while |U_j| ≤ bound (W = I)."""
    return {"scale": np.full(m, 1.0 / bound), "floor": np.full(m, bound)}


# ------------------------------------------------------------------------------ MINMUM


def test_minmum_case1_recovers_exact_quadratic_and_printed_a2_is_garbled():
    """Reference: the analytic minimizer of q(γ) = 3 − 2γ + 0.7γ² (γ* = 2/1.4, q(γ*) = 3 − 1/0.7).
    The fit is exact for a quadratic, so only rounding remains (1e-12).  The report's OCR prints
    a₂ = F(γ₀) − a₀/γ₀² + a₁/γ₀; that form is shown to be wrong (digest MINMUM-1)."""
    q = lambda g: 3.0 - 2.0 * g + 0.7 * g**2
    g0 = 1.3
    fit = quadratic_min(q(0), -2.0, g0, q(g0))
    assert fit.coeffs[2] == pytest.approx(0.7, abs=1e-12)
    assert fit.gamma == pytest.approx(2.0 / 1.4, abs=1e-12)
    assert fit.predicted == pytest.approx(3.0 - 1.0 / 0.7, abs=1e-12)
    printed_a2 = q(g0) - q(0) / g0**2 + (-2.0) / g0
    assert abs(printed_a2 - 0.7) > 0.1
    # Concave fit: no minimizer.
    assert math.isnan(quadratic_min(1.0, -1.0, 1.0, -1.0).gamma)


CUBIC = (1.0, -1.5, 0.4, 0.2)  # a0..a3


def _cubic(c, g):
    return sum(ck * g**k for k, ck in enumerate(c))


@pytest.mark.parametrize("order", ["small_first", "large_first"])
def test_minmum_case2_recovers_exact_cubic_and_printed_a3_is_garbled(order):
    """Reference: the cubic c(γ) = 1 − 1.5γ + 0.4γ² + 0.2γ³, whose local minimizer is the positive
    root of c'(γ) = −1.5 + 0.8γ + 0.6γ² = 0.  Four data determine a cubic exactly, so the
    coefficients and γ* come back to rounding (1e-12), whatever the order of γ₀, γ₁.  The OCR's a₃
    (α² dropped on F(λ), digest MINMUM-2b) is far off on this cubic: the garble is fixed."""
    g0, g1 = (0.7, 2.1) if order == "small_first" else (2.1, 0.7)
    f = lambda g: _cubic(CUBIC, g)
    fit = cubic_min(f(0), CUBIC[1], g0, f(g0), g1, f(g1))
    np.testing.assert_allclose(fit.coeffs, CUBIC, rtol=0, atol=1e-12)
    g_star = (-0.8 + math.sqrt(0.64 + 4 * 0.6 * 1.5)) / 1.2
    assert fit.gamma == pytest.approx(g_star, abs=1e-12)
    assert fit.predicted == pytest.approx(f(g_star), abs=1e-12)
    lam, al = 2.1, 0.7 / 2.1
    a0, a1 = CUBIC[0], CUBIC[1]
    printed_a3 = ((f(lam) - f(al * lam)) / (1 - al) + (1 + al) * a0 + lam * al * a1) / (lam**3 * al**2)
    assert abs(printed_a3 - CUBIC[3]) > 1.0 * abs(CUBIC[3])


def test_minmum_case2_negative_leading_term_and_rejections():
    """Reference: c(γ) = 1 − γ + 0.5γ² − 0.05γ³ has its local minimum at the smaller root of
    c' = −1 + γ − 0.15γ², γ* = (1 − √0.4)/0.3 (exact fit, 1e-12).  A cubic with negative
    discriminant a₂² − 3a₁a₃ < 0 has no minimum and is rejected (nan)."""
    c = (1.0, -1.0, 0.5, -0.05)
    f = lambda g: _cubic(c, g)
    fit = cubic_min(f(0), c[1], 0.5, f(0.5), 3.0, f(3.0))
    assert fit.gamma == pytest.approx((1 - math.sqrt(0.4)) / 0.3, abs=1e-12)
    bad = (1.0, -1.0, -1.0, -0.5)  # disc = 1 − 1.5 < 0
    fb = lambda g: _cubic(bad, g)
    assert math.isnan(cubic_min(fb(0), bad[1], 0.5, fb(0.5), 1.5, fb(1.5)).gamma)


def test_minmum_case3_bracket_recovers_quadratic_vertex():
    """Reference: the vertex of q(γ) = 2 + (γ − 1.7)²·0.9 − 0.3 (γ* = 1.7), fitted through the
    unequally spaced bracket 0.4 < 1.1 < 3.5; the Lagrange form is exact (1e-12)."""
    q = lambda g: 2.0 + 0.9 * (g - 1.7) ** 2 - 0.3
    gs = [0.4, 1.1, 3.5]
    fit = bracket_min(gs, [q(g) for g in gs])
    assert fit.gamma == pytest.approx(1.7, abs=1e-12)
    assert fit.predicted == pytest.approx(1.7, abs=1e-12)


def test_bucket_finds_the_bracket_in_sorted_order():
    """Reference: BUCKET-1 by inspection: unsorted trials, the interior minimum's sorted index."""
    assert bucket([2.0, 0.0, 1.0, 4.0], [3.0, 5.0, 1.0, 9.0]) == 1  # sorted: 0, 1, 2, 4
    assert bucket([0.0, 1.0, 2.0], [3.0, 2.0, 1.0]) == 0  # monotone: no bracket
    assert bucket([0.0, 1.0, 2.0], [3.0, 1.0, math.inf]) == 1  # a failed trial closes a bracket


def test_genmin_exact_quadratic_takes_two_trials():
    """Reference: F(γ) = (1 − 0.8γ)² + 0.1 has γ* = 1.25.  The first trial (γ₀ = 1) and F'(0) fix
    the quadratic exactly, so the case-1 fit lands on 1.25 and is accepted at the second trial."""
    calls = []
    cost = lambda g: calls.append(g) or (1 - 0.8 * g) ** 2 + 0.1
    g, f, pts = genmin(cost, cost(0.0), -1.6, gamma_max=4.0)
    calls.pop(0)
    assert g == pytest.approx(1.25, abs=1e-12) and f == pytest.approx(0.1, abs=1e-12)
    assert len(pts) == 2


def test_genmin_shrinks_past_failed_trials_and_refuses_ascent():
    """Reference: F(γ) = (γ − 0.3)² undefined (+inf, P-A12) for γ > 0.6: GENMIN must shrink below
    the failures and return a decrease; with F'(0) ≥ 0 it returns γ* = 0 without a trial (P-A10)."""
    cost = lambda g: math.inf if g > 0.6 else (g - 0.3) ** 2
    g, f, pts = genmin(cost, 0.09, -0.6, gamma_max=4.0)
    assert 0 < g <= 0.6 and f < 0.09
    assert any(math.isinf(p[1]) for p in pts)
    assert genmin(cost, 0.09, 0.0) == (0.0, 0.09, [])


def test_genmin_expands_toward_gamma_max_on_a_linear_decrease():
    """Reference: F(γ) = 1 − γ has no interior minimum; GENMIN must expand to γ_max = 4 (the cap)."""
    g, f, _ = genmin(lambda g: 1.0 - g, 1.0, -1.0, gamma_max=4.0)
    assert g == pytest.approx(4.0) and f == pytest.approx(-3.0)


# ------------------------------------------------------------------- WEIGHT, STEST, TEST, PINV


def test_weights_sensitivity_and_control_forms():
    """Reference: WEIGHT-1 d_j = k_j/max_i |S_ij|/ε_i and WEIGHT-2 d_j = k_j max(|U_j|, floor_j),
    computed by hand; a column without sensitivity falls back to control weighting."""
    S = np.array([[2.0, 0.0, -1.0], [0.5, 0.0, 4.0]])
    tol = np.array([0.1, 2.0])
    u = np.array([3.0, 0.0, -0.2])
    k = np.array([1.0, 2.0, 0.5])
    floor = np.array([0.0, 0.5, 1.0])
    d = weights(S, tol, u, k, floor, "sensitivity")
    np.testing.assert_allclose(d, [1.0 / 20.0, 2.0 * 0.5, 0.5 / 10.0], rtol=1e-15)
    np.testing.assert_allclose(weights(S, tol, u, k, floor, "control"), [3.0, 1.0, 0.5], rtol=1e-15)
    np.testing.assert_allclose(weights(np.zeros((0, 3)), np.zeros(0), u, k, np.zeros(3), "control"), [3.0, 2.0, 0.1])


def test_stest_drops_one_of_two_nearly_parallel_columns_and_permutation_changes_only_the_order():
    """Reference: STEST-1 by construction: columns a and a' (0.01° apart) are dependent under
    θ_min = 1°, b is not.  Under any permutation exactly one of {a, a'} is dropped, b never; with
    three mutually parallel columns two are dropped and one kept."""
    a = np.array([1.0, 2.0, 0.5])
    a2 = a + 1e-4 * np.array([0.3, -0.1, 0.2])
    b = np.array([0.0, 1.0, -1.0])
    cols = {"a": a, "a2": a2, "b": b}
    theta = math.radians(1.0)
    for order in (["a", "a2", "b"], ["b", "a2", "a"], ["a2", "b", "a"]):
        S = np.column_stack([cols[c] for c in order])
        drop = dependent_controls(S, theta)
        assert len(drop) == 1 and order[drop[0]] in ("a", "a2")
    S3 = np.column_stack([a, b, a2, 3.0 * a])
    drop3 = dependent_controls(S3, theta)
    assert len(drop3) == 2 and 1 not in drop3
    assert dependent_controls(np.column_stack([a, b]), theta) == ()


def test_choose_submode_thresholds():
    """Reference: TEST-1: E_rms > T_up → T, T_low < E_rms ≤ T_up → T+O, else O; fixed modes map."""
    s = SearchSettings()
    assert [choose_submode(x, s) for x in (10.5, 10.0, 1.5, 1.0, 0.0)] == ["T", "T+O", "T+O", "O", "O"]
    assert choose_submode(100.0, SearchSettings(submode="optimize")) == "O"
    assert choose_submode(0.0, SearchSettings(submode="target")) == "T"


def test_pseudo_inverse_forms_and_cutoff():
    """Reference: S⁺ = Sᵀ(SSᵀ)⁻¹ (N < M, full rank) and (SᵀS)⁻¹Sᵀ (N > M), to 1e-12; a rank-one S
    keeps one singular value (the relative cutoff, P-A5), matching numpy's pinv with the same rcond."""
    rng = np.random.default_rng(1)
    S = rng.normal(size=(2, 4))
    np.testing.assert_allclose(pseudo_inverse(S), S.T @ np.linalg.inv(S @ S.T), atol=1e-12)
    S = rng.normal(size=(4, 2))
    np.testing.assert_allclose(pseudo_inverse(S), np.linalg.inv(S.T @ S) @ S.T, atol=1e-12)
    S1 = np.outer([1.0, 2.0], [1.0, -1.0, 0.5]) + 1e-14 * rng.normal(size=(2, 3))
    np.testing.assert_allclose(pseudo_inverse(S1, 1e-10), np.linalg.pinv(S1, rcond=1e-10), atol=1e-9)


# ------------------------------------------------------------------------------ DELU / SIZE


def test_delu_null_space_and_targeting_equations():
    """Reference: DELU-1/2 as linear algebra: S̃ΔŨ₁ = 0 to rounding (1e-13 relative to |S̃||ΔŨ₁|),
    S̃ΔŨ₂ = −pτ exactly for full row rank when |ΔŨ₂| < R; DELU-3's gain ≤ ΔF_max and |ΔŨ| ≤ R."""
    rng = np.random.default_rng(7)
    S = rng.normal(size=(2, 5))
    G = rng.normal(size=5)
    tau = np.array([0.3, -0.2])
    step = delu(S, G, tau, p=0.5, radius=10.0, max_performance_change=0.05)
    scale = np.linalg.norm(S) * np.linalg.norm(step.du1)
    assert np.linalg.norm(S @ step.du1) <= 1e-13 * scale
    np.testing.assert_allclose(S @ step.du2, -0.5 * tau, atol=1e-14)
    pg = -step.du1 / step.K
    assert step.K * pg @ pg == pytest.approx(0.05, rel=1e-12)  # ΔF_max binds here
    tight = delu(S, G, tau, p=1.0, radius=0.2, max_performance_change=100.0)
    assert np.linalg.norm(tight.du2 + tight.du1) == pytest.approx(0.2, rel=1e-12)  # both budgets used
    far = delu(S, G, 100 * tau, p=1.0, radius=0.2, max_performance_change=100.0)
    assert np.linalg.norm(far.du2) == pytest.approx(0.2, rel=1e-12) and far.K == 0.0


def _analytic():
    """Smooth analytic targets/performance with exact derivatives (for the slope check)."""
    T = lambda u: np.array([u[0] ** 2 + u[1] + math.sin(u[2]), u[0] * u[3] - u[1] ** 3])
    S = lambda u: np.array([[2 * u[0], 1.0, math.cos(u[2]), 0.0], [u[3], -3 * u[1] ** 2, 0.0, u[0]]])
    F = lambda u: 100.0 - (u[0] - 1) ** 2 - 0.5 * u[1] ** 2 + 0.3 * u[2] * u[3] + math.exp(0.2 * u[3])
    G = lambda u: np.array([-2 * (u[0] - 1), -u[1], 0.3 * u[3], 0.3 * u[2] + 0.2 * math.exp(0.2 * u[3])])
    return T, S, F, G


@pytest.mark.parametrize("alpha,beta", [(1.0, 1.0), (1.0, 0.0), (0.0, 1.0)])
def test_predicted_slope_equals_numerical_slope_of_funct(alpha, beta):
    """Reference: a central difference (h = 1e-5, truncation O(h²) ≈ 1e-10 relative) of FUNCT's
    F(γ) along the DELU step of a smooth analytic problem equals SIZE-5's F'(0) (rtol 1e-6)."""
    from fracas.tom.search import _svd_parts, predicted_slope

    T, Sf, F, Gf = _analytic()
    u = np.array([0.4, 0.3, -0.2, 0.7])
    desired = np.array([0.2, 0.1])
    tol = np.array([0.05, 0.02])
    S, G = Sf(u), Gf(u)
    d = weights(S, tol, u, np.ones(4), np.zeros(4), "sensitivity")
    St, Gt = S * d / tol[:, None], -d * G
    tau = (T(u) - desired) / tol
    dfm = 0.3
    step = delu(St, Gt, tau, p=0.7, radius=2.0, max_performance_change=dfm, alpha=alpha)
    du_s = alpha * step.du2 + beta * step.du1
    pinv = _svd_parts(St, 1e-10)[0]
    restoration = pinv.T @ Gt

    def phi(g):
        ut = u + g * d * du_s
        return funct(
            (T(ut) - desired) / tol, F(ut), F(u), restoration, alpha=alpha, beta=beta, max_performance_change=dfm
        )

    h = 1e-5
    numeric = (phi(h) - phi(-h)) / (2 * h)
    pred = predicted_slope(St, Gt, tau, du_s, alpha=alpha, beta=beta, max_performance_change=dfm)
    assert pred < 0
    assert pred == pytest.approx(numeric, rel=1e-6)


# ------------------------------------------------------------------------------ the search


def test_projection_problem_converges_to_closed_form():
    """Reference: max −½‖U − a‖² s.t. AU = b has the KKT answer U* = a − Aᵀ(AAᵀ)⁻¹(Aa − b).
    With W = I the stop test bounds the error: null-space part ≤ sin θ·|G| ≤ θ_conv|G| (Hessian I),
    range part ≤ ‖A⁺‖·√N·ε; tolerance 2(θ_conv|G*| + ‖A⁺‖√N ε)."""
    prob, answer, A = projection_problem(tol=1e-8, **unit_weights(4))
    s = SearchSettings(convergence_angle_rad=1e-7, weighting="control")
    seen = []
    res = projected_gradient(prob, s, on_iteration=seen.append)
    assert res.search_converged, res.stop_reason
    assert res.stop_reason.startswith("converged: targets within tolerance and gradient angle")
    g_norm = np.linalg.norm(answer - np.array([0.8, -0.3, 0.4, 1.1]))
    bound = 2 * (1e-7 * g_norm + np.linalg.norm(np.linalg.pinv(A), 2) * math.sqrt(2) * 1e-8)
    assert np.linalg.norm(res.u - answer) <= bound
    assert seen == res.history and res.history[-1].gamma == 0.0
    assert res.n_sensitivity_evaluations == len(res.history)
    assert min(res.time_sensitivities_s, res.time_line_search_s, res.time_bookkeeping_s) >= 0


@pytest.mark.parametrize("c", [(1.0, 1.0), (1.0, 2.0)])
def test_circle_converges_to_lagrange_point(c):
    """Reference: max c·U on u1² + u2² = 1 is c/|c| (Lagrange).  At a feasible point the gradient
    angle θ equals the polar-angle offset from the answer, and the radius is within ε/2: tolerance
    θ_conv + ε, doubled for the last step's slack."""
    c = np.array(c)
    prob, _ = circle_problem(tol=1e-8, **unit_weights(2))
    prob = make_like(prob, sensitivities=_with_gradient(prob.sensitivities, c), evaluate=_with_perf(prob.evaluate, c))
    answer = c / np.linalg.norm(c)
    s = SearchSettings(convergence_angle_rad=1e-7, weighting="control", max_performance_change=0.1)
    res = projected_gradient(prob, s)
    assert res.search_converged, res.stop_reason
    assert np.linalg.norm(res.u - answer) <= 2 * (1e-7 + 1e-8)
    assert {"T", "O"} <= {h.submode for h in res.history}


def test_targeting_only_newton_case():
    """Reference: the root (2, 1) of T(U) = (u0² + u1², u0 u1) = (5, 2) (N = M: Newton with a line
    search).  Targeting only must converge in a few iterations (quadratically) to |ΔT_i| ≤ ε, i.e.
    |U − U*| ≤ ‖S⁻¹‖·√2·ε."""
    prob = make_problem(
        [1.5, 0.5],
        lambda u: np.array([u @ u, u[0] * u[1]]),
        lambda u: np.array([[2 * u[0], 2 * u[1]], [u[1], u[0]]]),
        lambda u: 0.0,
        lambda u: np.zeros(2),
        [5.0, 2.0],
        1e-10,
        **unit_weights(2),
    )
    res = projected_gradient(prob, SearchSettings(submode="target", weighting="control"))
    assert res.search_converged and "targeting only" in res.stop_reason
    assert len(res.history) <= 8
    Sinv = np.linalg.inv(np.array([[4.0, 2.0], [1.0, 2.0]]))
    assert np.linalg.norm(res.u - [2.0, 1.0]) <= np.linalg.norm(Sinv, 2) * math.sqrt(2) * 1e-10 * 1.01
    errs = [np.max(np.abs(h.tau)) for h in res.history]
    assert errs[-1] <= 1.0 and all(b < a for a, b in zip(errs, errs[1:]))


def test_no_targets_converges_on_gradient():
    """Reference: max −½‖U − a‖² with N = 0 is U = a; the N = 0 stop R|G̃| ≤ θ_conv ΔF_max with
    W = I bounds |U − a| by θ_conv·ΔF_max/R = 5e-6."""
    a = np.array([1.0, -2.0, 0.5])
    prob = make_problem(
        np.zeros(3),
        lambda u: np.zeros(0),
        lambda u: np.zeros((0, 3)),
        lambda u: -0.5 * float((u - a) @ (u - a)),
        lambda u: -(u - a),
        np.zeros(0),
        np.zeros(0),
        **unit_weights(3),
    )
    res = projected_gradient(prob, SearchSettings(convergence_angle_rad=1e-6, weighting="control"))
    assert res.search_converged and "no targets" in res.stop_reason, res.stop_reason
    assert np.linalg.norm(res.u - a) <= 5e-6
    assert math.isnan(res.history[0].angle_rad)


def test_more_targets_than_controls_is_least_squares():
    """Reference: N > M linear targets A U = b (inconsistent) end at the least-squares solution
    (numpy lstsq, 1e-9: one exact Gauss–Newton step), not converged (no optimization freedom)."""
    A = np.array([[1.0, 0.0], [0.0, 1.0], [1.0, 1.0]])
    b = np.array([1.0, 2.0, 4.0])
    prob = make_problem(
        np.zeros(2), lambda u: A @ u, lambda u: A, lambda u: 0.0, lambda u: np.zeros(2), b, 1e-3, **unit_weights(2)
    )
    s = SearchSettings(weighting="control", linearity_radius=100.0, max_iterations=20)
    res = projected_gradient(prob, s)
    np.testing.assert_allclose(res.u, np.linalg.lstsq(A, b, rcond=None)[0], atol=1e-9)
    assert not res.search_converged and "no decrease" in res.stop_reason


def test_bound_active_at_optimum_is_reported_dropped():
    """Reference: max −½‖U − a‖², a = (2, 0, 0), s.t. u0 + u1 + u2 = 1 and u0 ≤ 0.5.  The bound-free
    answer (5/3, −1/3, −1/3) violates u0 ≤ 0.5; the KKT point is (0.5, 0.25, 0.25) with the bound
    active.  Tolerance as for the projection problem (θ_conv = 1e-7, ε = 1e-8)."""
    prob = bound_problem(1e-8, labels=("x", "y", "z"))
    res = projected_gradient(prob, SearchSettings(weighting="control", convergence_angle_rad=1e-7))
    assert res.search_converged, res.stop_reason
    np.testing.assert_allclose(res.u, [0.5, 0.25, 0.25], atol=1e-6)
    assert 0 in res.history[-1].dropped
    assert res.u[0] <= 0.5


def test_sensitivity_weighting_makes_the_path_unit_invariant():
    """Reference: the same search with control 1 expressed in a unit 1000× smaller (u → 1000u,
    S and G columns /1000).  Under WEIGHT-1 the scaled problem is identical, so the iterate paths
    agree to rounding (1e-9 relative)."""
    T, Sf, F, Gf = _analytic()
    desired, tol = np.array([0.9, 0.4]), np.array([1e-3, 1e-3])
    c = np.array([1.0, 1000.0, 1.0, 1.0])

    def build(cv):
        return make_problem(
            np.array([0.5, 0.2, 0.1, 0.6]) * cv,
            lambda v: T(v / cv),
            lambda v: Sf(v / cv) / cv,
            lambda v: F(v / cv),
            lambda v: Gf(v / cv) / cv,
            desired,
            tol,
            scale=np.full(4, 100.0),
        )

    s = SearchSettings(max_iterations=12, max_performance_change=0.5)
    base = projected_gradient(build(np.ones(4)), s)
    scaled = projected_gradient(build(c), s)
    assert len(base.history) == len(scaled.history) > 3
    for h0, h1 in zip(base.history, scaled.history):
        np.testing.assert_allclose(h1.u / c, h0.u, rtol=1e-9, atol=1e-12)
        assert h0.submode == h1.submode


def test_given_smag_replaces_the_first_sensitivity_call():
    """Reference: the $SMAG contract: with given_S/given_G, iteration 1 calls evaluate (not
    sensitivities) and the search still reaches the projection answer."""
    log = []
    prob, answer, A = projection_problem(tol=1e-6, log=log, **unit_weights(4))
    prob.given_S, prob.given_G = A.copy(), np.array([0.8, -0.3, 0.4, 1.1])
    res = projected_gradient(prob, SearchSettings(weighting="control", convergence_angle_rad=1e-5))
    assert res.search_converged
    assert log[0][0] == "eval"
    assert res.n_sensitivity_evaluations == len(res.history) - 1


# ------------------------------------------------------------------------------ failure paths


def test_start_failure_returns_reason():
    """Reference: the contract: a failed starting trajectory stops at once, with that reason."""
    prob, _ = circle_problem(fails=lambda u: True)
    res = projected_gradient(prob)
    assert res.stop_reason == "trajectory failed at the starting controls"
    assert not res.search_converged and res.history == [] and not res.evaluation.ok


def test_wrong_gradient_gives_no_decrease_and_keeps_the_start():
    """Reference: a sign-flipped G (N = 0) makes every trial worse than F(0): GENMIN finds no
    decrease, the search stops with that reason and returns the start (never worse)."""
    a = np.array([1.0, 2.0])
    prob = make_problem(
        np.zeros(2),
        lambda u: np.zeros(0),
        lambda u: np.zeros((0, 2)),
        lambda u: -0.5 * float((u - a) @ (u - a)),
        lambda u: +(u - a),
        np.zeros(0),
        np.zeros(0),
    )
    res = projected_gradient(prob, SearchSettings(weighting="control"))
    assert res.stop_reason.startswith("line search found no decrease in 6 trials")
    np.testing.assert_array_equal(res.u, [0.0, 0.0])


def test_singular_sensitivity_reports_uncontrollable_target():
    """Reference: T = (u0 + u1, 0) with T0 = (1, 1): target 'b' has no control authority.  The
    search satisfies 'a', then stops with a singular-matrix reason naming 'b' (no exception)."""
    prob = make_problem(
        np.zeros(2),
        lambda u: np.array([u[0] + u[1], 0.0]),
        lambda u: np.array([[1.0, 1.0], [0.0, 0.0]]),
        lambda u: 0.0,
        lambda u: np.zeros(2),
        [1.0, 1.0],
        1e-3,
        target_labels=("a", "b"),
        **unit_weights(2),
    )
    res = projected_gradient(prob, SearchSettings(weighting="control"))
    assert res.stop_reason.startswith("sensitivity matrix singular")
    assert "'b'" in res.stop_reason and not res.search_converged
    assert abs(res.evaluation.targets[0] - 1.0) <= 1e-3


def test_failed_trials_shrink_gamma_and_search_still_converges():
    """Reference: the Newton system of test_targeting_only_newton_case (root (2, 1)) from (3, 0.2),
    with trajectories failing (P-A12) where u0 > 2.2 and u1 > 0.6.  The first full step lands there
    (at (2.29, 0.71)); GENMIN must shrink γ and the search still reach the root (1e-8: ε = 1e-10)."""
    prob = make_problem(
        [3.0, 0.2],
        lambda u: np.array([u @ u, u[0] * u[1]]),
        lambda u: np.array([[2 * u[0], 2 * u[1]], [u[1], u[0]]]),
        lambda u: 0.0,
        lambda u: np.zeros(2),
        [5.0, 2.0],
        1e-10,
        fails=lambda u: u[0] > 2.2 and u[1] > 0.6,
        **unit_weights(2),
    )
    res = projected_gradient(prob, SearchSettings(submode="target", weighting="control"))
    assert res.search_converged, res.stop_reason
    np.testing.assert_allclose(res.u, [2.0, 1.0], atol=1e-8)
    assert any(not t.ok for h in res.history for t in h.trials)


def test_malformed_inputs_raise_value_error():
    """Reference: the input contract: shape mismatch, tolerance ≤ 0, lower > upper, u0 outside its
    bounds (the message names the control) raise ValueError."""
    prob, _ = circle_problem(labels=("alpha", "beta"))
    for change, match in [
        ({"tolerance": np.array([0.0])}, "tolerance"),
        ({"tolerance": np.array([1.0, 1.0])}, "shape"),
        ({"lower": np.array([0.0, 1.0]), "upper": np.array([1.0, 0.0])}, "'beta'"),
        ({"lower": np.array([0.95, -1.0])}, "'alpha'"),
    ]:
        bad = make_like(prob, **change)
        with pytest.raises(ValueError, match=match):
            projected_gradient(bad)
    with pytest.raises(ValueError):
        SearchSettings(submode="grid")


def _with_gradient(sens, c):
    def wrapped(u):
        ev, S, _ = sens(u)
        return Evaluation(ev.targets, float(c @ u), ev.ok), S, c.copy()

    return wrapped


def _with_perf(evaluate, c):
    return lambda u: Evaluation(evaluate(u).targets, float(c @ u), True)


def make_like(prob, **change):
    from dataclasses import replace

    return replace(prob, **change)


def test_angle_target_error_wraps():
    """Reference: an angle target with T0 = π − 0.1 from θ = −π + 0.1: the wrapped error is +0.2 rad,
    so the search must move by −0.2 (to −π − 0.1 ≡ π − 0.1), not by +2π − 0.2 (P-A4)."""
    prob = make_problem(
        [-math.pi + 0.1],
        lambda u: np.array([u[0]]),
        lambda u: np.ones((1, 1)),
        lambda u: 0.0,
        lambda u: np.zeros(1),
        math.pi - 0.1,
        1e-9,
        **unit_weights(1),
    )
    prob.target_error = lambda T: (T - (math.pi - 0.1) + math.pi) % (2 * math.pi) - math.pi
    res = projected_gradient(prob, SearchSettings(submode="target", weighting="control"))
    assert res.search_converged
    assert res.u[0] == pytest.approx(-math.pi - 0.1, abs=1e-9)


def test_min_performance_gain_stops_optimization():
    """Reference: the min_performance_gain contract on max u1 + 2u2 on the unit circle (answer
    (1, 2)/√5): with θ_conv out of reach (1e-300) and a 1e-6 kg floor, the search stops on the
    predicted gain, near the answer (1e-2: a gain of 1e-6 kg allows a ~1e-3 offset)."""
    prob = make_problem(
        [0.9, 0.1],
        lambda u: np.array([u @ u]),
        lambda u: 2.0 * u[None, :],
        lambda u: float(u[0] + 2 * u[1]),
        lambda u: np.array([1.0, 2.0]),
        1.0,
        1e-8,
        **unit_weights(2),
    )
    answer = np.array([1.0, 2.0]) / math.sqrt(5)
    s = SearchSettings(
        weighting="control", max_performance_change=0.1, convergence_angle_rad=1e-300, min_performance_gain=1e-6
    )
    res = projected_gradient(prob, s)
    assert res.search_converged and "predicted performance gain" in res.stop_reason, res.stop_reason
    assert np.linalg.norm(res.u - answer) <= 1e-2


def test_evaluation_is_a_named_tuple():
    """Reference: the interface: Evaluation(targets, performance, ok) unpacks as a 3-tuple."""
    t, f, ok = Evaluation(np.zeros(1), 1.0, True)
    assert ok and f == 1.0


def test_optimality_angle_counts_active_bounds_and_switch_order_rows():
    """TEST's θ for the NLP answers (search.optimality_angle), against closed-form KKT points:
    the bound-active problem at (0.5, 0.25, 0.25): G = a − u = (1.5, −0.25, −0.25); u₀ at its
    bound leaves (−0.25, −0.25), parallel to S's free part (1, 1): θ = 0 (1e-12, rounding);
    at the feasible non-optimum (0.4, 0.3, 0.3) θ > 0.1.  The isotonic problem at its answer
    (1.5, 1.5, 1.5, 1.5): G = −2(u − c) = (3, −1, 1, −3) sums to zero, so it lies in the span of
    the three active switch-order rows: θ = 0 with them counted."""
    prob = _validated(bound_problem(1e-8))
    a = np.array([2.0, 0.0, 0.0])
    for u, small in ((np.array([0.5, 0.25, 0.25]), True), (np.array([0.4, 0.3, 0.3]), False)):
        theta = optimality_angle(prob, u, np.ones((1, 3)), a - u, "control")
        assert (theta < 1e-12) if small else (theta > 0.1), (u, theta)
    iso, c, A = isotonic_problem()
    iso = _validated(dataclasses.replace(iso, ineq_matrix=A, ineq_bound=np.zeros(3)))
    u = np.full(4, 1.5)
    assert optimality_angle(iso, u, np.zeros((0, 4)), -2.0 * (u - c), "control") < 1e-12
