"""The intercept maneuver (fracas.guidance.intercept) against independent references:

* the solution hits: an independent scipy integration of the two-body equations (DOP853,
  rtol 1e-12) of the chaser with v_1 reaches the target's scipy-integrated position to
  1e-6 km (the integrations' own error over ~40 min is ~1e-8 km);
* a Hohmann transfer between two circular coplanar orbits (analytic dV), as an intercept
  with a 180-deg-minus-epsilon transfer avoided: the half-period transfer at 179 deg is
  checked against the vis-viva velocity to 1e-3 relative (the 1-deg offset changes dV at
  the 1e-4 level);
* the sensitivity M (3 x 12) against central differences of the full nonlinear solve
  (steps 1e-4 km, 1e-7 km/s: truncation ~1e-9 relative; 1e-6 relative bound).
"""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from fracas.guidance.intercept import intercept, intercept_sensitivity

MU = 4902.800


def _two_body(x0, t):
    f = lambda _t, y: np.r_[y[3:], -MU * y[:3] / np.linalg.norm(y[:3]) ** 3]
    return solve_ivp(f, (0, t), x0, method="DOP853", rtol=1e-12, atol=1e-12).y[:, -1]


def _pair():
    ra, rt = 1738.0 + 20.0, 1738.0 + 110.0
    va, vt = np.sqrt(MU / ra), np.sqrt(MU / rt)
    th = np.deg2rad(12.0)
    xa = np.array([ra, 0.0, 0.0, 0.0, va, 0.0])
    xt = np.array([rt * np.cos(th), rt * np.sin(th), 1.0, -vt * np.sin(th), vt * np.cos(th), 0.002])
    return xa, xt


def test_intercept_hits_the_target_by_scipy_integration():
    xa, xt = _pair()
    tof = 2400.0
    dv, v1, miss, status = intercept(xa, xt, tof, MU)
    assert int(status) == 0 and float(miss) < 1e-8
    ya = _two_body(np.r_[xa[:3], np.asarray(v1)], tof)
    yt = _two_body(xt, tof)
    assert np.linalg.norm(ya[:3] - yt[:3]) < 1e-6


def test_half_transfer_matches_hohmann_dv():
    r1, r2 = 1738.0 + 20.0, 1738.0 + 110.0
    a = 0.5 * (r1 + r2)
    tof = np.pi * np.sqrt(a**3 / MU)
    xa = np.array([r1, 0.0, 0.0, 0.0, np.sqrt(MU / r1), 0.0])
    tof = tof * (179.0 / 180.0)
    ang = np.deg2rad(179.0) - np.sqrt(MU / r2**3) * tof  # the target arrives at 179 deg
    vt = np.sqrt(MU / r2)
    xt = np.array([r2 * np.cos(ang), r2 * np.sin(ang), 0.0, -vt * np.sin(ang), vt * np.cos(ang), 0.0])
    dv, v1, miss, status = intercept(xa, xt, tof, MU)
    hohmann = np.sqrt(MU / r1) * (np.sqrt(2 * r2 / (r1 + r2)) - 1.0)
    assert int(status) == 0
    assert np.linalg.norm(np.asarray(dv)) == pytest.approx(hohmann, rel=1e-3)


def test_sensitivity_against_central_differences_of_the_solve():
    xa, xt = _pair()
    tof = 2400.0
    _, v1, _, _ = intercept(xa, xt, tof, MU)
    M = np.asarray(intercept_sensitivity(xa, xt, v1, tof, MU))
    x = np.r_[xa, xt]
    h = np.r_[np.full(3, 1e-4), np.full(3, 1e-7), np.full(3, 1e-4), np.full(3, 1e-7)]
    M_fd = np.zeros((3, 12))
    for i in range(12):
        e = np.zeros(12)
        e[i] = h[i]
        dp = np.asarray(intercept((x + e)[:6], (x + e)[6:], tof, MU)[0])
        dm = np.asarray(intercept((x - e)[:6], (x - e)[6:], tof, MU)[0])
        M_fd[:, i] = (dp - dm) / (2 * h[i])
    for cols in (slice(0, 3), slice(3, 6), slice(6, 9), slice(9, 12)):
        assert np.max(np.abs(M[:, cols] - M_fd[:, cols])) <= 1e-6 * np.max(np.abs(M_fd[:, cols]))
