"""White acceleration process noise (Shuttle UNF s_q, digest unf-apollo.md A.5.4) against
its references:

- the zero-order-hold Q_d = q [[dt^3/3 D, dt^2/2 D], [dt^2/2 D, dt D]] against a scipy
  integration (rtol 1e-12) of dP/dt = F P + P F^T + B q D B^T for a straight line;
- the Gauss-Legendre quadrature of the exact integral (:func:`white_q_nodes`, the reference's
  STMs at the nodes) against the scipy covariance ODE on a two-body LEO arc, full and
  crosstrack-only (D = zeta zeta^T varying along the reference);
- crosstrack-only noise on a circular orbit: the crosstrack channel is a harmonic oscillator
  z'' = -n^2 z + w (E[w w] = q delta), so from P = 0 (closed form, derived in the docs)

      var z    = q / n^2 (t/2 - sin(2 n t) / (4 n)),
      var zdot = q (t/2 + sin(2 n t) / (4 n)),
      cov      = q sin^2(n t) / (2 n^2),

  and the in-plane 4x4 block stays zero (the channels decouple);
- the direction matrices (full = radial + along + crosstrack) and the continuous Qc.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from fracas.filters.process_noise import (
    gauss_legendre,
    white_direction,
    white_q_nodes,
    white_q_zoh,
    white_Qc,
)
from tests.filters.helpers import scaled_err

MU = 398600.4418  # km^3/s^2


def _G(r):
    rn = np.linalg.norm(r)
    return MU / rn**5 * (3.0 * np.outer(r, r) - rn**2 * np.eye(3))


def _F(r):
    F = np.zeros((6, 6))
    F[:3, 3:] = np.eye(3)
    F[3:, :3] = _G(r)
    return F


def _two_body(x0, t_out):
    """States and STMs Phi(t, 0) of two-body motion at ``t_out`` (scipy, rtol 1e-13)."""

    def rhs(t, y):
        r, v = y[:3], y[3:6]
        phi = y[6:].reshape(6, 6)
        a = -MU * r / np.linalg.norm(r) ** 3
        return np.concatenate([v, a, (_F(r) @ phi).ravel()])

    y0 = np.concatenate([x0, np.eye(6).ravel()])
    sol = solve_ivp(rhs, (0.0, float(np.max(t_out))), y0, t_eval=t_out, rtol=1e-13, atol=1e-12, method="DOP853")
    return sol.y[:6].T, sol.y[6:].T.reshape(-1, 6, 6)


def _np_direction(r, v, direction):
    """The direction matrix in plain numpy (independent of the kernel)."""
    if direction == "full":
        return np.eye(3)
    zeta = np.cross(r, v) / np.linalg.norm(np.cross(r, v))
    rh = r / np.linalg.norm(r)
    u = {"crosstrack": zeta, "radial": rh, "along": np.cross(zeta, rh)}[direction]
    return np.outer(u, u)


def _cov_ode(x0, t1, q, direction, P0=None):
    """Reference: dP/dt = F P + P F^T + B q D(x) B^T along two-body motion (scipy, rtol 1e-12)."""

    def rhs(t, y):
        x = y[:6]
        P = y[6:].reshape(6, 6)
        r, v = x[:3], x[3:]
        F = _F(r)
        Qc = np.zeros((6, 6))
        Qc[3:, 3:] = q * _np_direction(r, v, direction)
        dP = F @ P + P @ F.T + Qc
        return np.concatenate([v, -MU * r / np.linalg.norm(r) ** 3, dP.ravel()])

    P0 = np.zeros((6, 6)) if P0 is None else P0
    y0 = np.concatenate([x0, P0.ravel()])
    s = np.sqrt(np.array([q * t1**3] * 3 + [q * t1] * 3) + np.diag(P0))  # sigma scales of P(t1)
    atol = np.concatenate([np.full(6, 1e-12), 1e-14 * np.outer(s, s).ravel()])
    sol = solve_ivp(rhs, (0.0, t1), y0, rtol=1e-12, atol=atol, method="DOP853")
    return sol.y[6:, -1].reshape(6, 6)


def _quadrature_q(x0, t1, q, direction, pieces=8, n=4):
    """white_q_nodes over ``pieces`` equal pieces of [0, t1], mapped to t1 with the STMs."""
    edges = np.linspace(0.0, t1, pieces + 1)
    nodes, w = gauss_legendre(n, edges[:-1], edges[1:])
    xs, phis = _two_body(x0, np.concatenate([nodes.ravel(), [t1]]))
    phi_t1 = phis[-1]
    phi_end = np.array([phi_t1 @ np.linalg.inv(p) for p in phis[:-1]])  # Phi(t1, s) = Phi(t1, 0) Phi(s, 0)^-1
    D = np.asarray(white_direction(xs[:-1, :3], xs[:-1, 3:], direction))
    return np.asarray(white_q_nodes(phi_end, D, w.ravel(), q))


def _block_err(P, ref):
    """max |P - ref| relative to the largest element of each 3x3 block (pos-pos, pos-vel,
    vel-vel) of ref: entries that are rounding noise in ref (a zero crosstrack component)
    are judged on their block's scale."""
    out = 0.0
    for a in (slice(0, 3), slice(3, 6)):
        for b in (slice(0, 3), slice(3, 6)):
            d, e = np.max(np.abs(ref[a, b])), np.max(np.abs(P[a, b] - ref[a, b]))
            out = max(out, float(e / d) if d > 0 else float(e))
    return out


LEO = np.array([7000.0, 0.0, 0.0, 0.0, 6.5, 3.752])  # km, km/s: e ~ 0.03, i ~ 30 deg


