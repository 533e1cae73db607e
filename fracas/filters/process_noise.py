"""Gauss-Markov thrust process noise for TEAM, two ways (FRACAS DYNO, DERY, PATH; App. 9.3).

The time-varying thrust errors eta (k components: proportionality, in-plane and
out-of-plane pointing, ``fracas.integrate.variational.THRUST_NOISE_LABELS``) are
stationary first-order Gauss-Markov processes (App. 9.3 eq. 3):

    eta_i' = -eta_i / tau_i + q_i,   E[eta_i(t1) eta_i(t2)] = sigma_i^2 exp(-|t1 - t2| / tau_i),
    E[q_i(t1) q_i(t2)] = (2 sigma_i^2 / tau_i) delta(t1 - t2)                        (3)

and enter the linearised motion through h(t) = d xdot / d eta (App. 9.3 eq. 2,
delta xdot = f dx + g du + h d eta).

PHI (FRACAS DYNO, eqs. 1-7; App. 9.3 eqs. 6-7): between events t_k and t_{k+1} the state
covariance is mapped with the transition matrix and an *effective* process noise is added,

    P_{k+1} = Phi P_k Phi^T + Qtilde,
    Qtilde = R(dt, tau) [alpha H_{k+1} + Phi H_k Phi^T],   R = tau dt / 2,
    alpha = 2 if dt > tau else 0,   H = [[0, 0], [0, h P_eta h^T]]                   (1-7)

a semi-empirical stand-in for the exact double integral
Qtilde = int int Phi(t, s1) h E[eta(s1) eta(s2)^T] h^T Phi(t, s2)^T ds1 ds2 (App. 9.3).

PDOT (FRACAS DERY; App. 9.3 "PDOT"): the noise states are appended to the state and
the augmented covariance is integrated, Pdot = F P + P F^T + Qc, with

    z = [x (nx), p (np constant parameters u), eta (k)],
    F = [[A, B, h], [0, 0, 0], [0, 0, -diag(1/tau)]],   Qc = diag(0, 0, 2 sigma^2 / tau).

Equations rebuilt from the scan of NASA CR-112256: DERY's F is printed for the ordering
(p, v, eta, u) with the noise block's zeros read as "sigma", and App. 9.3's augmented F and
eq. 3's white-noise strength carry stray symbols; the forms above are the standard
Gauss-Markov augmentation they describe (F's last block -rho, rho = diag(1/tau_i);
E[q q] = (2/tau) sigma_eta^2 delta) and are checked against closed-form covariances in
tests/filters/test_process_noise.py.

White acceleration noise (Shuttle UNF s_q, digest unf-apollo.md A.5.4; docs/process_noise.md):
a white acceleration w(t) of spectral density q (km^2/s^3) on the velocity rows,
delta xdot = F dx + B w, B = [0; I3; 0], E[w(t1) w(t2)^T] = q D delta(t1 - t2), with D the
direction matrix (:func:`white_direction`): I3 ("full", UNF s_q = 1), zeta zeta^T
("crosstrack", s_q = 2, zeta = r x v / |r x v| of the reference), r^ r^T ("radial") or
a^ a^T ("along", a^ = zeta x r^).  Over an interval the discrete noise is

    Q_d = int_{t0}^{t1} Phi(t1, s) B q D(s) B^T Phi(t1, s)^T ds,

for a short interval with Phi ~ [[I, dt I], [0, I]] and constant D the zero-order-hold form
q [[dt^3/3 D, dt^2/2 D], [dt^2/2 D, dt D]] (:func:`white_q_zoh`); exactly, by quadrature
with the reference's transition matrices at the nodes (:func:`white_q_nodes`); PDOT adds
the continuous Qc = B q D B^T (:func:`white_Qc`) to Pdot.

Units: s for times, and whatever units the state uses (the trajectory core: km, km/s, kg;
h in xdot units per unit of eta).  Pure jnp; every function is jit-able.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from fracas import _jax  # noqa: F401

__all__ = [
    "WHITE_DIRECTIONS",
    "gauss_legendre",
    "white_direction",
    "white_Qc",
    "white_q_nodes",
    "white_q_zoh",
    "covariance_derivative",
    "dyno_q",
    "effective_bias_sigma",
    "gm_Qc",
    "gm_augmented_F",
    "gm_decay",
    "pdot_propagate",
]


def _f64(a):
    return jnp.asarray(a, dtype=jnp.float64)


def _sym(p):
    return 0.5 * (p + jnp.swapaxes(p, -1, -2))


@jax.jit
def dyno_q(phi, h_k, h_k1, sigma, tau_s, dt_s):
    """DYNO's effective process noise Qtilde (nx, nx) over one interval (FRACAS DYNO eqs. 1-7).

    phi (nx, nx): transition matrix Phi(t_{k+1}, t_k) of the basic state (nx = 6 or 7:
    r km, v km/s, optionally m kg); h_k, h_k1 (nx, k): h = d xdot / d eta at t_k and t_{k+1}
    (position rows zero, so h P_eta h^T has eq. 7's block form; a mass row is allowed);
    sigma (k,): stationary 1-sigma of each noise component (P_eta = diag(sigma^2), eq. 6);
    tau_s (k,): correlation times (s); dt_s: interval length t_{k+1} - t_k (s; its magnitude
    is used).  With a different tau per component, R and alpha differ per component and
    Qtilde is the sum of the per-component Qtilde_i (eq. 1 applied to each independent
    component), which reduces to eq. 1 itself when all tau are equal.

    DYNO assumes no thrust on/off event inside the interval (the caller splits there).
    """
    phi = _f64(phi)
    h_k = _f64(h_k)
    h_k1 = _f64(h_k1)
    var = _f64(sigma) ** 2
    tau = _f64(tau_s)
    dt = jnp.abs(_f64(dt_s))
    r = 0.5 * tau * dt  # eq. 4, s^2
    alpha = jnp.where(dt > tau, 2.0, 0.0)  # eq. 3
    hk1 = jnp.einsum("ai,i,bi->ab", h_k1, r * alpha * var, h_k1)  # sum_i R_i alpha_i H_{k+1,i}
    ph = phi @ h_k
    hk = jnp.einsum("ai,i,bi->ab", ph, r * var, ph)  # sum_i R_i Phi H_{k,i} Phi^T
    return _sym(hk1 + hk)


def gm_augmented_F(A, B, h, tau_s):
    """Augmented system matrix F (..., n, n), n = nx + np + k, for z = [x, p, eta] (FRACAS DERY;
    App. 9.3 PDOT): F = [[A, B, h], [0, 0, 0], [0, 0, -diag(1/tau)]].

    A (..., nx, nx) = d xdot/dx (1/s); B (..., nx, np) = d xdot/dp for constant parameters;
    h (..., nx, k) = d xdot/d eta; tau_s (k,) correlation times (s; inf makes eta a bias).
    Leading batch dimensions (e.g. integration nodes) broadcast.  From the trajectory core:
    ``A, Bfull = variational.jacobians_at(..., labels=params + THRUST_NOISE_LABELS)``, then
    ``gm_augmented_F(A, Bfull[..., :np], Bfull[..., np:], tau_s)``.
    """
    A, B, h, tau = _f64(A), _f64(B), _f64(h), _f64(tau_s)
    batch = jnp.broadcast_shapes(A.shape[:-2], B.shape[:-2], h.shape[:-2])
    nx, npar, k = A.shape[-1], B.shape[-1], h.shape[-1]
    n = nx + npar + k
    A = jnp.broadcast_to(A, batch + (nx, nx))
    B = jnp.broadcast_to(B, batch + (nx, npar))
    h = jnp.broadcast_to(h, batch + (nx, k))
    top = jnp.concatenate([A, B, h], axis=-1)
    mid = jnp.zeros(batch + (npar, n))
    decay = jnp.broadcast_to(-jnp.diag(1.0 / tau), batch + (k, k))
    bot = jnp.concatenate([jnp.zeros(batch + (k, nx + npar)), decay], axis=-1)
    return jnp.concatenate([top, mid, bot], axis=-2)


def gm_Qc(sigma, tau_s, nx, np):
    """White-noise spectral density Qc (n, n) of the augmented system: 2 sigma^2 / tau on the
    eta diagonal, zero elsewhere (App. 9.3 eq. 3; units of eta^2 / s)."""
    q = 2.0 * _f64(sigma) ** 2 / _f64(tau_s)
    k = q.shape[0]
    n = nx + np + k
    return jnp.zeros((n, n)).at[nx + np :, nx + np :].set(jnp.diag(q))


def covariance_derivative(P, F, Qc):
    """Pdot = F P + P F^T + Qc (FRACAS DERY; App. 9.3 PDOT)."""
    return F @ P + P @ jnp.swapaxes(F, -1, -2) + Qc


@jax.jit
def pdot_propagate(P0, F_nodes, Qc, dt_s):
    """Integrate Pdot = F P + P F^T + Qc by classical RK4 over N uniform steps (FRACAS PATH/DERY).

    P0 (n, n) at t0; F_nodes (2N+1, n, n): F at t0, t0 + h/2, t0 + h, ..., t0 + N h with
    h = dt_s (s; negative integrates backward); Qc (n, n) constant, or (2N+1, n, n) at the
    same nodes.  Each step uses F at its start, midpoint and end (stages 2 and 3 share the
    midpoint); P is symmetrised after every step.  Returns P (n, n) at t0 + N h.
    ``dt_s`` may also be one step per node pair, (N,): a zero step leaves P as it is, so a
    caller can pad N to a few sizes and share one compiled program (fracas.team.pdot).
    Global error O(h^4) (tests/filters/test_process_noise.py checks the order).
    """
    P0 = _f64(P0)
    F_nodes = _f64(F_nodes)
    Qc = _f64(Qc)
    if Qc.ndim == 2:
        Qc = jnp.broadcast_to(Qc, F_nodes.shape)
    hs = jnp.broadcast_to(_f64(dt_s), ((F_nodes.shape[0] - 1) // 2,))
    xs = (F_nodes[0:-1:2], F_nodes[1::2], F_nodes[2::2], Qc[0:-1:2], Qc[1::2], Qc[2::2], hs)

    def step(P, nodes):
        f0, fm, f1, q0, qm, q1, h = nodes
        k1 = covariance_derivative(P, f0, q0)
        k2 = covariance_derivative(P + (0.5 * h) * k1, fm, qm)
        k3 = covariance_derivative(P + (0.5 * h) * k2, fm, qm)
        k4 = covariance_derivative(P + h * k3, f1, q1)
        return _sym(P + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)), None

    P, _ = jax.lax.scan(step, _sym(P0), xs)
    return P


def gm_decay(tau_s, dt_s):
    """Gauss-Markov transition exp(-|dt| / tau) over dt_s seconds (App. 9.3 eq. 3)."""
    return jnp.exp(-jnp.abs(_f64(dt_s)) / _f64(tau_s))


def effective_bias_sigma(sigma_noise, tau_days):
    """1-sigma of the thrust *bias* that mimics correlated thrust noise of 1-sigma
    ``sigma_noise`` and correlation time ``tau_days`` (days, not s):
    sigma_bias ~ (0.30 + 0.05 tau) sigma_noise (App. 9.3 eq. 5; empirical, from GODSEP runs
    of a SEP Mercury approach, fitted for tau of about 1 to 10 days)."""
    return (0.30 + 0.05 * _f64(tau_days)) * _f64(sigma_noise)


# ----------------------------------------------------------------------------- white acceleration noise
#: Directions of the white acceleration noise (UNF s_q = 1: "full", s_q = 2: "crosstrack").
WHITE_DIRECTIONS = ("full", "crosstrack", "radial", "along")


def _unit(a):
    return a / jnp.linalg.norm(a, axis=-1, keepdims=True)


def white_direction(r, v, direction: str):
    """Direction matrix D (..., 3, 3) of the white acceleration noise at the reference state
    (UNF s_q; digest A.5.4): I3 for "full", zeta zeta^T for "crosstrack" (zeta = r x v / |r x v|,
    the orbit normal), r^ r^T for "radial", a^ a^T for "along" (a^ = zeta x r^, the in-plane
    horizontal).  ``r`` (..., 3) km and ``v`` (..., 3) km/s relative to the primary; ``direction``
    is static (a Python string).  D is dimensionless; the noise is q D with q in km^2/s^3."""
    r = _f64(r)
    v = _f64(v)
    if direction == "full":
        return jnp.broadcast_to(jnp.eye(3), r.shape[:-1] + (3, 3))
    if direction not in WHITE_DIRECTIONS:
        raise ValueError(f"direction = {direction!r}: expected one of {WHITE_DIRECTIONS}")
    zeta = _unit(jnp.cross(r, v))
    rh = _unit(r)
    u = {"crosstrack": zeta, "radial": rh, "along": jnp.cross(zeta, rh)}[direction]
    return u[..., :, None] * u[..., None, :]


def white_Qc(q, D, nx: int = 6):
    """Continuous-time noise B q D B^T (..., nx, nx) of a white acceleration: q D (km^2/s^3)
    on the velocity block [3:6, 3:6], zero elsewhere (PDOT: Pdot = F P + P F^T + Qc)."""
    D = _f64(D)
    out = jnp.zeros(D.shape[:-2] + (nx, nx))
    return out.at[..., 3:6, 3:6].set(_f64(q) * D)


def white_q_zoh(q, D, dt_s, nx: int = 6):
    """Zero-order-hold discrete white-acceleration noise over dt_s seconds (digest A.5.4),
    exact for a straight line (Phi = [[I, dt I], [0, I]]) with constant D::

        Q_d = q [[dt^3/3 D, dt^2/2 D], [dt^2/2 D, dt D]]     (km^2, km^2/s, km^2/s^2)

    q: spectral density (km^2/s^3); D (3, 3) from :func:`white_direction`; returns (nx, nx)
    (a mass row/column is zero).  Its magnitude |dt| is used."""
    q = _f64(q)
    D = _f64(D)
    dt = jnp.abs(_f64(dt_s))
    blk = jnp.block([[dt**3 / 3.0 * D, dt**2 / 2.0 * D], [dt**2 / 2.0 * D, dt * D]])
    return jnp.zeros((nx, nx)).at[:6, :6].set(q * blk)


@jax.jit
def white_q_nodes(phi_end, D, weights, q):
    """Discrete white-acceleration noise by quadrature of the exact integral (digest A.5.4)::

        Q_d = int Phi(t1, s) B q D(s) B^T Phi(t1, s)^T ds ~ sum_j w_j q Phi_j[:, 3:6] D_j Phi_j[:, 3:6]^T

    phi_end (m, nx, nx): Phi(t1, s_j) from each node s_j to the interval's end t1 (the
    reference's transition matrices); D (m, 3, 3) the direction matrices at the nodes;
    weights (m,) quadrature weights (s), e.g. :func:`gauss_legendre`; q (km^2/s^3).
    Returns the symmetric (nx, nx) noise at t1 (km^2, km^2/s, km^2/s^2)."""
    pb = _f64(phi_end)[:, :, 3:6]
    return _sym(jnp.einsum("j,jai,jik,jbk->ab", _f64(weights) * _f64(q), pb, _f64(D), pb))


def gauss_legendre(n: int, a, b) -> tuple[np.ndarray, np.ndarray]:
    """n-point Gauss-Legendre nodes and weights on [a, b] for each of the intervals ``a`` (m,),
    ``b`` (m,) (s): (nodes (m, n), weights (m, n)), exact for polynomials of degree 2n - 1
    (numpy; the node times are inputs of the reference integration, not traced)."""
    x, w = np.polynomial.legendre.leggauss(int(n))
    a = np.atleast_1d(np.asarray(a, np.float64))[:, None]
    b = np.atleast_1d(np.asarray(b, np.float64))[:, None]
    return 0.5 * (a + b) + 0.5 * (b - a) * x[None, :], 0.5 * (b - a) * w[None, :]
