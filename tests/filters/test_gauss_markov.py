"""The exact Gauss-Markov piece transition and noise (fracas.filters.gauss_markov) against
independent references written here:

- the product-integration weights against scipy's adaptive quadrature of the same
  integrals (split at the kernel's kink);
- a gravity-free (straight-line) arc against Van Loan's closed form: the matrix
  exponential of [[-F, G Qc G^T], [0, F^T]] L gives the augmented transition and noise
  exactly (Van Loan 1978, IEEE TAC 23(3) 395);
- a time-varying case (harmonic-oscillator A, h varying in time) against a scipy DOP853
  integration of Psi' = F Psi, Q' = F Q + Q F^T + Qc at rtol 1e-12.

Tolerances: the weights are exact to round-off (1e-12 absolute on O(1) values); the
closed-form cases are exact for G of degree < 8, so round-off bounds them (1e-10 relative,
1e-9 over 4 days, where the Van Loan matrix's entries span 1e-16 to 1 and expm's round-off
is ~3e-10);
the time-varying case is limited by the interpolation of G on a piece of omega L = 0.5
(~1e-9) and by the ODE's rtol (1e-12): 1e-8.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import quad, solve_ivp
from scipy.linalg import expm

from fracas.filters.gauss_markov import GM_NODES, compose, piece_nodes, piece_noise, product_weights


def _lagrange_fn(j, n=GM_NODES):
    x = 0.5 * (np.polynomial.legendre.leggauss(n)[0] + 1.0)

    def ell(t):
        out = 1.0
        for m in range(n):
            if m != j:
                out *= (t - x[m]) / (x[j] - x[m])
        return out

    return ell


@pytest.mark.parametrize("beta", [0.0, 0.3, 1.0, 4.0])
def test_product_weights_against_scipy_quad(beta):
    u, v, W = product_weights(np.array(beta))
    for j in (0, 3, 7):
        lj = _lagrange_fn(j)
        uj = quad(lambda x, lj=lj: lj(x) * np.exp(-beta * x), 0, 1, epsabs=1e-14, epsrel=1e-13)[0]
        vj = quad(lambda x, lj=lj: lj(x) * (np.exp(-beta * (1 - x)) - np.exp(-beta * (1 + x))), 0, 1, epsabs=1e-14)[0]
        assert abs(u[j] - uj) < 1e-12
        assert abs(v[j] - vj) < 1e-12
        for k in (0, 5):
            lk = _lagrange_fn(k)

            def inner(x, lk=lk):
                f = lambda y: lk(y) * (np.exp(-beta * abs(x - y)) - np.exp(-beta * (x + y)))  # noqa: E731
                return quad(f, 0, 1, points=[x], epsabs=1e-14, epsrel=1e-13)[0]

            wjk = quad(lambda x, lj=lj, inner=inner: lj(x) * inner(x), 0, 1, epsabs=1e-13, epsrel=1e-12)[0]
            assert abs(W[j, k] - wjk) < 1e-11, (j, k, W[j, k], wjk)


def _van_loan(F, GQG, L):
    n = F.shape[0]
    M = np.zeros((2 * n, 2 * n))
    M[:n, :n] = -F
    M[:n, n:] = GQG
    M[n:, n:] = F.T
    B = expm(M * L)
    psi = B[n:, n:].T
    return psi, psi @ B[:n, n:]


def _straight_line_case():
    rng = np.random.default_rng(4)
    h = np.zeros((6, 3))
    h[3:6] = rng.normal(size=(3, 3)) * 1e-7  # km/s^2 per unit of eta
    sigma = np.array([0.01, 0.0087, 0.005])
    tau = np.array([0.5, 0.25, 1.0]) * 86400.0
    A = np.zeros((6, 6))
    A[:3, 3:] = np.eye(3)
    F = np.zeros((9, 9))
    F[:6, :6] = A
    F[:6, 6:] = h
    F[6:, 6:] = -np.diag(1.0 / tau)
    GQG = np.zeros((9, 9))
    GQG[6:, 6:] = np.diag(2.0 * sigma**2 / tau)
    return h, sigma, tau, F, GQG


def _straight_line_pieces(h, edges):
    s, L = piece_nodes(edges[:-1], edges[1:])
    m = len(L)
    G = np.zeros((m, GM_NODES, 6, 3))
    phi = np.zeros((m, 6, 6))
    for p in range(m):
        b = edges[p + 1]
        for j in range(GM_NODES):
            ph = np.eye(6)
            ph[:3, 3:] = (b - s[p, j]) * np.eye(3)
            G[p, j] = ph @ h
        phi[p] = np.eye(6)
        phi[p][:3, 3:] = L[p] * np.eye(3)
    return phi, G, L


@pytest.mark.parametrize("days", [0.05, 0.5, 2.0])
def test_one_piece_against_van_loan(days):
    h, sigma, tau, F, GQG = _straight_line_case()
    L = days * 86400.0
    psi, Q = _van_loan(F, GQG, L)
    phi, G, Ls = _straight_line_pieces(h, np.array([0.0, L]))
    gamma, E, Qp = piece_noise(G, Ls, sigma, tau)
    assert np.allclose(gamma[0], psi[:6, 6:], rtol=1e-10, atol=1e-12 * np.abs(psi[:6, 6:]).max())
    assert np.allclose(E[0], np.diag(psi[6:, 6:]), rtol=1e-13)
    scale = np.sqrt(np.outer(np.diag(Q), np.diag(Q)))
    assert np.max(np.abs(Qp[0] - Q) / scale) < 1e-10


def test_composed_pieces_against_van_loan():
    """Unequal pieces (as events cut them) chained by compose = one closed form over the span."""
    h, sigma, tau, F, GQG = _straight_line_case()
    edges = np.array([0.0, 0.1, 0.37, 1.0, 1.05, 2.5, 4.0]) * 86400.0
    psi, Q = _van_loan(F, GQG, edges[-1])
    phi, G, L = _straight_line_pieces(h, edges)
    P, Gm, Em, Qm = compose(phi, *piece_noise(G, L, sigma, tau))
    assert np.allclose(P, psi[:6, :6], rtol=1e-13, atol=1e-13)
    assert np.max(np.abs(Gm - psi[:6, 6:])) < 1e-10 * np.abs(psi[:6, 6:]).max()
    scale = np.sqrt(np.outer(np.diag(Q), np.diag(Q)))
    assert np.max(np.abs(Qm - Q) / scale) < 1e-9  # expm of a 4-day Van Loan matrix: ~3e-10 round-off


def test_infinite_tau_is_a_random_constant():
    """tau = inf: E = 1, no noise, Gamma = int G (a bias), against the closed form."""
    h, sigma, tau, F, GQG = _straight_line_case()
    tau = np.array([np.inf, tau[1], tau[2]])
    L = 86400.0
    phi, G, Ls = _straight_line_pieces(h, np.array([0.0, L]))
    gamma, E, Q = piece_noise(G, Ls, sigma, tau)
    assert E[0, 0] == 1.0 and Q[0, 6, 6] == 0.0 and np.all(Q[0, :6, 6] == 0.0)
    expect = np.zeros(6)
    expect[:3] = 0.5 * L**2 * h[3:6, 0]
    expect[3:] = L * h[3:6, 0]
    assert np.allclose(gamma[0, :, 0], expect, rtol=1e-12)


def test_time_varying_against_scipy_ode():
    """A = harmonic oscillator (omega^2 = mu / r^3 of a 7000 km orbit), h(t) rotating with
    it: pieces of omega L = 0.5 against the augmented covariance equation."""
    om = np.sqrt(398600.4418 / 7000.0**3)
    sigma = np.array([0.01, 0.0087, 0.005])
    tau = np.array([600.0, 300.0, 3000.0])

    def A(t):
        a = np.zeros((6, 6))
        a[:3, 3:] = np.eye(3)
        a[3:, :3] = -(om**2) * np.eye(3)
        return a

    def h(t):
        out = np.zeros((6, 3))
        c, s = np.cos(om * t), np.sin(om * t)
        out[3:6] = 1e-6 * np.array([[c, -s, 0.2], [s, c, 0.1 * c], [0.0, 0.3, 1.0]])
        return out

    def F(t):
        f = np.zeros((9, 9))
        f[:6, :6] = A(t)
        f[:6, 6:] = h(t)
        f[6:, 6:] = -np.diag(1.0 / tau)
        return f

    GQG = np.zeros((9, 9))
    GQG[6:, 6:] = np.diag(2.0 * sigma**2 / tau)
    T = 2 * np.pi / om

    def rhs(t, y):
        psi, Q = y[:81].reshape(9, 9), y[81:].reshape(9, 9)
        f = F(t)
        return np.concatenate([(f @ psi).ravel(), (f @ Q + Q @ f.T + GQG).ravel()])

    y0 = np.concatenate([np.eye(9).ravel(), np.zeros(81)])
    sol = solve_ivp(rhs, (0, T), y0, method="DOP853", rtol=1e-12, atol=1e-20)
    psi, Q = sol.y[:81, -1].reshape(9, 9), sol.y[81:, -1].reshape(9, 9)

    m = int(np.ceil(om * T / 0.5))
    edges = np.linspace(0.0, T, m + 1)
    s, L = piece_nodes(edges[:-1], edges[1:])

    def phi_oscillator(dt):
        c, sn = np.cos(om * dt), np.sin(om * dt)
        out = np.zeros((6, 6))
        out[:3, :3] = c * np.eye(3)
        out[:3, 3:] = sn / om * np.eye(3)
        out[3:, :3] = -om * sn * np.eye(3)
        out[3:, 3:] = c * np.eye(3)
        return out

    G = np.array([[phi_oscillator(edges[p + 1] - s[p, j]) @ h(s[p, j]) for j in range(GM_NODES)] for p in range(m)])
    phi = np.array([phi_oscillator(Lp) for Lp in L])
    P, Gm, Em, Qm = compose(phi, *piece_noise(G, L, sigma, tau))
    assert np.allclose(P, psi[:6, :6], atol=1e-9)
    assert np.max(np.abs(Gm - psi[:6, 6:])) < 1e-8 * np.abs(psi[:6, 6:]).max()
    scale = np.sqrt(np.outer(np.diag(Q), np.diag(Q)))
    assert np.max(np.abs(Qm - Q) / scale) < 1e-8
