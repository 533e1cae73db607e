"""TEAM's Gauss-Markov thrust noise through a yaw-switch flip (issue 32, item 1a) against an
independent reference: the augmented covariance equation with the saltation matrix at the flip.

The case (tests/data/team_yaw_switch.toml on team_yaw_switch_traj.toml): a circular 1 AU
heliocentric orbit inclined 23.44 deg, 10 kW at 1 AU, efficiency 0.65, c = 30 km/s, one
``velocity_yaw_switch`` arc over 10 days at alpha 0, beta 40 deg; the sign of the
out-of-plane angle follows sign(cos u), u the argument of latitude, and flips once, at
u = 90 deg (3.18 d).  Thrust noise only (proportionality 2 % / 0.5 d, in-plane 1 deg /
0.25 d, out-of-plane 2 deg / 2 d), a zero a priori, no measurements.

The reference (:func:`reference_covariances`) uses no fracas code: the decks are read with
``tomllib`` and the plain equations written out again in numpy,

    r'' = -mu r / r^3 + (T / m) u,   m' = -T / c,   T = (1 + eta_1) 2e-3 eff P0 (AU / r)^2 / c,
    u = [v^, (h x v)^, h^] [cos b cos a, cos b sin a, s sin b],
    a = alpha + eta_2,  b = beta + eta_3,  s = sign(cos u) = sign(h_x r_y - h_y r_x),  h = r x v,

(the noise enters as fracas's thrust-noise labels do, fracas.params.THRUST_NOISE_LABELS:
eta_1 scales the thrust and the mass flow, eta_2 adds to the in-plane angle, eta_3 to the
out-of-plane angle *before* the sign s is applied), the three eta first-order Gauss-Markov
(eta' = -eta / tau + w, spectral density 2 sigma^2 / tau, started stationary), and the
covariance of [dr, dv, dm, eta] carried by P' = F P + P F^T + G Q G^T with F the Jacobian of
that right-hand side by complex-step differentiation (exact to round-off; Squire and
Trapp, SIAM Review 40(1), 1998), integrated with the state by scipy DOP853 (rtol 1e-12).
The flip is located as an event of g = h_x r_y - h_y r_x (scipy's Brent root, to ~1e-15 s
relative) and there P <- S P S^T with the saltation matrix

    S = I + (f+ - f-) g_x^T / (g_x . f-)

(f- and f+ the augmented right-hand side just before and after the flip, g_x the gradient
of g; the eta rows and columns of S are the identity since g does not depend on eta and
the eta dynamics do not switch; Müller, "Calculation of Lyapunov exponents for dynamic
systems with discontinuities", Chaos, Solitons & Fractals 5(9), 1995; Leine and Nijmeijer,
Dynamics and Bifurcations of Non-Smooth Mechanical Systems, Springer 2004).

Tolerances, and why:

* the reference's own transition matrix across the flip (0 to 4 d) against central
  differences of its nonlinear flow: 1e-5 of each column's largest entry (measured 1.5e-6:
  the differences' truncation and the flow's 1e-13 tolerance over the steps); the same
  matrix without the jump misses by more than 1e-2 (measured 6.9e-2), so the check sees
  the jump;
* fracas TEAM's sigma of every state component (x, y, z, vx, vy, vz, mass) and of the noise
  states, at every output time, within 1e-3 of the reference's (the issue's goal; the
  reference is good to ~1e-9, so 1e-3 is the accuracy asked of fracas, not of the
  reference), and the full 7 x 7 state covariance within 1e-3 of sqrt(P_ii P_jj) entrywise
  (measured: 9e-14 and 2e-13 with the noise pieces cut at the flips; 2.4e-3 and 4.8e-3,
  sigma(vz) just after the flip, with the saltation jump in the STM but the quadrature
  pieces straddling the flip);
* the reference without the jump differs from the one with it by more than 5e-2 in some
  sigma after the flip (the issue measured 0.13 in sigma(vz)): a TEAM that forgot the jump
  fails the 1e-3 test by a factor of 50.

The test prints the ratios per output time.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
import tomllib
from scipy.integrate import solve_ivp

DATA = Path(__file__).resolve().parents[1] / "data"
TEAM_DECK = DATA / "team_yaw_switch.toml"

AU_KM = 149_597_870.7  # IAU 2012 Resolution B2
DAY_S = 86_400.0
NX = 7  # r, v, m
NA = NX + 3  # ... and the three thrust-noise states

TOL = 1e-3  # the goal for fracas against the reference
NO_JUMP_MIN = 5e-2  # how far the reference without the jump must be from the one with it
STM_TOL = 1e-5  # the reference's transition matrix against its own flow's differences


# ------------------------------------------------------------------------------ the case
@dataclass(frozen=True)
class Case:
    """The study in km, s, kg, rad, read from the decks with tomllib (no fracas code)."""

    mu: float
    x0: np.ndarray  # (7,)
    p0_kw: float
    eff: float
    c: float
    alpha: float
    beta: float
    t_on: float
    t_off: float
    sigma: np.ndarray  # (3,) proportionality (1), in-plane (rad), out-of-plane (rad)
    tau: np.ndarray  # (3,) s
    times_s: np.ndarray  # output times, 0 first
    P0: np.ndarray  # (7, 7)


def load_case(team_deck: Path = TEAM_DECK) -> Case:
    team = tomllib.loads(team_deck.read_text())
    traj = tomllib.loads((team_deck.parent / team["ertraj"]["deck"]).read_text())
    mu = traj["forces"]["overrides"]["sun"]["mu_km3_s2"]
    el = traj["initial_state"]["elements"]
    assert traj["initial_state"]["centre"] == "sun" and traj["initial_state"]["frame"] == "EME2000"
    assert el["e"] == 0.0 and el["argp_deg"] == 0.0 and el["raan_deg"] == 0.0  # circular, node on x
    a, inc, u = el["a_km"], np.radians(el["i_deg"]), np.radians(el["mean_anomaly_deg"])
    vc = np.sqrt(mu / a)
    r0 = a * np.array([np.cos(u), np.sin(u) * np.cos(inc), np.sin(u) * np.sin(inc)])
    v0 = vc * np.array([-np.sin(u), np.cos(u) * np.cos(inc), np.cos(u) * np.sin(inc)])
    (arc,) = traj["thrust_arc"]
    assert arc["frame"] == "velocity_yaw_switch" and arc.get("throttle", 1.0) == 1.0
    prop = traj["propulsion"]
    assert prop["power_source"] == "solar"
    tn = team["thrust_noise"]
    comps = ("proportionality", "in_plane_deg", "out_of_plane_deg")
    unit = np.array([1.0, np.pi / 180.0, np.pi / 180.0])
    ap = team["a_priori"]
    sig0 = np.concatenate([ap["position_sigma_km"], ap["velocity_sigma_km_s"], [ap["mass_sigma_kg"]]])
    (ev,) = team["event"]
    return Case(
        mu=mu,
        x0=np.concatenate([r0, v0, [traj["spacecraft"]["mass_kg"]]]),
        p0_kw=prop["power_kw"],
        eff=prop["efficiency"],
        c=prop["exhaust_velocity_km_s"],
        alpha=np.radians(arc["alpha_deg"]),
        beta=np.radians(arc["beta_deg"]),
        t_on=arc["start_days"] * DAY_S,
        t_off=arc["stop_days"] * DAY_S,
        sigma=np.array([tn[k]["sigma"] for k in comps]) * unit,
        tau=np.array([tn[k]["tau_days"] for k in comps]) * DAY_S,
        times_s=np.array([0.0, *ev["times_days"]]) * DAY_S,
        P0=np.diag(sig0**2),
    )


# -------------------------------------------------------------------- the plain equations
def _cross(a, b):
    return np.stack(
        [
            a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1],
            a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2],
            a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0],
        ],
        axis=1,
    )


def xdot(case: Case, t: float, X, s: float):
    """Augmented right-hand side, rows of X (B, 10) = (r km, v km/s, m kg, eta), the yaw
    sign s held (+-1).  Complex-safe (no abs, no real-only functions)."""
    r, v, m, eta = X[:, :3], X[:, 3:6], X[:, 6], X[:, 7:]
    rr = np.sum(r * r, axis=1)
    acc = -case.mu * r / (rr * np.sqrt(rr))[:, None]
    mdot = np.zeros_like(m)
    if case.t_on <= t < case.t_off:
        thrust = (1.0 + eta[:, 0]) * 2e-3 * case.eff * case.p0_kw * AU_KM**2 / rr / case.c
        h = _cross(r, v)
        xh = v / np.sqrt(np.sum(v * v, axis=1))[:, None]
        zh = h / np.sqrt(np.sum(h * h, axis=1))[:, None]
        yh = _cross(zh, xh)
        al, be = case.alpha + eta[:, 1], case.beta + eta[:, 2]
        u = (np.cos(be) * np.cos(al))[:, None] * xh + (np.cos(be) * np.sin(al))[:, None] * yh
        u = u + (s * np.sin(be))[:, None] * zh
        acc = acc + (thrust / m)[:, None] * u
        mdot = -thrust / case.c
    return np.concatenate([v, acc, mdot[:, None], -eta / case.tau], axis=1)


def jacobian(case: Case, t: float, y, s: float) -> np.ndarray:
    """d xdot / d [x, eta] (10, 10) by complex steps (one vectorized call)."""
    h = 1e-30 * np.maximum(np.abs(y), 1.0)
    Z = np.tile(y.astype(complex), (NA, 1)) + 1j * np.diag(h)
    return (xdot(case, t, Z, s).imag / h[:, None]).T


def g_yaw(y) -> float:
    """g = h_x r_y - h_y r_x: the node vector z x h dotted with r, |h| r sin i cos u."""
    r, v = y[:3], y[3:6]
    h = np.cross(r, v)
    return h[0] * r[1] - h[1] * r[0]


def g_gradient(y) -> np.ndarray:
    """dg / d[x, eta] (10,), written out from g = v_z (r_x^2 + r_y^2) - r_z (r_x v_x + r_y v_y)."""
    rx, ry, rz, vx, vy, vz = y[:6]
    out = np.zeros(NA)
    out[:6] = [2 * rx * vz - rz * vx, 2 * ry * vz - rz * vy, -(rx * vx + ry * vy), -rz * rx, -rz * ry, rx**2 + ry**2]
    return out


def saltation(case: Case, t: float, y, s_before: float) -> np.ndarray:
    """S = I + (f+ - f-) g_x^T / (g_x . f-) at a flip from sign s_before to -s_before."""
    ya = np.concatenate([y[:NX], np.zeros(3)])[None]  # on the reference: eta = 0
    f_m = xdot(case, t, ya, s_before)[0]
    f_p = xdot(case, t, ya, -s_before)[0]
    gx = g_gradient(y)
    return np.eye(NA) + np.outer(f_p - f_m, gx) / (gx @ f_m)


# ------------------------------------------------------------------------ the integration
def _fly(case: Case, y0, times, rhs, jump, *, rtol=1e-12, atol=None):
    """Integrate y (state first) through ``times``, the flips located as events of s g
    (s the sign held, crossing from + to -), ``jump(t, y, s)`` applied at each; returns
    (y at each time, the flip times)."""
    s = 1.0 if g_yaw(y0) >= 0.0 else -1.0
    y, t = np.array(y0, float), float(times[0])
    quiet_until = -np.inf  # no event check within a minute after a flip (the root itself)
    out, flips = [y.copy()], []
    for tb in times[1:]:
        while t < tb:

            def event(tt, yy, s=s):
                return s * g_yaw(yy)

            event.terminal, event.direction = True, -1.0
            end = min(tb, quiet_until) if t < quiet_until else tb
            sol = solve_ivp(
                lambda tt, yy, s=s: rhs(tt, yy, s),
                (t, end),
                y,
                method="DOP853",
                rtol=rtol,
                atol=atol,
                events=None if t < quiet_until else event,
            )
            assert sol.status >= 0, sol.message
            if sol.status == 1:
                t, y = float(sol.t_events[0][0]), jump(float(sol.t_events[0][0]), sol.y_events[0][0], s)
                flips.append(t)
                s, quiet_until = -s, t + 60.0
            else:
                t, y = end, sol.y[:, -1]
        out.append(y.copy())
    return np.array(out), np.array(flips)


def _scales(case: Case) -> np.ndarray:
    """P is integrated as P / outer(d, d): km, 1e-5 km/s, kg, the noise sigmas."""
    return np.concatenate([[1.0] * 3, [1e-5] * 3, [1.0], case.sigma])


def reference_covariances(case: Case, jump: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """(P (K, 10, 10) of [r, v, m, eta] at ``case.times_s``, the flip times s)."""
    d = _scales(case)
    Qc = np.diag(np.concatenate([np.zeros(NX), 2.0 * case.sigma**2 / case.tau])) / np.outer(d, d)
    P0 = np.zeros((NA, NA))
    P0[:NX, :NX] = case.P0
    P0[NX:, NX:] = np.diag(case.sigma**2)

    def rhs(t, y, s):
        x = np.concatenate([y[:NX], np.zeros(3)])
        F = jacobian(case, t, x, s) * d[None, :] / d[:, None]
        Pt = y[NX:].reshape(NA, NA)
        return np.concatenate([xdot(case, t, x[None], s)[0, :NX], (F @ Pt + Pt @ F.T + Qc).ravel()])

    def flip(t, y, s):
        if not jump:
            return y
        St = saltation(case, t, y, s) * d[None, :] / d[:, None]
        Pt = y[NX:].reshape(NA, NA)
        return np.concatenate([y[:NX], (St @ Pt @ St.T).ravel()])

    atol = np.concatenate([[1e-6] * 3, [1e-12] * 3, [1e-10], np.full(NA * NA, 1e-12)])
    y0 = np.concatenate([case.x0, (P0 / np.outer(d, d)).ravel()])
    ys, flips = _fly(case, y0, case.times_s, rhs, flip, atol=atol)
    return ys[:, NX:].reshape(-1, NA, NA) * np.outer(d, d), flips


def reference_transition(case: Case, t_end: float, jump: bool = True) -> np.ndarray:
    """The augmented transition matrix (10, 10) from 0 to ``t_end`` (variational equations,
    the saltation matrix at each flip when ``jump``)."""

    def rhs(t, y, s):
        x = np.concatenate([y[:NX], np.zeros(3)])
        Phi = y[NX:].reshape(NA, NA)
        return np.concatenate([xdot(case, t, x[None], s)[0, :NX], (jacobian(case, t, x, s) @ Phi).ravel()])

    def flip(t, y, s):
        S = saltation(case, t, y, s) if jump else np.eye(NA)
        return np.concatenate([y[:NX], (S @ y[NX:].reshape(NA, NA)).ravel()])

    atol = np.concatenate([[1e-6] * 3, [1e-12] * 3, [1e-10], np.full(NA * NA, 1e-14)])
    ys, _ = _fly(case, np.concatenate([case.x0, np.eye(NA).ravel()]), [0.0, t_end], rhs, flip, atol=atol)
    return ys[-1, NX:].reshape(NA, NA)


def reference_flow(case: Case, y0, t_end: float) -> np.ndarray:
    """The nonlinear flow of [x, eta] from 0 to ``t_end`` (eta decaying, no noise)."""

    def rhs(t, y, s):
        return xdot(case, t, y[None], s)[0]

    atol = np.concatenate([[1e-7] * 3, [1e-13] * 3, [1e-11], [1e-15] * 3])
    ys, _ = _fly(case, y0, [0.0, t_end], rhs, lambda t, y, s: y, rtol=1e-13, atol=atol)
    return ys[-1]


# ------------------------------------------------------------------------------- the tests
@pytest.fixture(scope="module")
def case() -> Case:
    return load_case()


@pytest.fixture(scope="module")
def reference(case):
    return reference_covariances(case, jump=True)


@pytest.fixture(scope="module")
def fracas_team(tmp_path_factory):
    """fracas TEAM on the deck through its Python entry, read back from the results file."""
    from fracas.io.team_results_read import read_team_results
    from fracas.modes.team import run_team

    out = tmp_path_factory.mktemp("yaw") / "team_yaw_switch.h5"
    _, path, _ = run_team(TEAM_DECK, output=out)
    return read_team_results(path)


def _sigmas(P) -> np.ndarray:
    return np.sqrt(np.einsum("kii->ki", P))


def test_reference_transition_against_finite_differences_of_its_flow(case):
    """The reference's jump is right: its transition matrix across the flip (0 to 4 d) against
    central differences of the nonlinear flow, which flies the flip itself."""
    t_end = 4.0 * DAY_S
    steps = np.array([10.0] * 3 + [1e-5] * 3 + [1e-2] + [1e-5] * 3)
    y0 = np.concatenate([case.x0, np.zeros(3)])
    fd = np.zeros((NA, NA))
    for j, h in enumerate(steps):
        e = np.zeros(NA)
        e[j] = h
        fd[:, j] = (reference_flow(case, y0 + e, t_end) - reference_flow(case, y0 - e, t_end)) / (2 * h)
    col = np.max(np.abs(fd), axis=0)
    err = np.max(np.abs(reference_transition(case, t_end) - fd) / col[None, :])
    err_no_jump = np.max(np.abs(reference_transition(case, t_end, jump=False) - fd) / col[None, :])
    print(f"reference STM vs flow differences: {err:.2e} with the jump, {err_no_jump:.2e} without")
    assert err < STM_TOL
    assert err_no_jump > 1e-2


def test_reference_flip_time_and_the_no_jump_reference_differ(case, reference):
    """One flip, at 3.18 d (the issue's case); the reference without the jump is far from it
    (so a TEAM without the jump cannot pass the comparison below)."""
    P, flips = reference
    assert len(flips) == 1 and abs(flips[0] / DAY_S - 3.18) < 0.01, flips / DAY_S
    P_nj, _ = reference_covariances(case, jump=False)
    r = _sigmas(P_nj[1:, :NX, :NX]) / _sigmas(P[1:, :NX, :NX])
    before = case.times_s[1:] < flips[0]
    print("no-jump / jump sigma ratios after the flip:\n", np.round(r[~before], 4))
    assert np.max(np.abs(r[before] - 1.0)) < 1e-8
    assert np.max(np.abs(r[~before] - 1.0)) > NO_JUMP_MIN


def test_team_sigmas_against_the_saltation_reference(case, reference, fracas_team):
    """fracas TEAM's sigmas (state and noise states) and its state covariance at every output
    time within 1e-3 of the reference (the issue's goal)."""
    P_ref, flips = reference
    res = fracas_team
    assert list(res["labels"][:NA]) == [
        "x", "y", "z", "vx", "vy", "vz", "mass",
        "eta_proportionality", "eta_in_plane_rad", "eta_out_of_plane_rad",
    ]  # fmt: skip
    np.testing.assert_allclose(res["times_s"], case.times_s, rtol=0, atol=1e-6)
    np.testing.assert_allclose(res["states"][0], case.x0, rtol=1e-12)
    P = res["assumed"]["P_plus"][:, :NA, :NA]
    ratio = _sigmas(P[1:]) / _sigmas(P_ref[1:])
    np.set_printoptions(linewidth=160, precision=6, suppress=True)
    print("flip at", flips / DAY_S, "d; fracas / reference sigma by time (d) and component:")
    for t, row in zip(case.times_s[1:] / DAY_S, ratio):
        print(f"{t:6.2f}", row)
    print("worst |ratio - 1|", np.max(np.abs(ratio - 1.0)))
    d = _sigmas(P_ref[1:, :NX, :NX])
    rel = np.abs(P[1:, :NX, :NX] - P_ref[1:, :NX, :NX]) / np.einsum("ki,kj->kij", d, d)
    print("worst covariance entry / sqrt(Pii Pjj)", np.max(rel))
    assert np.max(np.abs(ratio - 1.0)) < TOL
    assert np.max(rel) < TOL
