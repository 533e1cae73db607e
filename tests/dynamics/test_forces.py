"""Force terms against independent references: the gradient of the J2 potential by finite
differences, the plain third-body formula, Potter's f(q) against (1+q)^1.5 - 1, and hand
values for SRP and thrust."""

from __future__ import annotations

import numpy as np

from fracas import constants as C
from fracas.dynamics import forces, propulsion

MU, J2, RE = 398600.4418, 1.08262668e-3, 6378.137


def _j2_potential(r, pole):
    rn = np.linalg.norm(r)
    s = r @ pole / rn
    return -MU / rn * J2 * (RE / rn) ** 2 * 0.5 * (3 * s * s - 1)


def test_j2_is_gradient_of_the_zonal_potential():
    """a_J2 = grad V_2 with V_2 = -(mu/r) J2 (R/r)^2 P2(sin phi), the J2 term of the geopotential
    V = (mu/r)[1 - J2 (R/r)^2 P2] (a = +grad V): central differences with h = 1e-3 km
    (truncation ~h^2/r^2 ~ 1e-14), agreement 1e-7 relative (roundoff of V differences)."""
    rng = np.random.default_rng(1)
    pole = np.array([0.1, -0.2, 1.0])
    pole /= np.linalg.norm(pole)
    for _ in range(5):
        r = rng.normal(size=3)
        r = r / np.linalg.norm(r) * rng.uniform(6600, 40000)
        g = np.array([(_j2_potential(r + h, pole) - _j2_potential(r - h, pole)) / 2e-3 for h in np.eye(3) * 1e-3])
        a = np.asarray(forces.j2_accel(r, MU, J2, RE, pole))
        np.testing.assert_allclose(a, g, rtol=1e-7, atol=1e-15)


def test_central_plus_j2_is_gradient_of_the_potential():
    """forces.central_j2_accel (one shared division) = grad(mu/r + V_2) (V_2 as in the J2 test
    above, a = +grad V), by central differences with h = 1e-3 km: truncation ~h^2/r^2 ~ 1e-14;
    roundoff of differences of mu/r (~1e-16 x 60 km^2/s^2 / 2e-3 km ~ 3e-12 km/s^2) is
    ~1e-9 of the ~8e-3 km/s^2 total, so 1e-8 relative is asserted.  Also dot3 = np.dot."""
    rng = np.random.default_rng(2)
    pole = np.array([0.1, -0.2, 1.0])
    pole /= np.linalg.norm(pole)

    def potential(r):
        return MU / np.linalg.norm(r) + _j2_potential(r, pole)

    for _ in range(5):
        r = rng.normal(size=3)
        r = r / np.linalg.norm(r) * rng.uniform(6600, 40000)
        g = np.array([(potential(r + e) - potential(r - e)) / 2e-3 for e in np.eye(3) * 1e-3])
        a = np.asarray(forces.central_j2_accel(r, MU, J2, RE, pole))
        np.testing.assert_allclose(a, g, rtol=1e-8)
        assert np.isclose(float(forces.dot3(r, pole)), r @ pole, rtol=1e-15, atol=0)


def test_third_body_matches_direct_formula_and_keeps_digits():
    """Battin's form equals mu[(rho-r)/|rho-r|^3 - rho/rho^3] where the direct form is exact
    (comparable distances), and at |r| << |rho| it stays accurate where the direct form
    cancels (checked against a 50-digit evaluation with mpmath-free exact rationals)."""
    r = np.array([4000.0, 1000.0, 300.0])
    rho = np.array([3.0e5, -1.0e5, 2.0e4])
    d = rho - r
    direct = C.BODIES["moon"].mu_km3_s2 * (d / np.linalg.norm(d) ** 3 - rho / np.linalg.norm(rho) ** 3)
    np.testing.assert_allclose(forces.third_body_accel(r, rho, C.BODIES["moon"].mu_km3_s2), direct, rtol=1e-12)
    from fractions import Fraction as F

    r_small = np.array([1.0, 2.0, -1.0])
    rho_far = np.array([1.5e8, 2.0e7, -3.0e6])
    mu = C.BODIES["sun"].mu_km3_s2
    # exact: use the series-free identity with high precision via Python decimal
    from decimal import Decimal, getcontext

    getcontext().prec = 60
    D = [Decimal(float(x)) for x in rho_far - r_small]
    R = [Decimal(float(x)) for x in rho_far]
    nd = sum(x * x for x in D).sqrt()
    nr = sum(x * x for x in R).sqrt()
    exact = np.array([float(Decimal(mu) * (D[i] / nd**3 - R[i] / nr**3)) for i in range(3)])
    got = np.asarray(forces.third_body_accel(r_small, rho_far, mu))
    np.testing.assert_allclose(got, exact, rtol=1e-12)
    assert F(1) == 1  # (fractions kept for readers who want rational checks)


