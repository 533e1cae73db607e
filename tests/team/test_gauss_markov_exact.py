"""TEAM's Gauss-Markov thrust noise (issue 24) against the augmented covariance equation.

Reference (written here; no fracas numerics): the plain heliocentric equations with solar
electric thrust (tests/reference.py's thrust model, written again vectorized; Sun only), the three thrust errors eta as
first-order Gauss-Markov states (proportionality, in-plane and out-of-plane pointing),
F = [[A, h], [0, -1/tau]] with A = d xdot / dx and h = d xdot / d eta by central finite
differences of that right-hand side, and P' = F P + P F^T + Qc (Qc = 2 sigma^2 / tau on the
eta diagonal) integrated with the state by scipy DOP853 at rtol 1e-11, from the study's a
priori with eta stationary.

The issue's case: no measurements, a 1e-3 km / 1e-9 km/s a priori, proportionality sigma
0.01 (tau 0.5 d), in-plane 0.5 deg (0.25 d), out-of-plane 0.5 deg (1 d), over 4 days of
thrust.  Checked: PHI (default, the exact model) and PDOT (default step) within 1 +- 1e-3
of the reference in every position, velocity and mass sigma at every output time (the
goal); the noise states' own block too.  Events at odd times (0.37 d, 1.61 d) are in the
schedule, so intervals of several lengths are composed.  The finite differences are good
to ~1e-8 relative and the ODE to ~1e-10: the 1e-3 goal is the tolerance, and the test
prints the measured worst ratio.  The DYNO models' ratios are printed for the record
(they are the approximation the issue measured off by factors; not asserted here).

The 100-day cruise (tau 0.25 to 10 d, a coast in the middle) is in the slow subset.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from fracas.build.team import build_study
from fracas.config.team import load_team_deck
from fracas.team.engine import run_study
from fracas.team.reference import integrate_reference
from tests.reference import AU

DAY = 86400.0
MU_SUN = 132712440018.0

TRAJ = """
title = "SEP heliocentric arc, Sun only"
[epoch]
iso = "2028-10-01T00:00:00"
[initial_state]
centre = "sun"
frame = "EME2000"
[initial_state.cartesian]
r_km = [149814963.0, 19186168.0, 8315369.0]
v_km_s = [-4.761470, 27.864334, 12.077752]
[spacecraft]
mass_kg = 1000.0
[propulsion]
power_source = "solar"
power_kw = 10.0
efficiency = 0.65
exhaust_velocity_km_s = 30.0
{arcs}
[forces.overrides.sun]
mu_km3_s2 = 132712440018.0
[integrator]
tolerance = 1e-12
[stop]
duration_days = {days}
"""

ARC = """
[[thrust_arc]]
start_days = {a}
stop_days = {b}
frame = "velocity"
alpha_deg = 20.0
beta_deg = 10.0
"""

TEAM = """
mode = "team"
title = "Gauss-Markov thrust noise, no measurements"
[errcon]
propagation = "{prop}"
process_noise = "{model}"
[ertraj]
deck = "traj.toml"
[filter]
stop_days = {days}
[a_priori]
position_sigma_km = [1e-3, 1e-3, 1e-3]
velocity_sigma_km_s = [1e-9, 1e-9, 1e-9]
mass_sigma_kg = 1e-3
[thrust_noise]
proportionality = {{ sigma = 0.01, tau_days = {t0} }}
in_plane_deg = {{ sigma = 0.5, tau_days = {t1} }}
out_of_plane_deg = {{ sigma = 0.5, tau_days = {t2} }}
[[event]]
type = "propagation"
times_days = {times}
[budget]
enabled = false
"""


def _study(tmp: Path, days, arcs, taus, times, prop="phi", model="exact"):
    (tmp / "traj.toml").write_text(TRAJ.format(arcs="".join(ARC.format(a=a, b=b) for a, b in arcs), days=days))
    name = f"team_{prop}_{model}.toml"
    (tmp / name).write_text(
        TEAM.format(prop=prop, model=model, days=days, t0=taus[0], t1=taus[1], t2=taus[2], times=list(times))
    )
    return build_study(load_team_deck(tmp / name))


def _xdot(t, X, eta, on):
    """Plain heliocentric equations with solar electric thrust, vectorized over rows of
    X (B, 7) = (r km, v km/s, m kg) and eta (B, 3): two-body Sun gravity; thrust
    T = (1 + eta_0) 2 eff P / c with P = P0 (1 AU / r)^2 (tests/reference.py's model),
    along the velocity frame (x = v^, z = (r x v)^, y = z x x) at in-plane angle
    alpha + eta_1 and out-of-plane angle beta + eta_2; mdot = -T / c."""
    r, v, m = X[:, :3], X[:, 3:6], X[:, 6]
    rn = np.linalg.norm(r, axis=1)
    a = -MU_SUN * r / rn[:, None] ** 3
    mdot = np.zeros(len(X))
    if any(lo <= t < hi for lo, hi in on):
        p_kw = 10.0 * AU**2 / rn**2
        tm = (1.0 + eta[:, 0]) * 2e-3 * 0.65 * p_kw / 30.0
        x = v / np.linalg.norm(v, axis=1)[:, None]
        h = np.cross(r, v)
        z = h / np.linalg.norm(h, axis=1)[:, None]
        y = np.cross(z, x)
        al, be = np.radians(20.0) + eta[:, 1], np.radians(10.0) + eta[:, 2]
        u = (np.cos(be) * np.cos(al))[:, None] * x + (np.cos(be) * np.sin(al))[:, None] * y + np.sin(be)[:, None] * z
        a = a + (tm / m)[:, None] * u
        mdot = -tm / 30.0
    return np.concatenate([v, a, mdot[:, None]], axis=1)


def _augmented_reference(study, arcs, t_out):
    """P (len(t_out), nx + 3, nx + 3) of [x, eta] from the augmented covariance equation."""
    nx, k = study.nx, 3
    n = nx + k
    sig = np.asarray(study.noise_sigma_assumed, float)
    tau = np.asarray(study.noise_tau_assumed, float)
    on = [(a * DAY, b * DAY) for a, b in arcs]
    # central differences: states (7 +- steps) and eta (3 +- 1e-6), one vectorized call
    dx = np.array([1.0, 1.0, 1.0, 1e-6, 1e-6, 1e-6, 1e-3])
    de = 1e-6
    D = np.concatenate([np.diag(dx), -np.diag(dx), np.zeros((2 * k, 7))])
    E = np.concatenate([np.zeros((14, k)), de * np.eye(k), -de * np.eye(k)])
    # scaled covariance: P = S Pt S with S = diag(1 km, 1e-5 km/s, 1 kg, sigma)
    s = np.concatenate([[1.0] * 3, [1e-5] * 3, [1.0][: nx - 6], sig])
    Qc = np.diag(np.concatenate([np.zeros(nx), 2.0 * sig**2 / tau])) / np.outer(s, s)

    def rhs(t, y):
        x = y[:7]
        Pt = y[7:].reshape(n, n)
        f = _xdot(t, np.concatenate([x[None], x[None] + D]), np.concatenate([np.zeros((1, k)), E]), on)
        F = np.zeros((n, n))
        F[:nx, :nx] = ((f[1:8] - f[8:15]) / (2 * dx)[:, None]).T[:nx, :nx]
        F[:nx, nx:] = ((f[15 : 15 + k] - f[15 + k :]) / (2 * de)).T[:nx]
        F[nx:, nx:] = -np.diag(1.0 / tau)
        Ft = F * s[None, :] / s[:, None]
        return np.concatenate([f[0], (Ft @ Pt + Pt @ Ft.T + Qc).ravel()])

    P0 = np.zeros((n, n))
    P0[:nx, :nx] = study.P0_assumed[:nx, :nx]
    P0[nx:, nx:] = np.diag(sig**2)
    y = np.concatenate([study.problem.x0, (P0 / np.outer(s, s)).ravel()])
    breaks = sorted({0.0, *[t for ab in on for t in ab], *t_out})
    out = {}
    for ta, tb in zip(breaks[:-1], breaks[1:]):
        if tb > ta:
            sol = solve_ivp(rhs, (ta, tb), y, method="DOP853", rtol=1e-11, atol=1e-13)
            assert sol.success, sol.message
            y = sol.y[:, -1]
        out[tb] = y[7:].reshape(n, n) * np.outer(s, s)
    return np.array([out.get(t, P0) for t in t_out])


def _ratios(res, P_ref, nx):
    """sigma ratios (K, nx + 3) of the run's [x, eta] block against the reference (the
    initial time excluded), and position-RSS ratios (K,)."""
    n = res.study.layout.n
    idx = list(range(nx)) + ([n, n + 1, n + 2] if res.noise_states else [])
    P = res.Pa_plus[:, idx][:, :, idx]
    got = np.sqrt(np.einsum("kii->ki", P))[1:]
    want = np.sqrt(np.einsum("kii->ki", P_ref[:, : len(idx), : len(idx)]))[1:]
    rss = np.sqrt(np.trace(P[1:, :3, :3], axis1=1, axis2=2) / np.trace(P_ref[1:, :3, :3], axis1=1, axis2=2))
    return got / want, rss


ISSUE_TIMES = [0.25, 0.37, 1.0, 1.61, 2.0, 3.0, 4.0]
ISSUE_TAUS = (0.5, 0.25, 1.0)
ISSUE_ARCS = [(0.0, 4.0)]


@pytest.fixture(scope="module")
def issue_case(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("gm")
    study = _study(tmp, 4.0, ISSUE_ARCS, ISSUE_TAUS, ISSUE_TIMES)
    ref = integrate_reference(study)
    t = np.asarray(ref.times_s)
    return tmp, study, ref, _augmented_reference(study, ISSUE_ARCS, t)


def test_phi_exact_default_against_augmented_covariance_ode(issue_case):
    tmp, study, ref, P_ref = issue_case
    assert study.noise_model == "exact"  # the default
    res = run_study(study, ref)
    assert res.noise_states
    r, rss = _ratios(res, P_ref, study.nx)
    print("PHI exact: worst sigma ratio - 1 =", np.max(np.abs(r - 1)), " position RSS", rss)
    assert np.max(np.abs(r - 1.0)) < 1e-3
    assert np.max(np.abs(rss - 1.0)) < 1e-3


def test_pdot_default_against_augmented_covariance_ode(issue_case):
    tmp, study, ref, P_ref = issue_case
    st = _study(tmp, 4.0, ISSUE_ARCS, ISSUE_TAUS, ISSUE_TIMES, prop="pdot")
    res = run_study(st, ref)
    r, rss = _ratios(res, P_ref, study.nx)
    print("PDOT: worst sigma ratio - 1 =", np.max(np.abs(r - 1)), " position RSS", rss)
    assert np.max(np.abs(r - 1.0)) < 1e-3
    assert np.max(np.abs(rss - 1.0)) < 1e-3


def test_dyno_models_still_run_and_differ(issue_case):
    """FRACAS DYNO (named options): they run, and on this case they are far from the
    reference (the issue's measurement: the reason the default changed); printed."""
    tmp, study, ref, P_ref = issue_case
    for model in ("grid", "interval"):
        st = dataclasses.replace(study, noise_model=model)
        res = run_study(st, integrate_reference(st))
        assert not res.noise_states
        r, rss = _ratios(res, P_ref, study.nx)
        print(f"DYNO {model}: position RSS ratio by time", np.round(rss, 3))
        assert np.max(np.abs(rss - 1.0)) > 0.05


def test_exact_model_ignores_event_times(issue_case):
    """The pieces compose exactly: a schedule without the odd events gives the same
    covariances at the common times (to the integration's round-off, 1e-9)."""
    tmp, study, ref, P_ref = issue_case
    sub = tmp / "fewer"
    sub.mkdir(exist_ok=True)
    st = _study(sub, 4.0, ISSUE_ARCS, ISSUE_TAUS, [1.0, 4.0])
    r1 = run_study(st, integrate_reference(st))
    r0 = run_study(study, ref)
    for t in (1.0, 4.0):
        k0 = int(np.argmin(np.abs(r0.times_s - t * DAY)))
        k1 = int(np.argmin(np.abs(r1.times_s - t * DAY)))
        a, b = r0.Pa_plus[k0], r1.Pa_plus[k1]
        d = np.sqrt(np.outer(np.diag(a), np.diag(a)))
        assert np.max(np.abs(a - b) / np.where(d > 0, d, 1)) < 1e-9


CRUISE_TAUS = (0.25, 2.0, 10.0)
CRUISE_ARCS = [(0.0, 40.0), (45.0, 100.0)]
CRUISE_TIMES = [0.25, 1.0, 5.0, 20.0, 40.0, 42.5, 45.0, 60.0, 80.0, 100.0]


@pytest.mark.slow  # ~5 min: the reference ODE over 400 correlation times (phi 1.1e-9, pdot 6e-7 measured)
def test_cruise_100_days_against_augmented_covariance_ode(tmp_path):
    study = _study(tmp_path, 100.0, CRUISE_ARCS, CRUISE_TAUS, CRUISE_TIMES)
    ref = integrate_reference(study)
    P_ref = _augmented_reference(study, CRUISE_ARCS, np.asarray(ref.times_s))
    for prop in ("phi", "pdot"):
        st = study if prop == "phi" else _study(tmp_path, 100.0, CRUISE_ARCS, CRUISE_TAUS, CRUISE_TIMES, prop="pdot")
        res = run_study(st, ref)
        r, rss = _ratios(res, P_ref, study.nx)
        print(prop, "worst sigma ratio - 1 =", np.max(np.abs(r - 1)))
        assert np.max(np.abs(r - 1.0)) < 1e-3
