"""Two-vehicle (rendezvous) filter algebra: Draper R-649's block equations and the stacked
form the TEAM two-vehicle engine uses.

The state is [x_A; x_T; beta]: the active vehicle (chaser, 6: r km, v km/s), the target (6)
and n instrument biases.  One scalar measurement (R-649 Eq. 4/12)::

    dQ = b_A' de_A + b_T' de_T + b_b' beta + alpha,    alpha ~ N(0, alpha^2),   b_T = -b_A = b_R

Covariance blocks (R-649 §II.B notation; e = estimate - truth)::

    E_A = <e_A e_A'>   E_T = <e_T e_T'>   E_b = <e_b e_b'>
    G = <e_A e_T'>     GAb = <e_A e_b'>   GTb = <e_T e_b'>
    E_R = E_A + E_T - G - G'   (Eq. 17),   GRb = GTb - GAb

Block equations (rebuilt where the scan is garbled; digest ``unf-apollo.md`` §B.2-B.4, the
list of OCR defects there and ``tests/filters/test_two_vehicle.py``):

* :func:`optimum_gains`        Eq. 20, each vehicle's minimum-variance gain (biases considered)
* :func:`relative_gain_eq16`   Eq. 16, omega_R from the inertial blocks (= omega_T - omega_A)
* :func:`relative_gain_eq8`    Eq. 8, the relative-state Schmidt gain
* :func:`block_update`         Eqs. 18, 19, 22, 23, 24: the blocks after an update with ANY
  gains (omega_A, omega_T); E_b unchanged (biases considered, not estimated)
* :func:`ssu_gains`            Eq. 25, single-state update: omega_T = 0, omega_A = -omega_R
* :func:`apollo_gain`          Eq. 26, the Apollo filter: its one 6x6 W W' taken as E_R

Stacked form (what the engine runs; R-649's "no special code is needed, only the stacked
state"): :func:`stack`, :func:`unstack`, :func:`masked_gain` (Kalman-Schmidt on the estimated
rows of any role mask) and :func:`scalar_joseph` (the Joseph update for any gain, for the
assumed and the true covariance of a generalized-covariance run).  The tests prove the
block equations equal the stacked ones to rounding.

Pure JAX, float64, no I/O; nothing raises.
"""

from __future__ import annotations

import jax.numpy as jnp

from fracas import _jax  # noqa: F401  (float64 before any array exists)

__all__ = [
    "stack",
    "unstack",
    "relative_covariance",
    "optimum_gains",
    "relative_gain_eq16",
    "relative_gain_eq8",
    "block_update",
    "ssu_gains",
    "apollo_gain",
    "masked_gain",
    "scalar_joseph",
]


def _f(x):
    return jnp.asarray(x, dtype=jnp.float64)


def stack(E_A, E_T, G, GAb, GTb, E_b):
    """The stacked covariance of [x_A; x_T; beta] ((12 + n), (12 + n)) from R-649's blocks."""
    E_A, E_T, G, GAb, GTb, E_b = map(_f, (E_A, E_T, G, GAb, GTb, E_b))
    top = jnp.concatenate([E_A, G, GAb], axis=1)
    mid = jnp.concatenate([G.T, E_T, GTb], axis=1)
    bot = jnp.concatenate([GAb.T, GTb.T, E_b], axis=1)
    return jnp.concatenate([top, mid, bot], axis=0)


def unstack(P):
    """(E_A, E_T, G, GAb, GTb, E_b) from a stacked covariance (12 + n square)."""
    P = _f(P)
    return P[:6, :6], P[6:12, 6:12], P[:6, 6:12], P[:6, 12:], P[6:12, 12:], P[12:, 12:]


def relative_covariance(E_A, E_T, G):
    """E_R = E_A + E_T - G - G' (R-649 Eq. 17), the covariance of e_T - e_A (km, km/s)."""
    E_A, E_T, G = _f(E_A), _f(E_T), _f(G)
    return E_A + E_T - G - G.T


def _A(E_A, E_T, G, GAb, GTb, E_b, bA, bT, bb, alpha2):
    return (
        bA @ E_A @ bA
        + bT @ E_T @ bT
        + bb @ E_b @ bb
        + 2.0 * bA @ G @ bT
        + 2.0 * bA @ GAb @ bb
        + 2.0 * bT @ GTb @ bb
        + alpha2
    )


def optimum_gains(E_A, E_T, G, GAb, GTb, E_b, bA, bT, bb, alpha2):
    """R-649 Eq. 20: (omega_A, omega_T, A) with A the residual variance (Eq. 20's denominator)::

    omega_A = (E_A b_A + G b_T + GAb b_b) / A,   omega_T = (E_T b_T + G' b_A + GTb b_b) / A
    """
    args = tuple(map(_f, (E_A, E_T, G, GAb, GTb, E_b, bA, bT, bb, alpha2)))
    E_A, E_T, G, GAb, GTb, E_b, bA, bT, bb, alpha2 = args
    A = _A(*args)
    return (E_A @ bA + G @ bT + GAb @ bb) / A, (E_T @ bT + G.T @ bA + GTb @ bb) / A, A


def relative_gain_eq16(E_A, E_T, G, GAb, GTb, E_b, bA, bT, bb, alpha2):
    """R-649 Eq. 16: omega_R = -[E_A b_A - E_T b_T - G' b_A + G b_T + GAb b_b - GTb b_b] / A."""
    args = tuple(map(_f, (E_A, E_T, G, GAb, GTb, E_b, bA, bT, bb, alpha2)))
    E_A, E_T, G, GAb, GTb, E_b, bA, bT, bb, alpha2 = args
    A = _A(*args)
    return -(E_A @ bA - E_T @ bT - G.T @ bA + G @ bT + GAb @ bb - GTb @ bb) / A