def test_potter_f():
    """f(q) = (1+q)^1.5 - 1 where the direct form is accurate (|q| > 0.01: 3e-15 relative), and
    the binomial series 3/2 q + 3/8 q^2 - 1/16 q^3 at q = 1e-8 (Doc. 4; digest T1)."""
    for q in (-0.5, 0.01, 0.3, 3.0):
        np.testing.assert_allclose(float(forces.potter_f(q)), (1 + q) ** 1.5 - 1, rtol=1e-14)
    q = 1e-8
    np.testing.assert_allclose(float(forces.potter_f(q)), 1.5 * q + 0.375 * q * q - q**3 / 16, rtol=1e-15)
    assert float(forces.potter_f(3.0)) == 7.0


def test_srp_and_thrust_hand_values():
    """SRP at 1 AU: Cr S/c A/m = 1.3 * 4.5398e-6 N/m^2 * 10 m^2 / 500 kg = 1.180e-7 m/s^2; thrust
    T = 2 eta P / c = 2 * 0.65 * 10 kW / 30 km/s = 0.4333 N; solar power at 2 AU is P0/4."""
    a = forces.srp_accel(np.array([C.AU_KM, 0.0, 0.0]), 10.0, 500.0, 1.3)
    np.testing.assert_allclose(np.asarray(a) * 1e3, [1.3 * 1361.0 / 299792458.0 * 10 / 500, 0, 0], rtol=1e-12)
    t = propulsion.thrust_magnitude(10.0, 0.65, 30.0)
    np.testing.assert_allclose(float(t) * 1e3, 2 * 0.65 * 10e3 / 30e3, rtol=1e-14)
    p = propulsion.power_kw(10.0, np.array([2 * C.AU_KM, 0.0, 0.0]), 0.0, np.inf, solar=True)
    np.testing.assert_allclose(float(p), 2.5, rtol=1e-14)
    pn = propulsion.power_kw(10.0, None, 1.0e7, 1.0e7, solar=False)
    np.testing.assert_allclose(float(pn), 10.0 / np.e, rtol=1e-14)


def test_velocity_frame_thrust_direction():
    """EP's frame: alpha = 0, beta = 0 is along v; alpha = 90 deg along (h x v); beta = 90 deg along h."""
    r = np.array([7000.0, 100.0, 50.0])
    v = np.array([0.3, 7.4, 1.0])
    h = np.cross(r, v)
    u0 = np.asarray(propulsion.thrust_direction(r, v, 0.0, 0.0, 0.0))
    u1 = np.asarray(propulsion.thrust_direction(r, v, np.pi / 2, 0.0, 0.0))
    u2 = np.asarray(propulsion.thrust_direction(r, v, 0.0, np.pi / 2, 0.0))
    np.testing.assert_allclose(u0, v / np.linalg.norm(v), atol=1e-15)
    hv = np.cross(h, v)
    np.testing.assert_allclose(u1, hv / np.linalg.norm(hv), atol=1e-15)
    np.testing.assert_allclose(u2, h / np.linalg.norm(h), atol=1e-15)


def test_yaw_switch_frame_flips_beta_with_cos_u():
    """Frame code 2 (Edelbaum's steering): on a circular orbit of inclination 30 deg, the thrust
    direction is the velocity-frame direction with beta when cos u > 0 and with -beta when
    cos u < 0 (u the argument of latitude, from the orbit geometry built here), so its normal
    component r x v / |r x v| . d has the sign of cos u for beta > 0 (di/dt > 0 on both halves)."""
    inc = np.radians(30.0)
    alpha, beta = 0.1, 0.3
    for u in np.radians([20.0, 80.0, 100.0, 200.0, 260.0, 300.0]):
        # circular orbit, raan = 0: r = R1(i) (cos u, sin u, 0), v = R1(i) (-sin u, cos u, 0)
        rot = np.array([[1, 0, 0], [0, np.cos(inc), -np.sin(inc)], [0, np.sin(inc), np.cos(inc)]])
        r = rot @ np.array([7000.0 * np.cos(u), 7000.0 * np.sin(u), 0.0])
        v = rot @ np.array([-7.5 * np.sin(u), 7.5 * np.cos(u), 0.0])
        d2 = np.asarray(propulsion.thrust_direction(r, v, alpha, beta, 2.0))
        sign = np.sign(np.cos(u))
        d0 = np.asarray(propulsion.thrust_direction(r, v, alpha, sign * beta, 0.0))
        np.testing.assert_allclose(d2, d0, rtol=0, atol=1e-15)
        h_hat = np.cross(r, v) / np.linalg.norm(np.cross(r, v))
        assert np.sign(d2 @ h_hat) == sign and abs(d2 @ h_hat - sign * np.sin(beta)) < 1e-14
    # the integrator passes the trigonometry computed once per step (issue 23): the same vector
    for code in (0.0, 1.0, 2.0):
        pre = propulsion.angles_to_unit(alpha, beta)
        np.testing.assert_array_equal(
            np.asarray(propulsion.thrust_direction(r, v, alpha, beta, code, pre)),
            np.asarray(propulsion.thrust_direction(r, v, alpha, beta, code)),
        )
    # frame 1 stays inertial RA/Dec pointing
    d1 = np.asarray(propulsion.thrust_direction(r, v, alpha, beta, 1.0))
    np.testing.assert_allclose(
        d1, [np.cos(beta) * np.cos(alpha), np.cos(beta) * np.sin(alpha), np.sin(beta)], atol=1e-15
    )
