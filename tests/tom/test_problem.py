"""TOM's S = dT/dU and G = dm_f/dU (forward-mode AD through the core) against central finite
differences of the plain core, every column (reference: the propagations themselves).

Tolerance: each S row and G to 1e-5 of the row's largest entry.  The decks integrate at
tolerance 1e-12..1e-13, so a central difference with a relative step of ~1e-5 (1 s for
times) carries ~1e-8 relative rounding noise and O(h^2) truncation below that; measured
agreement is 1e-8..1e-6, so 1e-5 fails on any wrong term (a missing event-time term is O(1)).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fracas.build.tom import build_tom
from fracas.config.tom import parse_tom_deck

ROOT = Path(__file__).resolve().parents[2]


def _case(path: Path, edit=lambda t: t):
    return build_tom(parse_tom_deck(edit(path.read_text(encoding="utf-8")), str(path)))


def _steps(case):
    """1e-5 relative (1e-6 absolute floor) in canonical units; 1 s for times."""
    u = case.u0
    h = np.maximum(np.abs(u), 1.0) * 1e-5
    for j, unit in enumerate(case.control_units):
        if unit == "days":
            h[j] = 1.0
    return h


def _check(case):
    prob = case.problem
    ev, s_ad, g_ad = prob.exact_sensitivities(case.u0)
    assert ev.ok
    _, s_fd, g_fd = prob.fegs(case.u0, steps=_steps(case), central=True)
    scale = np.maximum(np.abs(s_fd).max(axis=1, keepdims=True), 1e-300)
    err = np.abs(s_ad - s_fd) / scale
    assert err.max() < 1e-5, (case.control_names, err)
    if np.abs(g_fd).max() > 0:
        # plus each column's rounding floor: a central difference of m_f carrying ~1e-11 relative
        # noise over a step h_j errs by ~1e-11 m_f / h_j (angle columns, whose true G is 0, show
        # 3e-8 kg/rad at h = 1e-5 rad on a 600 kg spacecraft)
        floor = 1e-11 * abs(ev.performance) / _steps(case)
        assert np.all(np.abs(g_ad - g_fd) < 1e-5 * np.abs(g_fd).max() + floor), (g_ad, g_fd)
    return s_ad, g_ad


@pytest.mark.slow  # DOP853 + thrust + J2 + a located event: the AD program compiles in ~60 s cold
def test_event_stop_every_control_kind_against_central_differences():
    """Two thrust arcs (velocity frame and yaw switch), J2, stopped by r = 7700 km: state,
    arc switch times, a duration, angles, throttle, exhaust velocity and a linked control;
    targets e, i, raan, r.v/|r| and the stop time, so every column carries dt_e/dU."""
    case = _case(ROOT / "tests" / "data" / "tom_fd_radius.toml")
    s_ad, _ = _check(case)
    # the stop time moves with the controls (the event term is present and not small)
    assert np.abs(s_ad[case.target_names.index("final_time")]).max() > 0


@pytest.mark.slow  # ~63 s of a cold make test (mostly XLA compilation; issue 22)
def test_impulses_and_final_time_against_central_differences():
    """Two impulses (one at t = 0, applied by the initial carry), the second one's time, and
    the final time as a control (its column is f(x_f) through the targets)."""

    def edit(t):
        return t.replace(
            '[[control]]\nname = "impulse_t[1]"', '[[control]]\nname = "impulse_t[1]"\n[[control]]\nname = "final_time"'
        )

    case = _case(ROOT / "tests" / "data" / "hohmann_tom.toml", edit)
    assert "final_time" in case.control_names
    s_ad, g_ad = _check(case)
    # rocket equation: m_f = m_0 exp(-(|dv_1| + |dv_2|)/c), so dm_f/d(dv_1x) = -(m_f/c) dv_1x/|dv_1| (c = 3 km/s)
    m_f = case.problem.evaluate(case.u0).performance
    dv1 = np.array([2.35, 0.08, 0.0])
    assert abs(g_ad[0] / (-m_f / 3.0 * dv1[0] / np.linalg.norm(dv1)) - 1.0) < 1e-9


def test_launch_excess_velocity_controls_against_central_differences():
    """v_inf magnitude, right ascension and declination (departure body = the centre)."""

    def edit(t):
        t = t.replace('name = "vx0"', 'name = "vinf"').replace('name = "vy0"', 'name = "vinf_ra"')
        return t.replace('name = "vz0"', 'name = "vinf_dec"')

    case = _case(ROOT / "namelists" / "lambert_tom.toml", edit)
    v0 = np.array([-5.5, 2.2, 3.0])
    assert abs(case.u0[0] - np.linalg.norm(v0)) < 1e-12  # nominal from the deck's velocity
    assert np.allclose(case.problem.controls.x0_of(case.u0)[3:6], v0, rtol=0, atol=1e-12)
    _check(case)


def test_pointing_law_controls_against_central_differences():
    """Two heliocentric arcs with Legendre pointing laws (``ForceModel.steering``): switch
    times, a mean angle and law coefficients P1..P3 of both angles as controls; the laws move
    with the switch times (s is normalised by the arc), so those columns carry that term too."""
    case = _case(ROOT / "tests" / "data" / "tom_fd_steering.toml")
    assert case.problem.model.steering
    s_ad, g_ad = _check(case)
    # every law coefficient moves the targets (the law is in the dynamics, not ignored)
    for j, name in enumerate(case.control_names):
        assert np.abs(s_ad[:, j]).max() > 0, name


@pytest.mark.slow  # ~34 s of a cold make test (mostly XLA compilation; issue 22)
def test_bplane_targets_at_closest_approach(tmp_path):
    """B-plane targeting stopped at closest approach (a located event): S against central
    differences, then the search converges, and the impact parameter of the solution's initial
    state, |B| = |r x v| / v_inf (two-body invariants, computed here in numpy), equals
    sqrt(B.T^2 + B.R^2) of the targets to 1e-6 (the 0.01 km tolerances on 13 400 km)."""
    from fracas.modes.tom import run_tom

    deck = ROOT / "namelists" / "earth_flyby_bplane_tom.toml"
    case = _case(deck)
    _check(case)
    prod, _, _ = run_tom(
        parse_tom_deck(deck.read_text(encoding="utf-8"), str(deck)),
        output=tmp_path / "b.h5",
        reference_deck=tmp_path / "b.toml",
    )
    assert prod.converged and len(prod.iteration) <= 6
    x0 = case.problem.controls.x0_of(prod.u_final * prod.control_factor)
    mu = float(case.base.params.mu[0])
    r, v = x0[:3], x0[3:6]
    v_inf = np.sqrt(v @ v - 2 * mu / np.linalg.norm(r))
    b_mag = np.linalg.norm(np.cross(r, v)) / v_inf
    assert abs(b_mag / np.hypot(12000.0, 6000.0) - 1.0) < 1e-6
