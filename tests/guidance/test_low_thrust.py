"""Low-thrust primary guidance (GUIDM low-thrust branch, digest B.7).

Independent references: central finite differences of re-propagated fracas trajectories
(S, the cost Jacobians, the nulling of an a-target), Gauss's equation da/dt = 2a²(v·f)/μ
(digest G4), and explicit normal-equation / numpy.linalg.lstsq solutions (Γ_U).  One force
model (Earth two-body, one velocity-frame nuclear thrust arc) so the propagator compiles once.
"""

from __future__ import annotations

import numpy as np
import pytest

from fracas.dynamics.model import ForceModel, IntegratorSettings, default_params
from fracas.dynamics.parameters import get_values, set_values
from fracas.guidance.impulsive import guidance_matrix
from fracas.guidance.low_thrust import (
    LOW_THRUST_CONTROLS,
    control_labels,
    control_sensitivity,
    correction_cost_jacobians,
    execution_covariance,
    weighted_correction_matrix,
)
from fracas.guidance.targets import target_jacobian
from fracas.integrate.problem import Problem
from fracas.integrate.propagate import propagate

MU = 398600.4418
R0 = 7000.0
T_ON, T_OFF, T_F = 1000.0, 4000.0, 5000.0
MODEL = ForceModel(
    bodies=("earth",),
    thrust=True,
    velocity_dependent=True,
    power="nuclear",
    n_arcs=1,
    integrator=IntegratorSettings(c_nom=0.02, rect_ratio=10.0),
)
LABELS = tuple(control_labels(0))


def _problem(alpha=0.0, beta=0.0, decay=np.inf):
    p = default_params(
        MODEL,
        mu=[MU],
        power_kw=100.0,
        power_decay_s=decay,
        efficiency=0.6,
        exhaust_velocity_km_s=25.0,
        arc_t_on=[T_ON],
        arc_t_off=[T_OFF],
        arc_alpha=[alpha],
        arc_beta=[beta],
    )
    x0 = np.array([R0, 0.0, 0.0, 0.0, np.sqrt(MU / R0), 0.0, 1000.0])  # circular, equatorial
    return Problem(MODEL, p, None, 0.0, x0, np.array([0.0, T_F]))


def _state(pr, x_start, t0, t1, params=None):
    tr = propagate(MODEL, pr.params if params is None else params, None, 0.0, x_start, np.array([t0, t1]))
    return np.asarray(tr.x[-1])


def _with(pr, label, value):
    vals = np.asarray(get_values(pr.params, LABELS, MODEL)).copy()
    vals[LABELS.index(label)] = value
    return set_values(pr.params, LABELS, vals, MODEL)


def test_control_labels():
    assert control_labels(2, ("t_off", "alpha")) == ["arc_t_off[2]", "arc_alpha[2]"]
    assert LABELS == ("arc_thrust_scale[0]", "arc_alpha[0]", "arc_beta[0]", "arc_t_on[0]", "arc_t_off[0]")
    with pytest.raises(KeyError, match="proportionality"):
        control_labels(0, ("throttle",))


def _fd_final(pr, x_start, t0, t1, label, h):
    v0 = float(np.asarray(get_values(pr.params, (label,), MODEL))[0])
    xp = _state(pr, x_start, t0, t1, _with(pr, label, v0 + h))
    xm = _state(pr, x_start, t0, t1, _with(pr, label, v0 - h))
    return (xp - xm) / (2 * h)


