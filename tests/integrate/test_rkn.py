"""High-order Nystrom / Runge-Kutta kernels (fracas.integrate.rkn, .tableaux) against
references this code did not produce.

* Tableaux: the order conditions of their stated orders, in exact rational arithmetic
  (Hairer, Norsett & Wanner, Solving ODEs I, secs. II.2 and II.14: quadrature conditions and
  the trees b^T c^m (A c^k)); DOP853 in float64.
* Order of convergence: fixed steps on an eccentric Kepler orbit (e = 0.5, one revolution
  from apocentre) against the analytic solution -- Kepler's equation solved by Newton's
  method in numpy long double in this file.  Slope of log(error) vs log(h) within +-0.5 of
  the stated order, over step ranges where truncation dominates round-off (measured: RKN4
  4.1, DPRKN8 8.2, DPRKN12 12.1, DOP853 8.4).
* LEO + J2 one day: scipy DOP853 at rtol 1e-13, atol 1e-9 km on the Cowell equations
  written here in numpy; forward, backward, and backward-then-forward.
* Eccentric (e = 0.6) three-day orbit: the achieved error against the requested tolerance,
  forward and backward, against the long-double analytic solution.
* vmap over a batch of initial states against per-lane runs.
"""

from __future__ import annotations

from fractions import Fraction

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from fracas import _jax  # noqa: F401
from fracas.integrate import rkn
from fracas.integrate import tableaux as T
from fracas.status import RunStatus

MU = 398600.4418  # km^3/s^2
J2 = 1.08262668e-3
RE = 6378.137  # km
DAY = 86400.0
X0 = np.array([7000.0, 0.0, 0.0, 0.0, 7.5, 1.0])  # the LEO case of tests/integrate/test_encke_leo.py

NYSTROM = [T.RKN4, T.DPRKN8, T.DPRKN12]
ADAPTIVE = [T.DPRKN8, T.DPRKN12, T.DOP853]


# ------------------------------------------------------------------------- dynamics
def two_body(t, r):
    r2 = jnp.dot(r, r)
    ir = jnp.sqrt(1.0 / r2)
    return (-MU * ir * ir * ir) * r


def two_body_j2(t, r):
    x, y, z = r[0], r[1], r[2]
    ir2 = 1.0 / (x * x + y * y + z * z)
    ir = jnp.sqrt(ir2)
    ir3 = ir * ir2
    k = 1.5 * J2 * MU * RE * RE * ir3 * ir2
    z2 = 5.0 * z * z * ir2
    return -MU * ir3 * r + k * jnp.stack([x * (z2 - 1.0), y * (z2 - 1.0), z * (z2 - 3.0)])


def accel_for(tab, f):
    return f if isinstance(tab, T.NystromTableau) else (lambda t, r, v: f(t, r))


def cowell_j2_numpy(t, y):
    r = y[:3]
    x, yy, z = r
    rn2 = x * x + yy * yy + z * z
    rn = np.sqrt(rn2)
    k = 1.5 * J2 * MU * RE**2 / rn**5
    z2 = 5.0 * z * z / rn2
    a = -MU * r / rn**3 + k * np.array([x * (z2 - 1.0), yy * (z2 - 1.0), z * (z2 - 3.0)])
    return np.concatenate([y[3:], a])


def kepler_state(a, e, mean_anomaly, inc=0.6, raan=0.4, argp=1.1):
    """Analytic two-body state (km, km/s) in long double: Kepler's equation by Newton."""
    L = np.longdouble
    a, e, M = L(a), L(e), L(mean_anomaly)
    E = M + e * np.sin(M)
    for _ in range(50):
        E = E - (E - e * np.sin(E) - M) / (1 - e * np.cos(E))
    n = np.sqrt(L(MU) / a**3)
    b = a * np.sqrt(1 - e * e)
    edot = n / (1 - e * np.cos(E))
    p = np.array([a * (np.cos(E) - e), b * np.sin(E), L(0)])
    q = np.array([-a * np.sin(E) * edot, b * np.cos(E) * edot, L(0)])

    def rot(axis, ang):
        c, s = np.cos(L(ang)), np.sin(L(ang))
        m = {2: [[c, -s, 0], [s, c, 0], [0, 0, 1]], 0: [[1, 0, 0], [0, c, -s], [0, s, c]]}[axis]
        return np.array(m, dtype=L)

    R = rot(2, raan) @ rot(0, inc) @ rot(2, argp)
    return (R @ p).astype(np.float64), (R @ q).astype(np.float64)


# ------------------------------------------------------------------------ tableaux
def _check(cond, tol, what):
    assert abs(cond) <= tol, f"{what}: residual {float(cond):.3e}"