def relative_gain_eq8(E_R, GRb, E_b, bR, bb, alpha2):
    """R-649 Eq. 8: the relative-state Schmidt gain and its residual variance (omega_R, A)::

    omega_R = (E_R b_R + GRb b_b) / A,   A = b_R' E_R b_R + b_b' E_b b_b + 2 b_R' GRb b_b + alpha^2
    """
    E_R, GRb, E_b, bR, bb, alpha2 = map(_f, (E_R, GRb, E_b, bR, bb, alpha2))
    A = bR @ E_R @ bR + bb @ E_b @ bb + 2.0 * bR @ GRb @ bb + alpha2
    return (E_R @ bR + GRb @ bb) / A, A


def block_update(E_A, E_T, G, GAb, GTb, E_b, bA, bT, bb, alpha2, wA, wT):
    """R-649 Eqs. 18, 19, 22, 23, 24: the covariance blocks after one scalar update with ANY
    gains omega_A = ``wA``, omega_T = ``wT`` (e_A+ = e_A - wA dQ, e_T+ = e_T - wT dQ; biases
    considered, so E_b is unchanged).  Returns (E_A, E_T, G, GAb, GTb, E_b).

    Scan defects fixed (digest §B.3): Eq. 18's bracket is truncated after "b_T' GTb' b_b +"
    (completed with b_b' GTb'' b_T + alpha^2); Eq. 22's "b_b GAb'' b_A" lacks a transpose;
    App. B-6's "b_a" is b_A.
    """
    E_A, E_T, G, GAb, GTb, E_b, bA, bT, bb, alpha2, wA, wT = map(
        _f, (E_A, E_T, G, GAb, GTb, E_b, bA, bT, bb, alpha2, wA, wT)
    )
    eye = jnp.eye(6, dtype=jnp.float64)
    IA = eye - jnp.outer(wA, bA)
    IT = eye - jnp.outer(wT, bT)
    # (18)
    sA = bT @ E_T @ bT + bb @ E_b @ bb + bT @ GTb @ bb + bb @ GTb.T @ bT + alpha2
    cA = G @ bT + GAb @ bb
    EA_new = IA @ E_A @ IA.T + sA * jnp.outer(wA, wA) - jnp.outer(IA @ cA, wA) - jnp.outer(wA, IA @ cA)
    # (19): A <-> T, G -> G'
    sT = bA @ E_A @ bA + bb @ E_b @ bb + bA @ GAb @ bb + bb @ GAb.T @ bA + alpha2
    cT = G.T @ bA + GTb @ bb
    ET_new = IT @ E_T @ IT.T + sT * jnp.outer(wT, wT) - jnp.outer(IT @ cT, wT) - jnp.outer(wT, IT @ cT)
    # (22)
    sG = bT @ G.T @ bA + bb @ E_b @ bb + bb @ GAb.T @ bA + bT @ GTb @ bb + alpha2
    G_new = (
        IA @ G @ IT.T
        + sG * jnp.outer(wA, wT)
        - jnp.outer(IA @ (E_A @ bA + GAb @ bb), wT)
        - jnp.outer(wA, IT @ (E_T @ bT + GTb @ bb))
    )
    # (23), (24)
    GAb_new = IA @ GAb - jnp.outer(wA, bT @ GTb + bb @ E_b)
    GTb_new = IT @ GTb - jnp.outer(wT, bA @ GAb + bb @ E_b)
    return EA_new, ET_new, G_new, GAb_new, GTb_new, E_b


def ssu_gains(E_A, E_T, G, GAb, GTb, E_b, bA, bT, bb, alpha2):
    """R-649 Eq. 25, the single-state update: omega_T = 0, omega_A = -omega_R (the optimal
    relative update at this mark, all of it put on the active vehicle)."""
    wR = relative_gain_eq16(E_A, E_T, G, GAb, GTb, E_b, bA, bT, bb, alpha2)
    return -wR, jnp.zeros(6, dtype=jnp.float64)


def apollo_gain(W_filter_cov, bA, alpha2):
    """R-649 Eq. 26, the Apollo filter's gain omega_A = E_R' b_A / (b_A' E_R' b_A + alpha^2),
    with E_R' the filter's own 6x6 W W' (the target is taken as perfect: in TEAM terms its
    errors are ignore parameters)."""
    E, bA, alpha2 = _f(W_filter_cov), _f(bA), _f(alpha2)
    return E @ bA / (bA @ E @ bA + alpha2)


def masked_gain(P, h, r, estimated):
    """Kalman-Schmidt gain of one scalar measurement on the stacked state: k = m * P h / (h'P h + r)
    with m the 0/1 mask of the estimated rows (solve-for states and biases; consider and
    ignore rows get zero gain).  (n,) in state units per measurement unit."""
    P, h, r, m = _f(P), _f(h), _f(r), _f(estimated)
    return m * (P @ h) / (h @ P @ h + r)


def scalar_joseph(P, h, r, k):
    """Joseph update for any gain: (I - k h') P (I - h k') + r k k' (symmetrized)."""
    P, h, r, k = _f(P), _f(h), _f(r), _f(k)
    IKH = jnp.eye(P.shape[0], dtype=jnp.float64) - jnp.outer(k, h)
    Pn = IKH @ P @ IKH.T + r * jnp.outer(k, k)
    return 0.5 * (Pn + Pn.T)