@pytest.mark.slow  # ~92 s of a cold make test (mostly XLA compilation; issue 22)
def test_control_sensitivity_against_repropagation():
    """S over the guidance arc [t_I = t_on, t_c = t_off] (both switches at the ends) against
    central differences of re-propagated trajectories: k, α, β from x(t_I) to t_c (steps 1e-4,
    1e-6 rad); t_on from a coast state 200 s before t_I (so the switch is interior; steps 1 s);
    t_off through the coast to t_f, Φ(t_f, t_c) S against FD of x(t_f) (Φ from AD, tested in
    tests/integrate).  Tolerance 1e-5 of each column's size (measured ≤ 1e-6; time columns
    are roundoff-bound at 1 s steps, ~1e-8 km / 1 s)."""
    pr = _problem(alpha=0.1, beta=0.05)
    s, phi = (np.asarray(a) for a in control_sensitivity(pr, T_ON, T_OFF, LABELS))
    x_i = _state(pr, pr.x0, 0.0, T_ON)
    x_a = _state(pr, pr.x0, 0.0, T_ON - 200.0)
    fd = np.zeros((7, 5))
    for j, h in zip((0, 1, 2), (1e-4, 1e-6, 1e-6)):
        fd[:, j] = _fd_final(pr, x_i, T_ON, T_OFF, LABELS[j], h)
    fd[:, 3] = _fd_final(pr, x_a, T_ON - 200.0, T_OFF, LABELS[3], 1.0)
    _, phi_cf = (np.asarray(a) for a in control_sensitivity(pr, T_OFF, T_F, LABELS))
    fd_off_f = _fd_final(pr, x_i, T_ON, T_F, LABELS[4], 1.0)
    err = np.abs(s[:, :4] - fd[:, :4]).max(axis=0) / np.abs(fd[:, :4]).max(axis=0)
    err_off = np.abs(phi_cf @ s[:, 4] - fd_off_f).max() / np.abs(fd_off_f).max()
    assert err.max() < 1e-5 and err_off < 1e-5, (err, err_off)
    # digest (L-1) hand checks: ∂m_c/∂k = −(m_I − m_c); ∂X(t_c)/∂t_c = [0; a_c û_c; −T_c/c]
    x_c = _state(pr, x_i, T_ON, T_OFF)
    thrust = 2e-3 * 0.6 * 100.0 / 25.0
    assert np.isclose(s[6, 0], -(x_i[6] - x_c[6]), rtol=1e-12)
    assert np.allclose(s[:3, 4], 0.0) and np.isclose(s[6, 4], -thrust / 25.0, rtol=1e-12)
    assert np.isclose(np.linalg.norm(s[3:6, 4]), thrust / x_c[6], rtol=1e-12)


@pytest.mark.slow  # ~25 s of a cold make test (issue 22)
def test_gauss_spiral_and_nulling():
    """Digest G4 on a circular coplanar tangential spiral: A_T(a) Φ(t_f, t_c) S[:, t_off]
    equals Gauss's 2a²(v·f)/μ at t_c to 1e-8 (the energy equation, exact; measured 2.4e-9, the
    integration error of Φ at c_nom 0.02), and the circular
    form 2a^{3/2}a_c/√μ to 1e-4 (the spiral's eccentricity, a_c r²/μ ~ 6e-4); δt_c alone from
    weighted_correction_matrix nulls a at t_f: the re-propagated residual is < 1e-3 of the
    uncorrected miss (second order)."""
    pr = _problem()
    s, _ = (np.asarray(a) for a in control_sensitivity(pr, T_ON, T_OFF, LABELS))
    _, phi_fc = (np.asarray(a) for a in control_sensitivity(pr, T_OFF, T_F, LABELS))
    _, phi_ci = control_sensitivity(pr, T_ON, T_OFF, LABELS)
    x_i = _state(pr, pr.x0, 0.0, T_ON)
    x_c = _state(pr, x_i, T_ON, T_OFF)
    x_f = _state(pr, x_c, T_OFF, T_F)
    a_t = np.asarray(target_jacobian(("a",), x_f, T_F, MU))
    k = a_t @ phi_fc @ s[:, 4:5]
    r, v = x_c[:3], x_c[3:6]
    a_c = 2e-3 * 0.6 * 100.0 / 25.0 / x_c[6]
    a_osc = 1.0 / (2.0 / np.linalg.norm(r) - v @ v / MU)
    gauss = 2.0 * a_osc**2 * np.linalg.norm(v) * a_c / MU
    assert abs(k[0, 0] / gauss - 1.0) < 1e-8
    assert abs(k[0, 0] / (2.0 * a_osc**1.5 * a_c / np.sqrt(MU)) - 1.0) < 1e-4
    lam = a_t @ phi_fc @ np.asarray(phi_ci)
    gamma, rank = weighted_correction_matrix(k, lam)
    assert int(rank) == 1
    dx = np.zeros(7)
    dx[4] = 1e-6  # 1 mm/s along y at t_I: Δa ≈ 0.9 m
    dt_c = float(-(np.asarray(gamma) @ dx)[0])
    a_of = lambda x: 1.0 / (2.0 / np.linalg.norm(x[:3]) - x[3:6] @ x[3:6] / MU)  # noqa: E731
    a_nom = a_of(x_f)
    miss = a_of(_state(pr, x_i + dx, T_ON, T_F)) - a_nom
    corrected = a_of(_state(pr, x_i + dx, T_ON, T_F, _with(pr, LABELS[4], T_OFF + dt_c))) - a_nom
    assert abs(miss) > 1e-4 and abs(corrected) < 1e-3 * abs(miss), (miss, corrected, dt_c)