@pytest.mark.parametrize("tab", NYSTROM, ids=lambda t: t.name)
def test_nystrom_order_conditions_exact(tab):
    """Exact rationals of the source: row sums c^2/2, quadrature and b^T c^m (A c^k) trees up
    to the stated order for the propagated weights and to the embedded order for the embedded
    ones.  Tolerance 1e-40: RKN12(10)'s published last-stage rationals are approximations at
    ~1e-53; float64 rounding of the rationals is checked separately."""
    q = T.exact(tab)
    c, A = q["c"], q["a_bar"]
    s = len(c)
    tol = Fraction(1, 10**40)
    assert c[0] == 0
    for i in range(s):
        assert all(A[i][j] == 0 for j in range(i, s)), "a_bar must be strictly lower triangular"
        _check(sum(A[i]) - c[i] ** 2 / 2, tol, f"row sum {i}")
    sets = [(q["bbar"], q["b"], tab.order)]
    if tab.embedded_order is not None:
        sets.append((q["bbar_low"], q["b_low"], tab.embedded_order))
    for bbar, b, p in sets:
        for k in range(p):  # velocity quadrature: sum b c^k = 1/(k+1)
            _check(sum(b[i] * c[i] ** k for i in range(s)) - Fraction(1, k + 1), tol, f"b c^{k} (p={p})")
        for k in range(p - 1):  # position quadrature: sum bbar c^k = 1/((k+1)(k+2))
            _check(sum(bbar[i] * c[i] ** k for i in range(s)) - Fraction(1, (k + 1) * (k + 2)), tol, f"bbar c^{k}")
        for k in range(p):
            ack = [sum(A[i][j] * c[j] ** k for j in range(s)) for i in range(s)]
            w = Fraction(1, (k + 1) * (k + 2))
            for m in range(p):
                if m + k + 3 <= p:
                    exact = w * Fraction(1, m + k + 3)
                    got = sum(b[i] * c[i] ** m * ack[i] for i in range(s))
                    _check(got - exact, tol, f"b c^{m} A c^{k} (p={p})")
                if m + k + 4 <= p:
                    exact = w * (Fraction(1, m + k + 3) - Fraction(1, m + k + 4))
                    got = sum(bbar[i] * c[i] ** m * ack[i] for i in range(s))
                    _check(got - exact, tol, f"bbar c^{m} A c^{k} (p={p})")
    # the embedded pair really is of lower order: its first velocity quadrature beyond fails
    if tab.embedded_order is not None and tab.embedded_order + 1 < tab.order:
        pe = tab.embedded_order
        failing = [
            abs(sum(q["b_low"][i] * c[i] ** k for i in range(s)) - Fraction(1, k + 1)) > tol
            for k in range(pe, tab.order)
        ]
        assert any(failing)
    # float64 arrays are the rationals rounded once
    np.testing.assert_array_equal(tab.c, [float(x) for x in c])
    np.testing.assert_array_equal(tab.a_bar, [[float(x) for x in row] for row in A])
    np.testing.assert_array_equal(tab.bbar, [float(x) for x in q["bbar"]])
    np.testing.assert_array_equal(tab.b, [float(x) for x in q["b"]])
    if tab.fsal:  # the last stage evaluates the acceleration at the new position
        assert c[-1] == 1 and A[-1][: s - 1] == q["bbar"][: s - 1] and q["bbar"][-1] == 0


def test_rkn4_is_the_fracas_nystrom_step():
    """RKN4 = the weights of fracas.integrate.encke._nystrom_step (Doc. 4 sec. 4.3)."""
    t = T.RKN4
    np.testing.assert_array_equal(t.c, [0, 0.5, 0.5, 1])
    np.testing.assert_array_equal(t.a_bar[1:, :3], [[1 / 8, 0, 0], [1 / 8, 0, 0], [0, 0, 1 / 2]])
    np.testing.assert_allclose(t.bbar, [1 / 6, 1 / 6, 1 / 6, 0], rtol=0, atol=1e-17)
    np.testing.assert_allclose(t.b, [1 / 6, 2 / 6, 2 / 6, 1 / 6], rtol=0, atol=1e-17)
    calls = []

    def counting(t_, r):
        calls.append(1)
        return two_body(t_, r)

    rkn.rkn_step(counting, 0.0, jnp.array(X0[:3]), jnp.array(X0[3:]), 10.0, t)
    # stages as data (issue 23): the acceleration is traced once per step program ...
    assert len(calls) == 1
    # ... and evaluated at 3 distinct stages: 2 and 3 coincide without velocity dependence
    from fracas.integrate.stages import plan_of_tableau

    plan = plan_of_tableau(t)
    assert plan.stages == 3
    np.testing.assert_array_equal(plan.c, [0, 0.5, 1])
    np.testing.assert_allclose(plan.b, [1 / 6, 4 / 6, 1 / 6], rtol=0, atol=1e-17)
    with pytest.raises(ValueError):
        rkn.integrate_adaptive(two_body, 0.0, X0[:3], X0[3:], 10.0, t)


