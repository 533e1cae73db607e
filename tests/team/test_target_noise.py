"""TEAM's target covariances at the target time (issue 32): the dispersion a guidance event
predicts at its targets carries the process noise from the event's cutoff to the target
time, not only the control covariance at the cutoff mapped by Ψ (GUIDM's P_T = Ψ P_c Ψᵀ,
digest (G-8)).

Reference here: a scipy integration, with no fracas code, of the two-body motion and the
covariance equation dP/dt = F P + P Fᵀ + q B Bᵀ (white acceleration noise on the velocity)
on a LEO arc with an impulsive correction at t_c aimed at the position at t_f.  The
engine's own control covariance after the correction is the reference's starting point
(the correction's algebra has its own tests, tests/team/test_guidance_engine.py); the
reference carries it, and the a priori before it, to t_f.

The Gauss-Markov thrust-noise case (TEAM's own state σ at the target time, and TSIM's
verdict) is in tests/tsim/test_target_noise_tsim.py.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from fracas.build.team import build_study
from fracas.config.team import load_team_deck
from fracas.team.engine import run_study
from fracas.team.reference import integrate_reference
from tests.team.test_white_noise_team import LEO_TRAJ  # the two-body LEO arc of the white-noise TEAM test

MU = 398600.4418  # km^3/s^2, the deck's override: the reference's two-body force
DAY = 86400.0
Q = 1e-10  # km^2/s^3: white acceleration noise, "full" direction (q I on the velocity)
T_C, T_F = 0.005 * DAY, 0.03 * DAY

LEO_TEAM = """
mode = "team"
title = "a correction on a LEO arc with white noise after it"
[ertraj]
deck = "leo_traj.toml"
[a_priori]
position_sigma_km = [0.1, 0.2, 0.3]
velocity_sigma_km_s = [1e-4, 2e-4, 3e-4]
[process_noise]
white_acceleration_km2_s3 = 1e-10
direction = "full"
quadrature_step_hours = 0.02
[[guidance]]
name = "tcm"
type = "impulsive"
time_days = 0.005
targets = ["x", "y", "z"]
target_time_days = 0.03
"""


def _two_body(x: np.ndarray) -> np.ndarray:
    r, v = x[:3], x[3:6]
    return np.concatenate([v, -MU * r / np.linalg.norm(r) ** 3])


def _gravity_gradient(r: np.ndarray) -> np.ndarray:
    rn = np.linalg.norm(r)
    return MU * (3.0 * np.outer(r, r) / rn**5 - np.eye(3) / rn**3)


def _covariance(x0: np.ndarray, P0: np.ndarray, t0: float, t1: float, q: float) -> tuple[np.ndarray, np.ndarray]:
    """(x(t1), P(t1)) from (x0, P0) at t0: dP/dt = F P + P Fᵀ + q B Bᵀ along two-body motion
    (DOP853, rtol 1e-12; the covariance's atol at 1e-14 of its own scale, floored for P ≡ 0)."""
    F = np.zeros((6, 6))
    F[:3, 3:] = np.eye(3)
    Qc = np.zeros((6, 6))
    Qc[3:, 3:] = q * np.eye(3)

    def rhs(_t, y):
        F[3:, :3] = _gravity_gradient(y[:3])
        P = y[6:].reshape(6, 6)
        return np.concatenate([_two_body(y[:6]), (F @ P + P @ F.T + Qc).ravel()])

    dt = t1 - t0
    s = np.sqrt(np.array([q * dt**3] * 3 + [q * dt] * 3) + np.diag(P0))
    atol = np.concatenate([np.full(6, 1e-12), np.maximum(1e-14 * np.outer(s, s).ravel(), 1e-30)])
    y0 = np.concatenate([x0, np.ravel(P0)])
    sol = solve_ivp(rhs, (t0, t1), y0, rtol=1e-12, atol=atol, method="DOP853")
    return sol.y[:6, -1], sol.y[6:, -1].reshape(6, 6)


@pytest.fixture(scope="module")
def leo(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("leo_target")
    (tmp / "leo_traj.toml").write_text(LEO_TRAJ)
    (tmp / "leo_team.toml").write_text(LEO_TEAM)
    study = build_study(load_team_deck(tmp / "leo_team.toml"))
    ref = integrate_reference(study)
    return study, ref, run_study(study, ref)


def _rel(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))


def test_target_covariance_against_scipy_covariance_equation(leo):
    """After: the engine's P_c⁺ at t_c carried to t_f by the covariance equation with the
    white noise, its position block against the event's target covariance; before: the a
    priori carried from 0 to t_c and on to t_f, the same way; noise: from P = 0 at t_c.
    Tolerance 1e-8 of the largest element: the engine's Φ (RKN at tolerance 1e-13) and its
    noise integral (4-point Gauss-Legendre on 72 s pieces, exact to degree 7) against a
    DOP853 solution at rtol 1e-12 (the same bound as tests/team/test_white_noise_team.py);
    leaving out the noise after t_c misses by ~0.8 of the variance here."""
    study, ref, res = leo
    g = res.guidance[0]
    k = g.index
    assert abs(ref.times_s[k] - T_C) < 1e-6 and abs(g.target_time_s - T_F) < 1e-6
    x0 = np.asarray(ref.states[0, :6], dtype=np.float64)
    x_c, p_minus = _covariance(x0, np.asarray(study.P0_true)[:6, :6], 0.0, T_C, Q)
    _, after = _covariance(x_c, np.asarray(res.control[k])[:6, :6], T_C, T_F, Q)
    _, before = _covariance(x_c, p_minus, T_C, T_F, Q)
    _, noise = _covariance(x_c, np.zeros((6, 6)), T_C, T_F, Q)
    assert _rel(g.target_cov_after, after[:3, :3]) < 1e-8
    assert _rel(g.target_cov_before, before[:3, :3]) < 1e-8
    assert _rel(g.target_noise_cov, noise[:3, :3]) < 1e-8
    # the noise matters here: GUIDM's mapping from t_c alone is far off
    assert _rel(g.target_cov_after - g.target_noise_cov, after[:3, :3]) > 0.1


def test_knowledge_mapped_without_noise(leo):
    """The knowledge mapped to the target stays Ψ P_k Ψᵀ (the navigation error the correction
    is designed from, no noise after it): the engine's P_k at t_c carried to t_f with q = 0
    by the scipy reference, 1e-8 as above."""
    study, ref, res = leo
    g = res.guidance[0]
    k = g.index
    x0 = np.asarray(ref.states[0, :6], dtype=np.float64)
    x_c, _ = _covariance(x0, np.zeros((6, 6)), 0.0, T_C, 0.0)
    p_minus = res.Pt_minus if res.Pt_minus is not None else res.Pa_minus  # before Σ_ex joins it
    p_k = np.asarray(p_minus[k])[:6, :6]
    _, know = _covariance(x_c, p_k, T_C, T_F, 0.0)
    assert _rel(g.target_cov_knowledge, know[:3, :3]) < 1e-8


def test_budget_books_the_noise_after_the_cutoff_to_process_noise(leo):
    """Linearity of the error budget with the target noise in (white noise included): the
    shares sum to the run's variance (1e-10, round-off), and the process-noise source holds
    at least the noise after the cutoff of each target's variance."""
    _, _, res = leo
    b = res.budget
    g = res.guidance[0]
    assert b.sum_check < 1e-10
    j = b.sources.index("process noise")
    for i, t in enumerate(g.target_names):
        row = b.outputs.index(f"tcm {t} after")
        assert b.total[row] == pytest.approx(g.target_cov_after[i, i], rel=1e-12)
        assert b.variance[row, j] >= g.target_noise_cov[i, i] * (1.0 - 1e-9)


def test_results_file_carries_the_target_noise(leo, tmp_path):
    """The file's guidance group holds target_noise_cov beside before/after, read back
    unchanged; a file without it (written before it existed) reads as None."""
    import h5py

    from fracas.io.team_results import read_team_results, write_team_results
    from fracas.team.result import team_product

    _, _, res = leo
    p = tmp_path / "r.h5"
    write_team_results(p, team_product(res, reference_source="memory"))
    g = read_team_results(p)["guidance"][0]
    np.testing.assert_array_equal(g["target_noise_cov"], res.guidance[0].target_noise_cov)
    np.testing.assert_array_equal(g["target_cov_after"], res.guidance[0].target_cov_after)
    with h5py.File(p, "r+") as f:  # an older file (the integrity header is not checked here)
        del f["team/guidance/000/target_noise_cov"]
    from fracas.io.hdf5 import Checked
    from fracas.io.team_results_read import _read_guidance

    with h5py.File(p, "r") as f:
        old = _read_guidance(Checked(f, p, RuntimeError, verify=False), f["team"], res.guidance[0].psi.shape[1])
    assert old[0]["target_noise_cov"] is None
