"""Target values, A_T, Ψ = A_T Φ and TARPRL's element partials (FRACAS TARMAT, TARPRL).

Independent references: fracas.dynamics.bplane.b_plane (B-plane values), a scipy DOP853
two-body integration to periapsis located by an event function (closest approach radius and
time), central finite differences of target_values (A_T), of re-propagated fracas
trajectories (Ψ, Ψ_p) and of elements_to_cartesian (TARPRL).  Float64 throughout.
"""

from __future__ import annotations

import subprocess
import sys

import jax
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from fracas.dynamics.bplane import b_plane
from fracas.dynamics.elements import cartesian_to_elements, elements_to_cartesian
from fracas.dynamics.model import ForceModel, IntegratorSettings, default_params
from fracas.dynamics.parameters import set_values
from fracas.guidance.target_kinds import TARGET_KINDS, check_targets, target_unit
from fracas.guidance.targets import element_position_partials, target_jacobian, target_matrix, target_values
from fracas.integrate.propagate import propagate, propagate_with_sensitivities

MU = 398600.4418
# every target with a state Jacobian (final_time is t_f itself: its row is zero by definition,
# tested in tests/tom/test_problem.py through the stop event)
ALL = tuple(n for n in TARGET_KINDS if n != "final_time")
# approaching hyperbola (r·v < 0, e ≈ 1.6) and an ellipse before periapsis (r·v < 0)
HYP = np.array([-60000.0, 25000.0, 8000.0, 5.0, -1.5, -0.6])
ELL = np.array([9000.0, -3000.0, 1500.0, -2.0, 6.4, 1.5])
NAMES = (
    "b_dot_t b_dot_r time_of_flight closest_approach_radius closest_approach_time x y z vx vy vz a e i raan argp M"
    " radius speed radial_velocity e_cos_argp e_sin_argp vinf vinf_x vinf_y vinf_z final_time"
).split()


def test_catalogue():
    """The catalogue holds exactly the brief's names; units; unknown names raise KeyError."""
    assert list(TARGET_KINDS) == NAMES
    assert target_unit("b_dot_t") == "km" and target_unit("time_of_flight") == "s" and target_unit("e") == "1"
    with pytest.raises(KeyError, match="b_dot_t"):
        check_targets(["a", "bdott"])
    code = "import sys, fracas.guidance.target_kinds; print('jax' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "False"


def test_bplane_targets_equal_b_plane():
    """b_dot_t, b_dot_r equal fracas.dynamics.bplane.b_plane (same function, exact to 1e-12 rel)."""
    bp = b_plane(HYP[:3], HYP[3:], MU)
    val = np.asarray(target_values(("b_dot_t", "b_dot_r"), HYP, 0.0, MU))
    np.testing.assert_allclose(val, [bp.b_dot_t, bp.b_dot_r], rtol=1e-12)


def _scipy_periapsis(state):
    """Two-body DOP853 (rtol = atol = 1e-13) to the first r·v = 0 crossing upward."""

    def f(_, y):
        r = y[:3]
        return np.concatenate([y[3:], -MU * r / np.linalg.norm(r) ** 3])

    def ev(_, y):
        return np.dot(y[:3], y[3:])

    ev.terminal, ev.direction = True, 1.0
    sol = solve_ivp(f, (0.0, 1e6), state, method="DOP853", rtol=1e-13, atol=1e-13, events=ev)
    t_p = sol.t_events[0][0]
    return t_p, np.linalg.norm(sol.y_events[0][0][:3])


@pytest.mark.parametrize("state", [HYP, ELL], ids=["hyperbola", "ellipse"])
def test_closest_approach_against_integrated_periapsis(state):
    """closest_approach_radius/time and time_of_flight against the numerically integrated
    periapsis (independent of fracas's conic code): agree to 1e-9 relative (measured ~1e-12;
    the event location is at the integrator's 1e-13 tolerance)."""
    t_f = 1234.0
    vals = np.asarray(
        target_values(("closest_approach_radius", "closest_approach_time", "time_of_flight"), state, t_f, MU)
    )
    t_p, r_p = _scipy_periapsis(state)
    np.testing.assert_allclose(vals[0], r_p, rtol=1e-9)
    np.testing.assert_allclose(vals[1], t_f + t_p, rtol=1e-9)
    assert vals[2] == vals[1]