def test_dop853_conditions():
    t = T.DOP853
    c, A, b = t.c, t.a, t.b
    np.testing.assert_allclose(A.sum(axis=1), c, rtol=0, atol=1e-13)
    for k in range(t.order):
        assert abs(b @ c**k - 1.0 / (k + 1)) < 1e-13, k
    for k in range(t.order):
        for m in range(t.order):
            if m + k + 2 <= t.order:
                got = (b * c**m) @ (A @ c**k)
                assert abs(got - 1.0 / ((k + 1) * (m + k + 2))) < 1e-13, (m, k)
    c_ext = np.append(c, 1.0)  # the error weights include the stage f(t + h, y1)
    for k in range(t.embedded_order):
        assert abs(t.e @ c_ext**k) < 1e-13, k
    for k in range(t.aux_order):
        assert abs(t.e_aux @ c_ext**k) < 1e-13, k
    assert abs(t.e @ c_ext**t.embedded_order) > 1e-5


# -------------------------------------------------------------- order of convergence
# (tableau, step counts per revolution); errors there lie between ~1 km (RKN4) and ~1e-9 km
ORDER_CASES = [
    (T.RKN4, np.arange(150, 1000, 50)),
    (T.DPRKN8, np.arange(40, 116, 6)),
    (T.DPRKN12, np.arange(24, 50, 2)),
    (T.DOP853, np.arange(50, 160, 10)),
]


@pytest.mark.parametrize(("tab", "ns"), ORDER_CASES, ids=lambda x: getattr(x, "name", "n"))
def test_observed_order_eccentric_kepler(tab, ns):
    """Reference: the analytic Kepler solution (long double), e = 0.5, one revolution."""
    e = 0.5
    a = 7000.0 / (1.0 - e)
    period = 2.0 * np.pi * np.sqrt(a**3 / MU)
    r0, v0 = kepler_state(a, e, np.pi)  # apocentre: the pericentre lies mid-arc
    r_ref, _ = kepler_state(a, e, 3.0 * np.pi)
    f = accel_for(tab, two_body)
    run = jax.jit(lambda h, n: rkn.integrate_fixed(f, 0.0, r0, v0, h, n, tab)[0])
    errs = np.array([np.linalg.norm(np.asarray(run(period / n, n)) - r_ref) for n in ns])
    assert errs.max() < 10.0 and errs.min() > 1e-10, errs  # km: truncation, not round-off
    slope = -np.polyfit(np.log(ns), np.log(errs), 1)[0]
    assert abs(slope - tab.order) <= 0.5, f"{tab.name}: observed order {slope:.2f}"


# ----------------------------------------------------------------- LEO + J2, one day
@pytest.fixture(scope="module")
def leo_reference():
    fwd = solve_ivp(cowell_j2_numpy, (0.0, DAY), X0, method="DOP853", rtol=1e-13, atol=1e-9)
    assert fwd.success
    return fwd.y[:, -1]


@pytest.fixture(scope="module")
def adaptive_runners():
    """One compiled driver per tableau (times, tolerance and direction traced)."""
    out = {}
    for tab in ADAPTIVE:
        for name, f in (("leo", two_body_j2), ("kepler", two_body)):
            acc = accel_for(tab, f)
            out[tab.name, name] = jax.jit(
                lambda r0, v0, ta, tb, tol, acc=acc, tab=tab: rkn.integrate_adaptive(
                    acc, ta, r0, v0, tb, tab, rtol=tol, atol=tol
                )
            )
    return out


LEO_RTOL = 1e-10  # atol 1e-10 (km, km/s): measured 0.01-1 mm after one day for all three


@pytest.mark.parametrize("tab", ADAPTIVE, ids=lambda t: t.name)
def test_leo_j2_one_day_within_1m_of_dop853(tab, leo_reference, adaptive_runners):
    run = adaptive_runners[tab.name, "leo"]
    xf = leo_reference
    fwd = run(X0[:3], X0[3:], 0.0, DAY, LEO_RTOL)
    assert int(fwd.status) == RunStatus.OK and float(fwd.t) == DAY
    assert np.linalg.norm(np.asarray(fwd.r) - xf[:3]) < 1e-3  # km
    assert np.linalg.norm(np.asarray(fwd.v) - xf[3:]) < 1e-6  # km/s
    # backward from the reference's final state to the start
    bwd = run(xf[:3], xf[3:], DAY, 0.0, LEO_RTOL)
    assert int(bwd.status) == RunStatus.OK and float(bwd.t) == 0.0 and float(bwd.h) < 0
    assert np.linalg.norm(np.asarray(bwd.r) - X0[:3]) < 1e-3
    # backward then forward returns to where it started
    back = run(fwd.r, fwd.v, DAY, 0.0, LEO_RTOL)
    again = run(back.r, back.v, 0.0, DAY, LEO_RTOL)
    assert np.linalg.norm(np.asarray(back.r) - X0[:3]) < 1e-3
    assert np.linalg.norm(np.asarray(again.r) - np.asarray(fwd.r)) < 1e-3
    assert int(fwd.n_accept) <= int(fwd.n_steps) < 2000


