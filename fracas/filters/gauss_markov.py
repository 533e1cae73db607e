"""Exact first-order Gauss-Markov thrust noise for PHI mode (issue 24; replaces FRACAS DYNO's
effective Q̃ as the default, App. 9.3).

The thrust errors eta (k components) obey eta_i' = -eta_i / tau_i + q_i with
E[q_i(t) q_i(s)] = (2 sigma_i^2 / tau_i) delta(t - s) (App. 9.3 eq. 3) and enter the
motion as delta xdot = A dx + h(t) eta.  With eta carried as augmented states, the exact
transition of z = [x, eta] over a piece [a, b] (L = b - a) is

    Psi(b, a) = [[Phi(b, a), Gamma], [0, E]],   E = diag(exp(-L / tau_i)),
    Gamma[:, i] = int_a^b G(s)[:, i] exp(-(s - a) / tau_i) ds,   G(s) = Phi(b, s) h(s),

and the exact discrete noise added over the piece (the covariance of the part of z(b)
driven by q on [a, b]) is

    Q_ee = diag(sigma_i^2 (1 - exp(-2 L / tau_i))),
    Q_xe[:, i] = sigma_i^2 int G(s)[:, i] (exp(-(b - s)/tau_i) - exp(-(b + s - 2a)/tau_i)) ds,
    Q_xx = sum_i sigma_i^2 int int G(s1)[:, i] G(s2)[:, i]^T
                 (exp(-|s1 - s2|/tau_i) - exp(-(s1 + s2 - 2a)/tau_i)) ds1 ds2,

the last bracket being the covariance of the q-driven part of eta at s1 and s2.  These are
*product integrals*: G is smooth on the dynamics' time scale (a piece is short against the
orbital period), the exponential kernel is not (tau can be much shorter, and the kernel
has a kink at s1 = s2).  So G is represented by its values at n Gauss-Legendre nodes of
the piece (the Lagrange interpolant, exact for G polynomial of degree n - 1) and the kernel
is integrated against the Lagrange basis exactly (:func:`product_weights`: the kink is
handled by splitting the square into its two triangles, each integrated by a tensor Gauss
rule of :data:`KERNEL_QUAD` points, exact to round-off for beta = L / tau <= 4).  The
result is exact for a G of degree n - 1 whatever tau is; the pieces compose exactly
(:func:`compose`), so the answer does not depend on where the events fall.

Tested against the gravity-free closed form (Van Loan's matrix exponential) and a scipy
integration of the augmented covariance equation (tests/filters/test_gauss_markov.py,
tests/team/test_gauss_markov_exact.py).  Pure numpy: the inputs (Phi and h at the nodes)
come from one integration of the reference; nothing here is compiled.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

__all__ = ["GM_NODES", "KERNEL_QUAD", "piece_nodes", "product_weights", "piece_noise", "compose"]

#: Gauss-Legendre nodes per piece at which G = Phi(b, s) h(s) is sampled (interpolant of
#: degree 7: on a piece of omega L <= 1 rad the interpolation error is ~ (1/4)^8 / 8! ~ 4e-10).
GM_NODES = 8
#: Gauss points per dimension of the kernel integrals (each triangle of the square):
#: exp(-beta x) times a degree-14 polynomial, beta <= 4, to ~1e-15.
KERNEL_QUAD = 24


def piece_nodes(a, b, n: int = GM_NODES) -> tuple[np.ndarray, np.ndarray]:
    """The n Gauss-Legendre nodes (m, n) of each piece [a, b] (s; a, b (m,))."""
    x, _ = np.polynomial.legendre.leggauss(n)
    a = np.atleast_1d(np.asarray(a, np.float64))[:, None]
    b = np.atleast_1d(np.asarray(b, np.float64))[:, None]
    return a + (b - a) * 0.5 * (x[None, :] + 1.0), (b - a)[:, 0]


@lru_cache(maxsize=8)
def _basis(n: int, nq: int):
    """Unit-interval Gauss nodes x (n,), quadrature points and weights (nq,), and the
    Lagrange basis of x at the quadrature points, ell (nq, n)."""
    xl, _ = np.polynomial.legendre.leggauss(n)
    xq, wq = np.polynomial.legendre.leggauss(nq)
    x, xq, wq = 0.5 * (xl + 1.0), 0.5 * (xq + 1.0), 0.5 * wq
    return x, xq, wq


def _lagrange(x: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """ell_j(pts) (len(pts), n) of the Lagrange basis on nodes x (n,)."""
    d = pts[:, None] - x[None, :]  # (p, n)
    n = len(x)
    out = np.ones((len(pts), n))
    for j in range(n):
        for m in range(n):
            if m != j:
                out[:, j] *= d[:, m] / (x[j] - x[m])
    return out


@lru_cache(maxsize=4096)
def _weights_one(beta: float, n: int, nq: int):
    x, xq, wq = _basis(n, nq)
    lq = _lagrange(x, xq)  # (nq, n)
    # u_j = int_0^1 ell_j(x) e^{-beta x} dx ; v_j = int ell_j(x) (e^{-beta (1-x)} - e^{-beta (1+x)}) dx
    u = (wq * np.exp(-beta * xq)) @ lq
    v = (wq * (np.exp(-beta * (1.0 - xq)) - np.exp(-beta * (1.0 + xq)))) @ lq
    # T_jk = int_0^1 int_0^x ell_j(x) ell_k(y) e^{-beta (x - y)} dy dx  (y = x t, t in [0, 1])
    X = xq[:, None]
    Y = xq[:, None] * xq[None, :]  # (p, q)
    wxy = wq[:, None] * xq[:, None] * wq[None, :]
    ker = wxy * np.exp(-beta * (X - Y))
    ly = _lagrange(x, Y.ravel()).reshape(nq, nq, n)
    T = np.einsum("pj,pq,pqk->jk", lq, ker, ly)
    W = T + T.T - np.outer(u, u)
    return u, v, W


def product_weights(beta: np.ndarray, n: int = GM_NODES, nq: int = KERNEL_QUAD):
    """Product-integration weights of the Lagrange basis on the n Gauss nodes of [0, 1] for
    the kernels of a Gauss-Markov process with beta = L / tau (any shape; 0 for tau = inf):
    u (..., n) = int ell_j(x) e^{-beta x}, v (..., n) = int ell_j(x) (e^{-beta (1 - x)} -
    e^{-beta (1 + x)}), W (..., n, n) = int int ell_j(x) ell_k(y) (e^{-beta |x - y|} -
    e^{-beta (x + y)}) dx dy.  Cached per distinct beta (pieces of equal length share them)."""
    beta = np.asarray(beta, np.float64)
    flat = beta.ravel()
    uniq, inv = np.unique(flat, return_inverse=True)
    got = [_weights_one(float(b), n, nq) for b in uniq]
    u = np.array([g[0] for g in got])[inv].reshape(beta.shape + (n,))
    v = np.array([g[1] for g in got])[inv].reshape(beta.shape + (n,))
    W = np.array([g[2] for g in got])[inv].reshape(beta.shape + (n, n))
    return u, v, W


def piece_noise(G: np.ndarray, L: np.ndarray, sigma, tau_s):
    """Gamma (m, nx, k), E (m, k) and Q (m, nx + k, nx + k) of m pieces (module docstring).

    G (m, n, nx, k): Phi(b, s_j) h(s_j) at the n Gauss nodes s_j of each piece (xdot units
    per unit of eta, times the transition: km/s per unit, km/s^2 ... as h); L (m,) the piece
    lengths (s); sigma (k,) stationary 1-sigma of each component; tau_s (k,) correlation
    times (s; inf: a constant, no noise).  Q is in the units of [x, eta]."""
    G = np.asarray(G, np.float64)
    L = np.asarray(L, np.float64)
    sig2 = np.asarray(sigma, np.float64) ** 2
    tau = np.asarray(tau_s, np.float64)
    m, n, nx, k = G.shape
    with np.errstate(divide="ignore"):
        beta = np.where(np.isfinite(tau)[None, :], L[:, None] / tau[None, :], 0.0)  # (m, k)
    u, v, W = product_weights(beta, n)  # (m, k, n), (m, k, n), (m, k, n, n)
    gamma = L[:, None, None] * np.einsum("mjai,mij->mai", G, u)
    E = np.exp(-beta)
    q_xe = sig2[None, None, :] * L[:, None, None] * np.einsum("mjai,mij->mai", G, v)
    q_xx = np.einsum("mjai,mijl,mlbi,i->mab", G, W, G, sig2) * (L**2)[:, None, None]
    q_ee = sig2[None, :] * (1.0 - np.exp(-2.0 * beta))
    live = (np.isfinite(tau) & (sig2 > 0))[None, :]
    q_xe = q_xe * live[:, None, :]
    q_ee = q_ee * live
    Q = np.zeros((m, nx + k, nx + k))
    Q[:, :nx, :nx] = 0.5 * (q_xx + np.swapaxes(q_xx, -1, -2))
    Q[:, :nx, nx:] = q_xe
    Q[:, nx:, :nx] = np.swapaxes(q_xe, -1, -2)
    Q[:, np.arange(nx, nx + k), np.arange(nx, nx + k)] = q_ee
    return gamma, E, Q


def compose(phi, gamma, E, Q):
    """Chain consecutive pieces: (Phi, Gamma, E, Q) over the whole span from the pieces'
    Phi (m, nx, nx), Gamma (m, nx, k), E (m, k), Q (m, nx + k, nx + k), first piece first.
    Psi = [[Phi, Gamma], [0, diag E]] multiplies (Psi_2 Psi_1) and Q accumulates as
    Q <- Psi_p Q Psi_p^T + Q_p (exact: the noise of disjoint pieces is independent)."""
    m, nx, k = gamma.shape
    P = np.eye(nx)
    Gm = np.zeros((nx, k))
    Em = np.ones(k)
    Qm = np.zeros((nx + k, nx + k))
    psi = np.zeros((nx + k, nx + k))
    for p in range(m):
        psi[:nx, :nx] = phi[p]
        psi[:nx, nx:] = gamma[p]
        psi[nx:, nx:] = np.diag(E[p])
        Qm = psi @ Qm @ psi.T + Q[p]
        Gm = phi[p] @ Gm + gamma[p] * Em[None, :]
        P = phi[p] @ P
        Em = E[p] * Em
    return P, Gm, Em, 0.5 * (Qm + Qm.T)