@pytest.mark.parametrize("state", [HYP, ELL], ids=["hyperbola", "ellipse"])
def test_target_jacobian_against_central_differences(state):
    """A_T by AD against central differences of target_values for every target (B-plane on the
    hyperbola only).  Steps 1e-2 km, 1e-5 km/s: truncation (h/|r|)², (h/|v|)² < 1e-10,
    roundoff eps|T|/h < 1e-7 of each row's scale; tolerance 1e-6 of the row's max |entry|."""
    names = ALL if state is HYP else tuple(n for n in ALL if not n.startswith(("b_dot", "vinf")))
    a_t = np.asarray(target_jacobian(names, state, 0.0, MU))
    assert a_t.shape == (len(names), 7) and np.all(a_t[:, 6] == 0.0)
    fd = np.zeros((len(names), 6))
    for j, h in enumerate([1e-2] * 3 + [1e-5] * 3):
        e = np.zeros(6)
        e[j] = h
        fd[:, j] = (np.asarray(target_values(names, state + e, 0.0, MU)) - target_values(names, state - e, 0.0, MU)) / (
            2 * h
        )
    err = np.abs(a_t[:, :6] - fd).max(axis=1) / np.abs(fd).max(axis=1)
    assert err.max() < 1e-6, dict(zip(names, err))


EL0 = np.array([12000.0, 0.35, 0.6, 1.1, 2.3, 4.0])  # a km, e, i, Ω, ω, M rad


def _cart(el):
    r, v = elements_to_cartesian(el, MU)
    return np.concatenate([r, v])


def test_element_targets_are_the_inverse_map():
    """d(elements)/d(cartesian) by AD equals inv(d(cartesian)/d(elements)) to 1e-9 relative
    (both AD; the round trip is exact, so this is conditioning-limited)."""
    x = _cart(EL0)
    d_el = np.asarray(jax.jacfwd(lambda s: cartesian_to_elements(s[:3], s[3:], MU))(x))
    d_cart = np.asarray(jax.jacfwd(lambda e: jax.numpy.concatenate(elements_to_cartesian(e, MU)))(EL0))
    inv = np.linalg.inv(d_cart)
    assert np.abs(d_el - inv).max() / np.abs(inv).max() < 1e-9
    a_t = np.asarray(target_jacobian(("a", "e", "i", "raan", "argp", "M"), x, 0.0, MU))[:, :6]
    assert np.abs(a_t - inv).max() / np.abs(inv).max() < 1e-9


def test_tarprl_closed_forms_and_the_scan_errors():
    """TARPRL's position partials (digest B.5, scan errors fixed) against central differences
    of elements_to_cartesian (steps 1e-3 km, 1e-7 in e and angles; tolerance 1e-7 of the
    column's size, measured ~1e-10), and against AD; the printed q = r[r − a − ae²(1 + sin²ν)]
    /(ae(1 − e²)) and printed s = ae sin ν/(1 − e²)² give ∂X/∂e, ∂X/∂M that fail FD by > 1 %."""
    p = np.asarray(element_position_partials(EL0, MU))
    fd = np.zeros((3, 6))
    for j, h in enumerate([1e-3, 1e-7, 1e-7, 1e-7, 1e-7, 1e-7]):
        e = np.zeros(6)
        e[j] = h
        fd[:, j] = (_cart(EL0 + e)[:3] - _cart(EL0 - e)[:3]) / (2 * h)
    err = np.abs(p - fd).max(axis=0) / np.abs(fd).max(axis=0)
    assert err.max() < 1e-7, err
    ad = np.asarray(jax.jacfwd(lambda e: elements_to_cartesian(e, MU)[0])(EL0))
    assert np.abs(p - ad).max() / np.abs(ad).max() < 1e-12
    # the scan's q and s, substituted into the same forms
    a, ecc = EL0[0], EL0[1]
    x = _cart(EL0)[:3]
    r = np.linalg.norm(x)
    el_c = np.asarray(cartesian_to_elements(x, _cart(EL0)[3:], MU))
    nu = float(jax.numpy.arctan2(*_sin_cos_nu(EL0)))
    q_ok, q_printed = -a * np.cos(nu), r / (a * ecc * (1 - ecc**2)) * (r - a - a * ecc**2 * (1 + np.sin(nu) ** 2))
    s_ok, s_printed = a * ecc * np.sin(nu) / np.sqrt(1 - ecc**2), a * ecc * np.sin(nu) / (1 - ecc**2) ** 2
    assert np.allclose(el_c, EL0)
    de_printed = p[:, 1] + (x / r) * (q_printed - q_ok)
    dm_printed = p[:, 5] + (x / r) * (s_printed - s_ok)
    assert np.abs(de_printed - fd[:, 1]).max() > 1e-2 * np.abs(fd[:, 1]).max()
    assert np.abs(dm_printed - fd[:, 5]).max() > 1e-2 * np.abs(fd[:, 5]).max()


def _sin_cos_nu(el):
    x = _cart(el)
    r, v = x[:3], x[3:]
    h = np.cross(r, v)
    e_vec = np.cross(v, h) / MU - r / np.linalg.norm(r)
    cos_nu = np.dot(e_vec, r) / (np.linalg.norm(e_vec) * np.linalg.norm(r))
    sin_nu = np.sign(np.dot(r, v)) * np.sqrt(1 - cos_nu**2)
    return sin_nu, cos_nu