# ------------------------------------------------ achieved vs requested, eccentric orbit
# final position error <= FACTOR * rtol * apocentre radius, e = 0.6, three days (~11 revs),
# forward and backward (measured ratios: DPRKN8 0.3-10, DPRKN12 0.1-4, DOP853 400-3000 --
# DOP853 controls the error of its 5th-order embedded solution)
FACTOR = {"DPRKN8": 30.0, "DPRKN12": 30.0, "DOP853": 1.0e4}


@pytest.mark.parametrize("tab", ADAPTIVE, ids=lambda t: t.name)
def test_eccentric_three_days_achieves_tolerance(tab, adaptive_runners):
    run = adaptive_runners[tab.name, "kepler"]
    e = 0.6
    a = 7000.0 / (1.0 - e)
    t1 = 3.0 * DAY
    n = np.sqrt(MU / a**3)
    r0, v0 = kepler_state(a, e, 0.3)
    r1, v1 = kepler_state(a, e, 0.3 + n * t1)
    scale = a * (1.0 + e)
    errs = {}
    for rtol in (1e-8, 1e-11):
        fwd = run(r0, v0, 0.0, t1, rtol)
        bwd = run(r1, v1, t1, 0.0, rtol)
        assert int(fwd.status) == RunStatus.OK and int(bwd.status) == RunStatus.OK
        ef = np.linalg.norm(np.asarray(fwd.r) - r1)
        eb = np.linalg.norm(np.asarray(bwd.r) - r0)
        for err in (ef, eb):
            assert err <= FACTOR[tab.name] * rtol * scale, (tab.name, rtol, err / (rtol * scale))
        errs[rtol] = max(ef, eb)
    # tolerance proportionality: 1000x tighter gives at least 100x smaller errors
    assert errs[1e-11] < errs[1e-8] / 100.0


# ---------------------------------------------------------------------------- batches
def test_vmap_equals_per_lane():
    """A batch of LEO states of different shapes and step counts, DPRKN12: each lane equals
    its own unbatched run (same steps, same state to 1e-9 km)."""
    tab = T.DPRKN12
    rng = np.random.default_rng(7)
    n = 6
    r0 = np.tile(X0[:3], (n, 1)) * (1.0 + 0.3 * rng.random((n, 1)))
    v0 = np.tile(X0[3:], (n, 1)) + 0.4 * rng.standard_normal((n, 3))

    def one(r, v):
        return rkn.integrate_adaptive(two_body_j2, 0.0, r, v, 0.5 * DAY, tab, rtol=1e-10, atol=1e-10)

    batched = jax.jit(jax.vmap(one))(r0, v0)
    single = jax.jit(one)
    steps = set()
    for i in range(n):
        s = single(r0[i], v0[i])
        assert int(batched.n_steps[i]) == int(s.n_steps)
        assert int(batched.status[i]) == int(s.status) == RunStatus.OK
        np.testing.assert_allclose(np.asarray(batched.r[i]), np.asarray(s.r), rtol=0, atol=1e-9)
        np.testing.assert_allclose(np.asarray(batched.v[i]), np.asarray(s.v), rtol=0, atol=1e-12)
        steps.add(int(s.n_steps))
    assert len(steps) > 1  # the lanes really took different numbers of steps


def test_status_codes():
    """NaN start -> NONFINITE; too few steps -> MAX_STEPS (no exception inside jit)."""
    run = jax.jit(
        lambda r, v, m: rkn.integrate_adaptive(two_body, 0.0, r, v, DAY, T.DPRKN12, rtol=1e-10, atol=1e-10, max_steps=5)
    )
    out = run(jnp.array([np.nan, 0.0, 0.0]), jnp.array(X0[3:]), 0)
    assert int(out.status) == RunStatus.NONFINITE and int(out.n_steps) == 0
    out = run(jnp.array(X0[:3]), jnp.array(X0[3:]), 0)
    assert int(out.status) == RunStatus.MAX_STEPS and int(out.n_steps) == 5
