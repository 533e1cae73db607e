"""PDOT's step follows the dynamics (issue 24, fracas.team.pdot.pdot_step_bounds) against
an independent reference: the covariance ODE dP/dt = F P + P F^T + B q D B^T integrated by
scipy along two-body motion (tests/filters/test_white_noise._cov_ode, DOP853 rtol 1e-12).

Before: the deck's 2.4 h step on a LEO arc (omega h = 4.6, past RK4's stability limit 2.8)
made the covariance grow by 1e9 in 6 h; the issue measured 0.83x / 0.77x at its events.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fracas.build.team import build_study
from fracas.config.team import load_team_deck
from fracas.team.engine import run_study
from fracas.team.pdot import PDOT_OMEGA_STEP, PDOT_TAU_STEP, pdot_step_bounds
from fracas.team.reference import integrate_reference
from tests.filters.test_white_noise import _block_err, _cov_ode
from tests.team.test_white_noise_team import LEO_TEAM, LEO_TRAJ

MU = 398600.4418


def _leo_pdot(tmp: Path, extra: str = ""):
    (tmp / "leo_traj.toml").write_text(LEO_TRAJ.replace("duration_days = 0.03", "duration_days = 0.26"))
    team = LEO_TEAM.replace("times_days = [0.01, 0.02]", "times_days = [0.05, 0.1, 0.15, 0.2, 0.25]")
    team = team.replace("[ertraj]\n", "[ertraj]\n" + extra) + '\n[errcon]\npropagation = "pdot"\n'
    (tmp / "leo_team.toml").write_text(team)
    study = build_study(load_team_deck(tmp / "leo_team.toml"))
    return study, integrate_reference(study)


@pytest.mark.slow  # ~25 s (the scipy references)
def test_leo_pdot_at_default_settings_matches_the_covariance_ode(tmp_path):
    """Two-body LEO (e 0.03, i 30 deg), white crosstrack noise, a priori 0.1-0.3 km: PDOT at
    the deck's defaults against the scipy covariance ODE at events 1.2, 3.6 and 6 h.
    Bound 1e-4 of each 3x3 block's largest element (the issue's goal; measured 3.9e-7,
    5.9e-6, 8.7e-6: RK4's 4th-order error at omega h = 0.015)."""
    study, ref = _leo_pdot(tmp_path)
    res = run_study(study, ref)
    x0, P0 = ref.states[0, :6], study.P0_assumed[:6, :6]
    for k in (1, 3, 5):
        P = _cov_ode(x0, float(ref.times_s[k]), 1e-10, "crosstrack", P0)
        assert _block_err(res.Pa_minus[k][:6, :6], P) < 1e-4, k


def test_step_bounds_follow_the_orbit_and_the_noise(tmp_path):
    """The cap: PDOT_OMEGA_STEP / sqrt(mu / r^3) on the LEO arc (the deck's 2.4 h is far
    above it), and the deck's step when that is smaller; PDOT_TAU_STEP tau with
    Gauss-Markov noise (arithmetic of the rule, not a reference check)."""
    study, ref = _leo_pdot(tmp_path)
    h = pdot_step_bounds(study, ref)
    r = np.linalg.norm(ref.states[:, :3], axis=1)
    omega = np.sqrt(MU / r**3)
    np.testing.assert_allclose(h, PDOT_OMEGA_STEP / np.maximum(omega[1:], omega[:-1]), rtol=1e-12)
    assert np.all(h < 20.0)  # seconds, against the deck's 8640
    fine, _ = _leo_pdot(tmp_path, "pdot_step_hours = 0.001\n")
    np.testing.assert_allclose(pdot_step_bounds(fine, ref), 3.6, rtol=1e-12)
    import dataclasses

    gm = dataclasses.replace(
        study, noise_sigma_assumed=np.array([0.01, 0.0, 0.0]), noise_tau_assumed=np.array([60.0, 1e9, 1e9])
    )
    np.testing.assert_allclose(pdot_step_bounds(gm, ref), np.minimum(h, PDOT_TAU_STEP * 60.0), rtol=1e-12)


def test_results_file_and_printout_state_the_noise_applied(tmp_path):
    """The issue's complaint: PDOT printed "process noise 0..0" with white noise on.  The
    results file records the model (white q and direction, Gauss-Markov sigma and tau by
    component, PDOT's RK4 steps) and the report prints it (compared with the deck's values)."""
    from fracas.io.team_results import read_team_results, write_team_results
    from fracas.report.team import process_noise_line
    from fracas.team.result import team_product

    study, ref = _leo_pdot(tmp_path)
    res = run_study(study, ref)
    path = tmp_path / "r.h5"
    write_team_results(path, team_product(res, reference_source="integrated"))
    at = read_team_results(path)["attrs"]
    assert at["process_noise"] == "pdot"
    assert at["white_noise_km2_s3"] == 1e-10 and at["white_noise_direction"] == "crosstrack"
    steps = np.diff(ref.times_s)
    n = np.ceil(steps / pdot_step_bounds(study, ref) - 1e-9)
    assert at["pdot_step_min_s"] == pytest.approx(np.min(steps / n), rel=1e-12)
    assert at["pdot_step_max_s"] == pytest.approx(np.max(steps / n), rel=1e-12)
    line = process_noise_line(at)
    assert "white 1e-10 km²/s³ crosstrack" in line and "(PDOT steps" in line
    # Gauss-Markov components by name, in deck units
    at2 = dict(at, thrust_noise_sigma=[0.02, np.radians(0.5), 0.0], thrust_noise_tau_s=[43200.0, 86400.0, 1.0])
    line2 = process_noise_line(at2)
    assert "thrust 1σ/τ: scale 0.02/0.5 d, in 0.5°/1 d;" in line2
    assert "out " not in line2
    # three components alone fit one 80-column line of the report
    at3 = dict(at2, thrust_noise_sigma=[0.02, 0.01, 0.01], white_noise_km2_s3=0.0, process_noise="grid")
    assert len(process_noise_line(at3)) <= 80, process_noise_line(at3)