# ------------------------------------------------------------ Ψ against re-propagation
MODEL = ForceModel(bodies=("earth",), j2=True, integrator=IntegratorSettings(c_nom=0.02, rect_ratio=10.0))
PARAMS = default_params(MODEL, mu=[MU], pole=[[0.0, 0.0, 1.0]])
STEPS = np.array([1e-3, 1e-3, 1e-3, 1e-6, 1e-6, 1e-6])
LEO = np.array([7000.0, 0.0, 0.0, 0.0, 7.5, 1.0, 1000.0])
FLYBY = np.array([-90000.0, 30000.0, 10000.0, 3.4, -1.0, -0.45, 1000.0])  # hyperbolic, approaching


@pytest.mark.slow  # ~34 s of a cold make test (mostly XLA compilation; issue 22)
@pytest.mark.parametrize(
    "x_c, t_f, names",
    [
        (FLYBY, 15000.0, ALL[:17]),  # TARMAT's targets (TOM's additions: the direct Jacobian test above)
        (LEO, 6000.0, ("x", "y", "z", "vx", "vy", "vz", "a", "e", "i", "raan", "argp", "M", "time_of_flight")),
    ],
    ids=["flyby-bplane", "leo-elements"],
)
def test_psi_against_repropagated_differences(x_c, t_f, names):
    """Ψ = A_T Φ(t_f, t_c) and Ψ_p = A_T Θ (J2) against central differences of targets of
    trajectories re-propagated from perturbed x(t_c) (steps 1e-3 km, 1e-6 km/s, 1e-6 relative
    J2; as tests/integrate/test_sensitivities): agree to 1e-6 of each row's scale."""
    t_out = np.array([0.0, t_f])
    traj, s = propagate_with_sensitivities(MODEL, PARAMS, None, 0.0, x_c, t_out, ("j2[earth]",))
    a_t = target_jacobian(names, traj.x[-1], t_f, MU)
    psi, psi_p = (np.asarray(m) for m in target_matrix(a_t, s.stm[-1], s.par[-1]))

    def targets(x0, params=PARAMS):
        return np.asarray(target_values(names, propagate(MODEL, params, None, 0.0, x0, t_out).x[-1], t_f, MU))

    fd = np.zeros((len(names), 7))
    for j, h in enumerate(STEPS):
        e = np.zeros(7)
        e[j] = h
        fd[:, j] = (targets(x_c + e) - targets(x_c - e)) / (2 * h)
    h = 1e-6 * PARAMS.j2[0]
    pp, pm = (set_values(PARAMS, ("j2[earth]",), np.array([PARAMS.j2[0] + d]), MODEL) for d in (h, -h))
    fd_p = (targets(x_c, pp) - targets(x_c, pm)) / (2 * h)
    full, full_fd = np.column_stack([psi[:, :6], psi_p]), np.column_stack([fd[:, :6], fd_p])
    err = np.abs(full - full_fd).max(axis=1) / np.abs(full_fd).max(axis=1)
    assert err.max() < 1e-6, dict(zip(names, err))
    assert np.allclose(psi[:, 6], 0.0)  # ballistic: no target depends on the mass


def test_tom_target_values_against_independent_formulas():
    """TOM's additions to the catalogue against formulas written here: |r|, |v|, r.v/|r|;
    e cos(argp), e sin(argp) from cartesian_to_elements' e and argp (away from e = 0, where
    both are defined); v_inf = sqrt(v^2 - 2 mu/r) and |v_inf vector| = v_inf, the vector along
    the incoming asymptote: the velocity long before the encounter, checked by
    propagating the two-body conic 2e7 s back (Kepler, fracas.dynamics.kepler) where the
    velocity has nearly reached it (1e-3 of v_inf); final_time is t_f.  Tolerances 1e-12
    relative (same arithmetic), except the asymptote (1e-3, the finite look-back)."""
    from fracas.dynamics.kepler import kepler

    names = ("radius", "speed", "radial_velocity", "e_cos_argp", "e_sin_argp", "final_time")
    vals = np.asarray(target_values(names, ELL, 123.0, MU))
    r, v = ELL[:3], ELL[3:]
    el = np.asarray(cartesian_to_elements(r, v, MU))
    ref = [
        np.linalg.norm(r),
        np.linalg.norm(v),
        r @ v / np.linalg.norm(r),
        el[1] * np.cos(el[4]),
        el[1] * np.sin(el[4]),
        123.0,
    ]
    np.testing.assert_allclose(vals, ref, rtol=1e-12, atol=1e-15)
    vinf = np.asarray(target_values(("vinf", "vinf_x", "vinf_y", "vinf_z"), HYP, 0.0, MU))
    assert abs(vinf[0] / np.sqrt(HYP[3:] @ HYP[3:] - 2 * MU / np.linalg.norm(HYP[:3])) - 1) < 1e-12
    assert abs(np.linalg.norm(vinf[1:]) / vinf[0] - 1) < 1e-12
    _, v_back = kepler(HYP[:3], HYP[3:], -2e7, MU)
    np.testing.assert_allclose(vinf[1:], np.asarray(v_back), atol=1e-3 * vinf[0])