def test_cost_jacobians_against_repropagation():
    """J_ΔV and J_m (digest (L-4)) against central differences of c ln(m_I/m_c) and of the
    propellant m_I − m_c from re-propagations through the whole arc (decaying power, so
    T_I ≠ T_c; steps 1 s, 1e-4): agree to 1e-6 relative (measured ~1e-8)."""
    decay = 2.0e4
    pr = _problem(decay=decay)
    c = 25.0
    m_i = pr.x0[6]
    t_i, t_c = (2e-3 * 0.6 * 100.0 * np.exp(-t / decay) / c for t in (T_ON, T_OFF))
    m_c = _state(pr, pr.x0, 0.0, T_F)[6]
    controls = ("proportionality", "t_on", "t_off")
    j_dv, j_m = (
        np.asarray(a) for a in correction_cost_jacobians(controls, t_i / m_i, t_c / m_c, m_i, m_c, c, t_i, t_c)
    )
    fd_dv, fd_m = [], []
    for label, h in (("arc_thrust_scale[0]", 1e-4), ("arc_t_on[0]", 1.0), ("arc_t_off[0]", 1.0)):
        v0 = float(np.asarray(get_values(pr.params, (label,), MODEL))[0])
        mp, mm = (_state(pr, pr.x0, 0.0, T_F, _with(pr, label, v0 + d))[6] for d in (h, -h))
        fd_dv.append(c * (np.log(m_i / mp) - np.log(m_i / mm)) / (2 * h))
        fd_m.append(((m_i - mp) - (m_i - mm)) / (2 * h))
    np.testing.assert_allclose(j_dv, fd_dv, rtol=1e-6)
    np.testing.assert_allclose(j_m, fd_m, rtol=1e-6)
    j_all, _ = correction_cost_jacobians(LOW_THRUST_CONTROLS, 1.0, 2.0, 3.0, 2.0, 1.0, 1.0, 1.0)
    assert np.asarray(j_all)[1] == 0.0 and np.asarray(j_all)[2] == 0.0


def test_weighted_correction_matrix_cases():
    """Minimum weighted norm (M > m) against W Kᵀ(K W Kᵀ)⁻¹Λ, weighted least squares (M < m)
    against numpy.linalg.lstsq of E⁻¹K Γ = E⁻¹Λ, square against K⁻¹Λ (1e-12 relative), the
    rank of a deficient K, and impulsive.guidance_matrix = the K = Ψ_v case."""
    rng = np.random.default_rng(3)
    k, lam, w = rng.normal(size=(2, 4)), rng.normal(size=(2, 7)), rng.uniform(0.5, 2.0, 4)
    g, rank = weighted_correction_matrix(k, lam, weights=w)
    ref = np.diag(w) @ k.T @ np.linalg.solve(k @ np.diag(w) @ k.T, lam)
    assert int(rank) == 2 and np.allclose(g, ref, rtol=1e-12, atol=1e-12)
    k2, lam2, tol = rng.normal(size=(5, 3)), rng.normal(size=(5, 7)), rng.uniform(0.5, 2.0, 5)
    g2, rank2 = weighted_correction_matrix(k2, lam2, tolerances=tol)
    ref2 = np.linalg.lstsq(k2 / tol[:, None], lam2 / tol[:, None], rcond=None)[0]
    assert int(rank2) == 3 and np.allclose(g2, ref2, rtol=1e-12, atol=1e-12)
    k3 = rng.normal(size=(3, 3))
    g3, _ = weighted_correction_matrix(k3, lam[:1].repeat(3, 0))
    assert np.allclose(g3, np.linalg.solve(k3, lam[:1].repeat(3, 0)), atol=1e-11)
    _, rank4 = weighted_correction_matrix(np.outer([1.0, 2.0], [1.0, 0.5, 3.0]), lam)
    assert int(rank4) == 1
    psi = rng.normal(size=(2, 7))
    gm = guidance_matrix(psi, weights=w[:3])
    g5, _ = weighted_correction_matrix(psi[:, 3:6], psi, weights=w[:3])
    assert np.array_equal(np.asarray(gm.gamma), np.asarray(g5))


def test_execution_covariance():
    """diag(fraction² diag P_U) + floor² (the fracas choice), independent of the off-diagonals."""
    p_u = np.array([[4.0, 1.0], [1.0, 9.0]])
    out = np.asarray(execution_covariance(("t_on", "t_off"), p_u, fraction=0.1, floor=np.array([0.0, 1.0])))
    assert np.allclose(out, np.diag([0.04, 0.09 + 1.0]))
    with pytest.raises(ValueError):
        execution_covariance(("t_on",), p_u)