def test_zoh_matches_scipy_straight_line():
    """Zero-order hold vs dP/dt = F P + P F^T + B q D B^T with F = [[0, I], [0, 0]]."""
    q, dt = 2.5e-9, 600.0
    D = np.asarray(white_direction(LEO[:3], LEO[3:], "crosstrack"))
    F = np.zeros((6, 6))
    F[:3, 3:] = np.eye(3)
    Qc = np.asarray(white_Qc(q, D))

    def rhs(t, y):
        P = y.reshape(6, 6)
        return (F @ P + P @ F.T + Qc).ravel()

    ref = solve_ivp(rhs, (0.0, dt), np.zeros(36), rtol=1e-12, atol=1e-12 * q * dt**3, method="DOP853")
    ref = ref.y[:, -1].reshape(6, 6)
    Qd = np.asarray(white_q_zoh(q, D, dt))
    assert np.max(np.abs(Qd - ref)) <= 1e-11 * np.max(np.abs(ref))
    Qfull = np.asarray(white_q_zoh(q, np.eye(3), dt))
    np.testing.assert_allclose(np.diag(Qfull), q * np.array([dt**3 / 3] * 3 + [dt] * 3), rtol=1e-15)


@pytest.mark.parametrize("direction", ["full", "crosstrack", "radial", "along"])
def test_quadrature_matches_scipy_covariance_ode(direction):
    """Gauss-Legendre quadrature of the exact integral vs the scipy covariance ODE over
    2000 s (~1/3 orbit) of a two-body LEO arc."""
    q, t1 = 1e-10, 2000.0
    ref = _cov_ode(LEO, t1, q, direction)
    Qd = _quadrature_q(LEO, t1, q, direction)
    err = _block_err(Qd, ref)
    assert err < 1e-9, err
    # the zero-order hold ignores gravity: far off over a third of an orbit
    zoh = np.asarray(white_q_zoh(q, np.asarray(white_direction(LEO[:3], LEO[3:], direction)), t1))
    assert _block_err(zoh, ref) > 1e-2


def test_quadrature_with_prior_composes():
    """P(t1) = Phi P0 Phi^T + Q_d reproduces the ODE started from a full P0."""
    q, t1 = 1e-10, 1500.0
    rng = np.random.default_rng(3)
    B = rng.normal(size=(6, 6)) * np.array([0.1] * 3 + [1e-4] * 3)
    P0 = B @ B.T
    ref = _cov_ode(LEO, t1, q, "crosstrack", P0)
    _, phis = _two_body(LEO, np.array([t1]))
    P = phis[-1] @ P0 @ phis[-1].T + _quadrature_q(LEO, t1, q, "crosstrack")
    assert scaled_err(P, ref, ref) < 1e-9


def test_crosstrack_circular_orbit_harmonic_oscillator():
    """Crosstrack-only noise on a circular orbit: closed-form oscillator variances, and the
    in-plane 4x4 block untouched."""
    r0 = 7000.0
    vc = np.sqrt(MU / r0)
    inc = np.radians(40.0)
    x0 = np.array([r0, 0.0, 0.0, 0.0, vc * np.cos(inc), vc * np.sin(inc)])
    n = np.sqrt(MU / r0**3)
    q, t = 1e-10, 3000.0
    Qd = _quadrature_q(x0, t, q, "crosstrack", pieces=12)
    xs, _ = _two_body(x0, np.array([t]))
    zeta = np.cross(xs[0, :3], xs[0, 3:])
    zeta /= np.linalg.norm(zeta)
    var_z = q / n**2 * (t / 2 - np.sin(2 * n * t) / (4 * n))
    var_zd = q * (t / 2 + np.sin(2 * n * t) / (4 * n))
    cov = q * np.sin(n * t) ** 2 / (2 * n**2)
    np.testing.assert_allclose(zeta @ Qd[:3, :3] @ zeta, var_z, rtol=1e-10)
    np.testing.assert_allclose(zeta @ Qd[3:, 3:] @ zeta, var_zd, rtol=1e-10)
    np.testing.assert_allclose(zeta @ Qd[:3, 3:] @ zeta, cov, rtol=1e-10)
    # in-plane: project out zeta from both position and velocity
    Pi = np.eye(3) - np.outer(zeta, zeta)
    T = np.block([[Pi, np.zeros((3, 3))], [np.zeros((3, 3)), Pi]])
    inplane = T @ Qd @ T.T
    assert np.max(np.abs(inplane)) < 1e-12 * var_z
    # full noise grows the in-plane block: the crosstrack option is a real restriction
    Qf = _quadrature_q(x0, t, q, "full", pieces=12)
    assert np.max(np.abs(T @ Qf @ T.T)) > 0.1 * var_z


def test_directions_and_continuous_q():
    r, v = LEO[:3], LEO[3:]
    D = {d: np.asarray(white_direction(r, v, d)) for d in ("full", "crosstrack", "radial", "along")}
    np.testing.assert_allclose(D["crosstrack"] + D["radial"] + D["along"], D["full"], atol=1e-15)
    for d in ("crosstrack", "radial", "along"):
        np.testing.assert_allclose(D[d] @ D[d], D[d], atol=1e-15)  # a rank-1 projector
        assert abs(np.trace(D[d]) - 1.0) < 1e-15
    zeta = np.cross(r, v) / np.linalg.norm(np.cross(r, v))
    np.testing.assert_allclose(D["crosstrack"] @ zeta, zeta, atol=1e-15)
    Qc = np.asarray(white_Qc(3.0, D["crosstrack"], nx=7))
    assert Qc.shape == (7, 7) and np.all(Qc[:3] == 0) and np.all(Qc[6] == 0)
    np.testing.assert_allclose(Qc[3:6, 3:6], 3.0 * D["crosstrack"])
    with pytest.raises(ValueError):
        white_direction(r, v, "sideways")
