"""Pointing that varies within a thrust arc (``ForceModel.steering``: Legendre laws of alpha and
beta in the arc's normalised time) against a SciPy DOP853 integration of the plain equations
with the same law written independently here (reference: tests/reference.py's Cowell equations).

Case: Sun only, solar-electric thrust (10 kW at 1 AU, eta 0.65, c 30 km/s) from 1 AU; two arcs
(0-60 d velocity frame, 80-150 d velocity frame) with P1..P3 coefficients of tens of degrees on
both angles, 150 days.  Tolerance 1 km in position and 1 g in mass: the core runs DOP853 at
1e-12 and the reference at 1e-13; a law read at the step midpoint instead of at each stage (the
error this guards against) moves the final position by ~10^3 km.
"""

from __future__ import annotations

import numpy as np
import pytest

from fracas import constants as C
from fracas.dynamics.model import ForceModel, default_params
from fracas.integrate.propagate import propagate
from tests.integrate.methods import integrator
from tests.reference import cowell_rhs_factory, integrate_piecewise

DAY = 86400.0
MU = C.BODIES["sun"].mu_km3_s2
ON = (0.0, 80 * DAY)
OFF = (60 * DAY, 150 * DAY)
ALPHA = (np.radians(20.0), np.radians(-10.0))
BETA = (np.radians(5.0), np.radians(-3.0))
ALPHA_P = ((np.radians(30.0), np.radians(-12.0), np.radians(6.0)), (np.radians(-25.0), np.radians(8.0), 0.0))
BETA_P = ((np.radians(4.0), 0.0, np.radians(-2.0)), (0.0, np.radians(3.0), np.radians(1.0)))


def _legendre(k: int, t: float, coeffs) -> float:
    """sum_i c_i P_i(s), s = (2t - t_on - t_off)/(t_off - t_on) (P1 = s, P2 = (3s^2-1)/2,
    P3 = (5s^3-3s)/2), written from the Legendre polynomials' definition."""
    s = (2 * t - ON[k] - OFF[k]) / (OFF[k] - ON[k])
    p = (s, 0.5 * (3 * s * s - 1), 0.5 * (5 * s**3 - 3 * s))
    return float(sum(c * q for c, q in zip(coeffs, p)))


def _arc(t: float) -> int:
    return 0 if t < OFF[0] else 1


def _x0():
    r = np.array([C.AU_KM, 0.0, 0.0])
    v = np.array([0.0, np.sqrt(MU / C.AU_KM), 0.5])
    return np.concatenate([r, v, [1000.0]])


def _model_params(steering: bool):
    m = ForceModel(
        bodies=("sun",),
        thrust=True,
        velocity_dependent=True,
        n_arcs=2,
        steering=steering,
        integrator=integrator("cowell", thrust=True),
    )
    laws = {
        f"arc_{a}_p{i + 1}": [c[k][i] for k in range(2)]
        for a, c in (("alpha", ALPHA_P), ("beta", BETA_P))
        for i in range(3)
    }
    p = default_params(
        m,
        power_kw=10.0,
        efficiency=0.65,
        exhaust_velocity_km_s=30.0,
        arc_t_on=list(ON),
        arc_t_off=list(OFF),
        arc_alpha=list(ALPHA),
        arc_beta=list(BETA),
        **laws,
    )
    return m, p


@pytest.fixture(scope="module")
def steered_final():
    m, p = _model_params(True)
    tr = propagate(m, p, None, 0.0, _x0(), np.array([0.0, 150 * DAY]))
    assert int(tr.status) == 0
    return np.asarray(tr.x_final)


def test_legendre_law_against_scipy_plain_equations(steered_final):
    """Final state of the steered two-arc cruise against DOP853 (rtol 1e-13) of the plain
    equations with the law evaluated at every right-hand-side call."""
    thrust = {
        "p0_kw": 10.0,
        "eta": 0.65,
        "c": 30.0,
        "factor": lambda t: 1.0 if (t < OFF[0] or t >= ON[1]) else 0.0,
        "alpha": lambda t: ALPHA[_arc(t)] + _legendre(_arc(t), t, ALPHA_P[_arc(t)]),
        "beta": lambda t: BETA[_arc(t)] + _legendre(_arc(t), t, BETA_P[_arc(t)]),
    }
    rhs = cowell_rhs_factory(MU, "sun", thrust=thrust)
    ref = integrate_piecewise(rhs, _x0(), [0.0, OFF[0], ON[1], OFF[1]])
    assert np.linalg.norm(steered_final[:3] - ref[:3]) < 1.0
    assert abs(steered_final[6] - ref[6]) * 1e3 < 1.0
    # the law matters: the constant-pointing run lands far away
    m, p = _model_params(False)
    flat = np.asarray(propagate(m, p, None, 0.0, _x0(), np.array([0.0, 150 * DAY])).x_final)
    assert np.linalg.norm(flat[:3] - ref[:3]) > 1e4


def test_zero_coefficients_are_constant_pointing():
    """With every Legendre coefficient zero the steering program reproduces the constant-pointing
    one (reference: the same core without the law), to the integrator's rounding (1e-6 km)."""
    m, p = _model_params(True)
    zeros = {f"arc_{a}_p{i}": np.zeros(2) for a in ("alpha", "beta") for i in (1, 2, 3)}
    a = np.asarray(propagate(m, p._replace(**zeros), None, 0.0, _x0(), np.array([0.0, 150 * DAY])).x_final)
    m0, p0 = _model_params(False)
    b = np.asarray(propagate(m0, p0, None, 0.0, _x0(), np.array([0.0, 150 * DAY])).x_final)
    assert np.linalg.norm(a[:3] - b[:3]) < 1e-6
    assert abs(a[6] - b[6]) < 1e-9
