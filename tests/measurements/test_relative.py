"""Relative measurement partials (fracas.measurements.relative) against central differences,
and their limiting/analytic values.

Reference: central differences of the model value, step h = 1e-6 x the scale of the
perturbed quantity (km for positions at ~100 km range, km/s for velocities at ~0.1 km/s,
rad for the misalignment).  The truncation error of a central difference is ~h^2 q'''/6,
i.e. ~1e-12 relative here, and rounding ~eps |q| / h ~ 1e-10 relative; 1e-7 relative leaves
three orders of margin and still catches any wrong term (which is O(1)).
"""

import numpy as np
import pytest

from fracas.measurements import relative as rel

KINDS = list(rel.RELATIVE_KINDS)


def _case(seed):
    rng = np.random.default_rng(seed)
    r = rng.standard_normal(3) * 150.0  # km
    v = rng.standard_normal(3) * 0.1  # km/s
    Q, _ = np.linalg.qr(rng.standard_normal((3, 3)))
    return r, v, Q


def _fd(f, x, h):
    g = np.zeros(len(x))
    for i in range(len(x)):
        e = np.zeros(len(x))
        e[i] = h[i]
        g[i] = (float(f(x + e)) - float(f(x - e))) / (2 * h[i])
    return g


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_partials_against_central_differences(kind, seed):
    r, v, M = _case(seed)
    x = np.concatenate([r, v])
    f = lambda z: rel.relative_value(kind, z[:3], z[3:], M)
    h = np.r_[np.full(3, 1e-6 * np.linalg.norm(r)), np.full(3, 1e-6 * np.linalg.norm(v))]
    g_fd = _fd(f, x, h)
    g = np.asarray(rel.relative_partials(kind, r, v, M))
    scale = np.r_[np.full(3, np.max(np.abs(g_fd[:3]))), np.full(3, max(np.max(np.abs(g_fd[3:])), 1e-300))]
    assert np.all(np.abs(g - g_fd) <= 1e-7 * scale + 1e-300), (g, g_fd)


@pytest.mark.parametrize("kind", ["los_beta", "los_theta"])
def test_misalignment_partials_against_central_differences(kind):
    """dq/dphi = g x r_rho for sensor axes rotated by phi (i' = R(phi) i, exact rotation in the FD)."""
    from scipy.spatial.transform import Rotation

    r, v, M = _case(3)

    def q_rot(phi):
        R = Rotation.from_rotvec(phi).as_matrix()  # i' = R i  (columns of M.T are the axes)
        return rel.relative_value(kind, r, v, (R @ M.T).T)

    d_fd = _fd(q_rot, np.zeros(3), np.full(3, 1e-6))
    d = np.asarray(rel.misalignment_partials(kind, r, v, M))
    assert np.max(np.abs(d - d_fd)) <= 1e-7 * np.max(np.abs(d_fd))


def test_range_and_range_rate_do_not_depend_on_the_sensor_axes():
    r, v, M = _case(4)
    for kind in ("range", "range_rate"):
        assert float(rel.relative_value(kind, r, v, M)) == pytest.approx(
            float(rel.relative_value(kind, r, v)), rel=1e-15
        )
        assert np.all(np.asarray(rel.misalignment_partials(kind, r, v, M)) == 0.0)


def test_angles_analytic_values_in_identity_axes():
    """beta = atan2(z, x), theta = elevation out of the x-z plane: r = (1, 1, 1) gives
    beta = 45 deg, theta = atan(1/sqrt 2)."""
    r, v = np.array([1.0, 1.0, 1.0]), np.zeros(3)
    assert float(rel.relative_value("los_beta", r, v)) == pytest.approx(np.pi / 4, rel=1e-15)
    assert float(rel.relative_value("los_theta", r, v)) == pytest.approx(np.arctan(1 / np.sqrt(2)), rel=1e-15)


def test_vehicle_rows_follow_b_T_equals_minus_b_A_and_match_inertial_differences():
    """d q / d x_A = -g and d q / d x_T = +g (R-649 §II.B), checked by differencing the
    inertial states directly."""
    rng = np.random.default_rng(5)
    xa = np.r_[rng.standard_normal(3) * 1800.0, rng.standard_normal(3) * 1.6]
    xt = xa + np.r_[rng.standard_normal(3) * 100.0, rng.standard_normal(3) * 0.05]
    vals, gs, _ = rel.relative_measurement(xa, xt)
    for j, kind in enumerate(KINDS):
        bA, bT = rel.vehicle_rows(gs[j])
        f = lambda z, j=j: rel.relative_measurement(z, xt)[0][j]
        h = np.r_[np.full(3, 1e-4), np.full(3, 1e-7)]
        g_fd = _fd(f, xa, h)
        assert np.max(np.abs(np.asarray(bA) - g_fd)) <= 1e-6 * np.max(np.abs(g_fd)), kind
        assert np.allclose(np.asarray(bT), -np.asarray(bA), rtol=0, atol=0)
        assert float(vals[j]) == pytest.approx(float(rel.relative_value(kind, xt[:3] - xa[:3], xt[3:] - xa[3:])))


def test_proportional_noise_with_floor():
    """Apollo's 1/3 % of range (R-649 Fig. II-4) and the floor as rdot -> 0."""
    assert float(rel.noise_sigma(300.0, 0.0, 1 / 300, 0.0)) == pytest.approx(1.0, rel=1e-15)
    assert float(rel.noise_sigma(1e-6, 0.0, 1.3 / 300, 3e-5)) == 3e-5
    assert float(rel.noise_sigma(5.0, 0.002, 0.0, 0.0)) == 0.002
