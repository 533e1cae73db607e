"""Gauss-Markov thrust process noise (fracas.filters.process_noise): PDOT against matrix
exponentials and closed-form covariances, DYNO's semi-empirical Qtilde against a brute-force
double integral (FRACAS DYNO eqs. 1-7, DERY; App. 9.3 eqs. 3, 5, 7).

The 1-D reference system is DYNO's setting in one axis: a double integrator (x, v) driven by
a Gauss-Markov acceleration eta with h = 1, eta stationary (var sigma^2, time constant tau),
x(0) = v(0) = 0.  With t the elapsed time, E = exp(-t/tau), and
E[eta(s1) eta(s2)] = sigma^2 exp(-|s1 - s2|/tau), the covariance at t is (derived by direct
integration of v = int_0^t eta, x = int_0^t (t - s) eta):

    var(v)     = 2 sigma^2 [tau t - tau^2 (1 - E)]
    cov(x, v)  = sigma^2 [tau t^2 - tau^2 t (1 - E)]
    var(x)     = sigma^2 [2/3 tau t^3 - tau^2 t^2 + 2 tau^4 (1 - E) - 2 tau^3 t E]
    cov(v, eta) = sigma^2 tau (1 - E),  cov(x, eta) = sigma^2 tau^2 [1 - E (1 + t/tau)],
    var(eta)   = sigma^2.

Checks of the limits: tau -> inf gives the bias case x = eta t^2/2, v = eta t
(var(x) -> sigma^2 t^4/4, cov -> sigma^2 t^3/2, var(v) -> sigma^2 t^2); t >> tau gives white
noise of density 2 sigma^2 tau (var(v) -> 2 sigma^2 tau t, var(x) -> 2/3 sigma^2 tau t^3).
The (x, v) block is also the exact Qtilde of App. 9.3 (eta independent of the state), which
the brute-force quadrature below confirms to 1e-11 (1e-14 away from
the cancellation at small t/tau).
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg

from fracas.filters.process_noise import (
    covariance_derivative,
    dyno_q,
    effective_bias_sigma,
    gm_augmented_F,
    gm_decay,
    gm_Qc,
    pdot_propagate,
)

DAY = 86400.0
TAU = DAY  # 1-day correlation time, as in App. 9.3's PHI study
SIG = 1.0e-9  # km/s^2: 0.2 % of a 5e-7 km/s^2 SEP acceleration
N_STEPS = 100  # one grid size for every PDOT case below: one compilation


def exact_gm_double_integrator(t, tau, sigma):
    """Closed-form covariance (3, 3) of (x, v, eta) at t (module docstring)."""
    s2 = sigma * sigma
    e = np.exp(-t / tau)
    om = -np.expm1(-t / tau)  # 1 - E without cancellation at small t/tau
    vv = 2.0 * s2 * (tau * t - tau**2 * om)
    xv = s2 * (tau * t**2 - tau**2 * t * om)
    xx = s2 * (2.0 / 3.0 * tau * t**3 - tau**2 * t**2 + 2.0 * tau**4 * om - 2.0 * tau**3 * t * e)
    ve = s2 * tau * om
    xe = s2 * tau**2 * (om - (t / tau) * e)
    return np.array([[xx, xv, xe], [xv, vv, ve], [xe, ve, s2]])


def brute_force_qtilde(t, tau, sigma):
    """App. 9.3's Qtilde = int_0^t int_0^t Phi(t,s1) h E[eta(s1) eta(s2)] h^T Phi(t,s2)^T ds1 ds2
    for the double integrator (Phi(t,s) h = (t - s, 1)), by Gauss-Legendre quadrature.

    The integrand is symmetric under (s1, s2) -> (s2, s1) with a transpose, so
    Qtilde = T + T^T, T = int_0^t dd int_d^t ds1 f(s1, s1 - d) over the lag d = s1 - s2 >= 0;
    the kernel exp(-d/tau) is smooth there (the |s1 - s2| kink is on the boundary).  Lag
    panels of width <= tau/4 with 8 nodes (error ~ (1/8)^16/16! ~ 0 for the exponential),
    6 nodes in s1 (exact: the integrand is a polynomial of degree 2 in s1)."""
    xg, wg = np.polynomial.legendre.leggauss(8)
    npan = int(np.ceil(t / (tau / 4.0)))
    edges = np.linspace(0.0, t, npan + 1)
    a, b = edges[:-1, None], edges[1:, None]
    d = (0.5 * (b - a) * xg + 0.5 * (a + b)).ravel()
    wd = (0.5 * (b - a) * wg).ravel()
    xi, wi = np.polynomial.legendre.leggauss(6)
    s1 = 0.5 * (t - d)[:, None] * xi + 0.5 * (t + d)[:, None]
    w1 = 0.5 * (t - d)[:, None] * wi
    s2 = s1 - d[:, None]
    g1 = np.stack([t - s1, np.ones_like(s1)], -1)  # Phi(t, s1) h
    g2 = np.stack([t - s2, np.ones_like(s2)], -1)
    w = wd[:, None] * w1 * (sigma * sigma) * np.exp(-d / tau)[:, None]
    T = np.einsum("ij,ija,ijb->ab", w, g1, g2)
    return T + T.T


def _double_integrator_F(tau):
    A = np.array([[0.0, 1.0], [0.0, 0.0]])
    h = np.array([[0.0], [1.0]])
    return np.asarray(gm_augmented_F(A, np.zeros((2, 0)), h, np.array([tau])))


# ------------------------------------------------------------------------------ PDOT
def test_pdot_without_noise_is_expm_congruence_at_fourth_order():
    """Qc = 0, constant F (augmented from random A, B, h, tau; seeded): RK4 PDOT equals
    expm(F dt) P0 expm(F dt)^T, and the error falls by ~16 per grid halving.

    ||F|| dt = 2 over N = 8..64 steps: measured relative errors 1.6e-5, 8.3e-7, 4.7e-8,
    2.8e-9 (ratios 19.7, 17.8, 16.9 -> 16 as the step shrinks).  Bounds: each ratio in
    [14, 24] (4th order, still pre-asymptotic at N = 8; a 3rd-order scheme gives 8, a
    5th-order one 32); the N = 64 error < 1e-8 (the N = 32 error / 16 is 2.9e-9).
    """
    rng = np.random.default_rng(20240611)
    nx, npar, k = 4, 2, 2
    A = rng.standard_normal((nx, nx))
    B = rng.standard_normal((nx, npar))
    h = rng.standard_normal((nx, k))
    tau = np.array([0.7, 2.5])
    c = np.linalg.norm(np.asarray(gm_augmented_F(A, B, h, tau)), 2)
    F = np.asarray(gm_augmented_F(A / c, B / c, h / c, tau * c))  # ||F||_2 = 1 (1/s)
    n = nx + npar + k
    assert F.shape == (n, n)
    # augmented layout (DERY / App. 9.3): parameter rows zero, eta block -diag(1/tau)
    assert np.all(F[nx : nx + npar] == 0.0) and np.all(F[nx + npar :, : nx + npar] == 0.0)
    np.testing.assert_allclose(np.diag(F[nx + npar :, nx + npar :]), -1.0 / (tau * c), rtol=1e-15)
    # batched nodes broadcast (h per node, A and B shared)
    Fb = np.asarray(gm_augmented_F(A / c, B / c, np.stack([h / c] * 3), tau * c))
    assert Fb.shape == (3, n, n) and np.array_equal(Fb[2], F)
    T = 2.0
    L = rng.standard_normal((n, n))
    P0 = L @ L.T / n + np.eye(n)
    E = scipy.linalg.expm(F * T)
    ref = E @ P0 @ E.T
    errs = []
    for N in (8, 16, 32, 64):
        P = np.asarray(pdot_propagate(P0, np.broadcast_to(F, (2 * N + 1, n, n)), np.zeros((n, n)), T / N))
        assert np.array_equal(P, P.T)  # symmetrised every step
        errs.append(np.abs(P - ref).max() / np.abs(ref).max())
    ratios = np.array(errs[:-1]) / np.array(errs[1:])
    assert np.all((ratios > 14.0) & (ratios < 24.0)), (errs, ratios)
    assert errs[-1] < 1e-8, errs


@pytest.mark.parametrize("ratio", [0.1, 1.0, 10.0])
def test_pdot_gauss_markov_double_integrator_matches_closed_form(ratio):
    """(x, v, eta) with constant h = 1, Qc = gm_Qc (2 sigma^2/tau), stationary start
    P0 = diag(0, 0, sigma^2): PDOT equals the closed-form covariance (module docstring) at
    dt/tau = 0.1, 1, 10.

    100 RK4 steps, so h/tau <= 0.1.  Only the decaying mode exp(-t/tau) is not integrated
    exactly (RK4 is exact on the polynomial integrator modes); its local error
    (h/tau)^5/120 bounds the result by ~1e-5 at dt/tau = 10, but it reaches (x, v) only
    through their integrals and the measured errors are 2.4e-10, 9.5e-10, 1.0e-10 (relative
    to sqrt(P_ii P_jj), correlation units).  Tolerance 1e-8: 10x the measured worst case,
    far below the O(1) errors a wrong Qc, sign or ordering gives.
    var(eta) must stay sigma^2: the 2 sigma^2 / tau density exactly balances the decay."""
    t = ratio * TAU
    F = _double_integrator_F(TAU)
    Qc = np.asarray(gm_Qc(np.array([SIG]), np.array([TAU]), 2, 0))
    np.testing.assert_allclose(Qc[2, 2], 2.0 * SIG**2 / TAU, rtol=1e-15)
    P0 = np.diag([0.0, 0.0, SIG**2])
    P = np.asarray(pdot_propagate(P0, np.broadcast_to(F, (2 * N_STEPS + 1, 3, 3)), Qc, t / N_STEPS))
    ref = exact_gm_double_integrator(t, TAU, SIG)
    d = np.sqrt(np.diag(ref))
    err = np.abs(P - ref) / np.outer(d, d)
    assert err.max() < 1e-8, err
    np.testing.assert_allclose(P[2, 2], SIG**2, rtol=1e-12)


def test_pdot_noise_state_relaxes_with_gm_decay():
    """eta alone from var 0: var(eta)(t) = sigma^2 (1 - exp(-2 t/tau)) = sigma^2 (1 - gm_decay^2),
    with Qc passed per node (constant, as (2N+1, 1, 1)).  t = 3 tau over 100 steps: RK4's
    relative error on exp(-2t/tau) = e^-6 is ~ N (2h/tau)^5/120 = 7e-7, i.e. 1.6e-9 of the
    result (measured 1.7e-9); tolerance 1e-8."""
    t = 3.0 * TAU
    F = np.asarray(gm_augmented_F(np.zeros((0, 0)), np.zeros((0, 0)), np.zeros((0, 1)), np.array([TAU])))
    Qc = np.asarray(gm_Qc(np.array([SIG]), np.array([TAU]), 0, 0))
    nodes = 2 * N_STEPS + 1
    P = np.asarray(
        pdot_propagate(
            np.zeros((1, 1)), np.broadcast_to(F, (nodes, 1, 1)), np.broadcast_to(Qc, (nodes, 1, 1)), t / N_STEPS
        )
    )
    g = float(gm_decay(TAU, t))
    assert g == pytest.approx(np.exp(-3.0), rel=1e-15)
    assert P[0, 0] == pytest.approx(SIG**2 * (1.0 - g * g), rel=1e-8)


def test_covariance_derivative_is_lyapunov_form():
    """Pdot = F P + P F^T + Qc against the element-wise sums (seeded random 3x3)."""
    rng = np.random.default_rng(7)
    F, P, Q = (rng.standard_normal((3, 3)) for _ in range(3))
    ref = np.einsum("ik,kj->ij", F, P) + np.einsum("ik,jk->ij", P, F) + Q
    np.testing.assert_allclose(np.asarray(covariance_derivative(P, F, Q)), ref, rtol=1e-14, atol=1e-14)


# ------------------------------------------------------------------------------ DYNO
# DYNO / exact for the double integrator (sigma, tau arbitrary: the ratios depend on dt/tau
# only), measured with the functions below; exact = brute-force quadrature = closed form.
#   dt/tau:     0.1       0.5       1         2         10        50
#   var(x):     20.5364   4.54831   2.56215   1.58647   0.879251  0.773177
#   cov(x,v):   10.3361   2.34674   1.35914   0.880797  0.555553  0.510204
#   var(v):     5.16805   1.17337   0.679570  1.32120   0.833329  0.765306
# DYNO is pessimistic for dt < tau (the bias-like growth t^2 is replaced by tau t / 2) and
# optimistic by 25 % in velocity for dt >> tau (1.5 tau dt vs 2 tau dt), as App. 9.3
# reports ("pessimistic early, optimistic later"); alpha's switch at dt = tau makes the
# ratio jump (0.68 -> 1.32 between dt/tau = 1 and 2).
DYNO_RATIOS = {
    0.1: (20.5364, 10.3361, 5.16805),
    0.5: (4.54831, 2.34674, 1.17337),
    1.0: (2.56215, 1.35914, 0.679570),
    2.0: (1.58647, 0.880797, 1.32120),
    10.0: (0.879251, 0.555553, 0.833329),
    50.0: (0.773177, 0.510204, 0.765306),
}


def _dyno_1d(t, tau, sigma):
    phi = np.array([[1.0, t], [0.0, 1.0]])
    h = np.array([[0.0], [1.0]])
    return np.asarray(dyno_q(phi, h, h, np.array([sigma]), np.array([tau]), t))


@pytest.mark.parametrize("ratio", sorted(DYNO_RATIOS))
def test_dyno_against_brute_force_double_integral(ratio):
    """Quadrature of App. 9.3's Qtilde = closed form to 1e-11 (both exact up to roundoff,
    but var(x)'s closed form cancels terms 4 (tau/dt)^2 = 400 times its size at dt/tau = 0.1:
    measured 1.2e-12 there, <= 3e-15 elsewhere), then DYNO/exact equals the ratios above to
    1e-5 relative (they are stored to 6 digits)."""
    t = ratio * TAU
    exact = brute_force_qtilde(t, TAU, SIG)
    closed = exact_gm_double_integrator(t, TAU, SIG)[:2, :2]
    np.testing.assert_allclose(exact, closed, rtol=1e-11)
    q = _dyno_1d(t, TAU, SIG)
    got = (q[0, 0] / exact[0, 0], q[0, 1] / exact[0, 1], q[1, 1] / exact[1, 1])
    np.testing.assert_allclose(got, DYNO_RATIOS[ratio], rtol=1e-5)


def test_dyno_formula_values():
    """Eqs. 1-7 by hand: Qtilde = (tau dt/2) [alpha H + Phi H Phi^T], H = diag(0, sigma^2),
    Phi H Phi^T = sigma^2 [[dt^2, dt], [dt, 1]]; alpha = 0 at dt = tau (dt <= tau), 2 at
    dt = 2 tau.  Exact arithmetic up to roundoff: rtol 1e-14."""
    s2 = SIG**2
    for t, alpha in ((TAU, 0.0), (2.0 * TAU, 2.0), (0.5 * TAU, 0.0)):
        r = 0.5 * TAU * t
        ref = r * np.array([[t * t * s2, t * s2], [t * s2, (1.0 + alpha) * s2]])
        np.testing.assert_allclose(_dyno_1d(t, TAU, SIG), ref, rtol=1e-14)


def test_dyno_long_interval_limit():
    """dt >> tau: exact var(v) -> 2 sigma^2 tau dt (white noise), DYNO -> (tau dt/2)(2 + 1)
    sigma^2, so the ratio -> 3/4; likewise cov(x,v) -> 1/2 and var(x) -> 3/4.  At dt/tau =
    1e4 the finite-dt correction is x/(x - 1) - 1 = 1e-4 relative (closed form used here:
    the quadrature would need 4e4 panels); tolerance 2e-4."""
    t = 1.0e4 * TAU
    q = _dyno_1d(t, TAU, SIG)
    ex = exact_gm_double_integrator(t, TAU, SIG)
    assert q[1, 1] == pytest.approx(1.5 * TAU * t * SIG**2, rel=1e-14)
    assert ex[1, 1] == pytest.approx(2.0 * TAU * t * SIG**2, rel=2e-4)
    np.testing.assert_allclose(
        [q[0, 0] / ex[0, 0], q[0, 1] / ex[0, 1], q[1, 1] / ex[1, 1]], [0.75, 0.5, 0.75], rtol=2e-4
    )


def test_dyno_sums_components_with_their_own_tau():
    """Three axes (nx = 6: r, v; h = [0; I3]) with tau = (0.5, 1, 4) dt, i.e. alpha = 2 on the
    first axis only: Qtilde is block-diagonal per axis, each block the 1-D DYNO of that
    axis's (sigma, tau); a 7th (mass) row of h contributes its own row/column.  Exact
    bookkeeping: rtol 1e-14."""
    dt = 2.0 * DAY
    sig = np.array([1.0e-9, 2.0e-9, 3.0e-9])
    tau = np.array([0.5, 1.0, 4.0]) * dt
    phi = np.block([[np.eye(3), dt * np.eye(3)], [np.zeros((3, 3)), np.eye(3)]])
    h = np.vstack([np.zeros((3, 3)), np.eye(3)])
    q = np.asarray(dyno_q(phi, h, h, sig, tau, dt))
    for i in range(3):
        qi = _dyno_1d(dt, tau[i], sig[i])
        idx = [i, 3 + i]
        np.testing.assert_allclose(q[np.ix_(idx, idx)], qi, rtol=1e-14)
        others = [j for j in range(6) if j not in idx]
        assert np.all(q[np.ix_(idx, others)] == 0.0)
    # mass row (proportionality noise also changes mdot): h7 = [h; mdot_eta], phi7 = diag(phi, 1)
    mrow = np.array([[2.0e-5, 0.0, 0.0]])
    h7 = np.vstack([h, mrow])
    phi7 = np.eye(7)
    phi7[:6, :6] = phi
    q7 = np.asarray(dyno_q(phi7, h7, h7, sig, tau, dt))
    np.testing.assert_allclose(q7[:6, :6], q, rtol=1e-14)
    r0, a0 = 0.5 * tau[0] * dt, 2.0  # axis 0: dt > tau
    np.testing.assert_allclose(q7[6, 6], r0 * (a0 + 1.0) * sig[0] ** 2 * mrow[0, 0] ** 2, rtol=1e-14)


def test_effective_bias_sigma():
    """App. 9.3 eq. 5, sigma_bias = (0.30 + 0.05 tau[days]) sigma_noise: 0.35 at tau = 1 day,
    0.80 at 10 days (the Mercury study's Tables 1.B-1.C correlation times).  Exact."""
    np.testing.assert_allclose(float(effective_bias_sigma(0.02, 1.0)), 0.35 * 0.02, rtol=1e-15)
    np.testing.assert_allclose(np.asarray(effective_bias_sigma(np.array([1.0, 2.0]), 10.0)), [0.8, 1.6], rtol=1e-15)
