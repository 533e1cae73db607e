"""Covariance-form filter algebra against the report's block equations, implemented LITERALLY
(numpy, block by block) in this file: FRACAS PROP eqs. 5-16, FILTER eqs. 1-21, KSGAIN,
WLSGAN eqs. 1-11 (NASA CR-112256 §5.3.4, 5.3.7, 5.3.13, 5.3.24).

Scanned equations rebuilt here (the OCR of CR-112256 garbles them):
* PROP eq. 1 reads "φ P φ⁺ + φ": rebuilt as 𝚽 P 𝚽ᵀ + Q̃ (eq. 4 defines Q̃).
* PROP eq. 5 lists "Θ_xw C_xuᵀ" as well as "Θ_xw C_xwᵀ" inside the bracket: the first is a
  duplicated, garbled term and is dropped.  No C_xv term belongs there because Θ_xv = 0
  (eq. 3); the expansion of eqs. 1-3 gives exactly
  P⁻ = [Φ P + Θ_xs C_xsᵀ + Θ_xu C_xuᵀ + Θ_xw C_xwᵀ] Φᵀ + C_xs⁻ Θ_xsᵀ + C_xu⁻ Θ_xuᵀ
       + C_xw⁻ Θ_xwᵀ + Q̃.
* FILTER eq. 5 ends in "C_uw H_wᵀ": the E (v-row) block needs C_vw H_wᵀ.
* FILTER eqs. 7-10 lost their minus signs ("P⁺ = P⁻ K_x Aᵀ"): P⁺ = P⁻ - K_x Aᵀ etc.
* FILTER eq. 16 "C_xs - K_x B": K_x Bᵀ.  Eq. 17 "P_s - K_x Bᵀ": K_s Bᵀ (the s-s block).
* WLSGAN eqs. 9-11 lost their minus signs; eq. 10 "C_xs - K_x B": K_x Bᵀ; eq. 8 "K_c": K_s.
"""

from __future__ import annotations

import numpy as np
import pytest

from fracas.filters.covariance import (
    PSD_TOLERANCE,
    Layout,
    augmented_transition,
    correlations,
    innovation,
    joseph_update,
    kalman_schmidt_gain,
    psd_check,
    time_update,
    wls_gain,
    wls_time_update,
)
from tests.filters.helpers import f64, random_cov, scaled_err

ROLES = ("x", "s", "u", "v", "w")

# (layout, number of measurements m): all five blocks non-empty; the 7-state thrusting case;
# one with empty s and v blocks (zero-size slices must work).
CASES = [
    (Layout(6, 2, 2, 1, 1), 3),
    (Layout(7, 3, 1, 2, 2), 2),
    (Layout(6, 0, 2, 0, 1), 1),
]


# ----------------------------------------------------------------------------- helpers
def random_problem(rng, L, m):
    n = L.n
    scales = 10.0 ** rng.uniform(-1.5, 1.5, size=n)  # mixed units, 3 decades
    P = random_cov(rng, n, scales)
    phi = np.eye(L.nx) + 0.2 * rng.normal(size=(L.nx, L.nx))
    theta = rng.normal(size=(L.nx, n - L.nx)) * scales[: L.nx, None] / scales[None, L.nx :]
    Bq = rng.normal(size=(L.nx, L.nx - 2))  # singular process noise
    Q = 0.1 * Bq @ Bq.T * np.outer(scales[: L.nx], scales[: L.nx])
    H = rng.normal(size=(m, n)) / scales[None, :]
    R = random_cov(rng, m) * 0.3
    return P, phi, theta, Q, H, R


def blocks(P, L):
    sl = {r: getattr(L, r) for r in ROLES}
    return {a + b: P[sl[a], sl[b]] for a in ROLES for b in ROLES}


def assemble(b, L):
    return np.block([[b[a + c] for c in ROLES] for a in ROLES])


# ------------------------------------------------------------- literal block equations
def prop_literal(P, phi, Ts, Tu, Tw, Q, L):
    """FRACAS PROP eqs. 5-16, block by block (eq. 5 rebuilt, see module docstring)."""
    b = blocks(P, L)
    F = phi
    T = lambda a: a.T
    o = dict(b)
    o["xs"] = F @ b["xs"] + Ts @ b["ss"] + Tu @ T(b["su"]) + Tw @ T(b["sw"])  # (6)
    o["xu"] = F @ b["xu"] + Ts @ b["su"] + Tu @ b["uu"] + Tw @ T(b["uw"])  # (7)
    o["xv"] = F @ b["xv"] + Ts @ b["sv"] + Tu @ b["uv"] + Tw @ T(b["vw"])  # (8)
    o["xw"] = F @ b["xw"] + Ts @ b["sw"] + Tu @ b["uw"] + Tw @ b["ww"]  # (9)
    o["xx"] = (  # (5)
        (F @ b["xx"] + Ts @ T(b["xs"]) + Tu @ T(b["xu"]) + Tw @ T(b["xw"])) @ F.T
        + o["xs"] @ Ts.T
        + o["xu"] @ Tu.T
        + o["xw"] @ Tw.T
        + Q
    )
    # (10)-(16): P_s, C_su, C_sv, C_sw, C_uv, C_uw, C_vw (and U_o, V_o, W_o) unchanged.
    for a in "suvw":
        o[a + "x"] = o["x" + a].T
    return assemble(o, L)


def filter_residuals(P, H, R, L):
    """FRACAS FILTER eqs. 1-6 (eq. 5 rebuilt: C_vw H_wᵀ)."""
    b = blocks(P, L)
    Hx, Hs, Hu, Hv, Hw = (H[:, getattr(L, r)] for r in ROLES)
    T = lambda a: a.T
    A = b["xx"] @ Hx.T + b["xs"] @ Hs.T + b["xu"] @ Hu.T + b["xv"] @ Hv.T + b["xw"] @ Hw.T
    B = b["ss"] @ Hs.T + T(b["xs"]) @ Hx.T + b["su"] @ Hu.T + b["sv"] @ Hv.T + b["sw"] @ Hw.T
    D = T(b["xu"]) @ Hx.T + T(b["su"]) @ Hs.T + b["uu"] @ Hu.T + b["uv"] @ Hv.T + b["uw"] @ Hw.T
    E = T(b["xv"]) @ Hx.T + T(b["sv"]) @ Hs.T + T(b["uv"]) @ Hu.T + b["vv"] @ Hv.T + b["vw"] @ Hw.T
    F = T(b["xw"]) @ Hx.T + T(b["sw"]) @ Hs.T + T(b["uw"]) @ Hu.T + T(b["vw"]) @ Hv.T + b["ww"] @ Hw.T
    J = Hx @ A + Hs @ B + Hu @ D + Hv @ E + Hw @ F + R
    return A, B, D, E, F, J


def ksgain_literal(A, B, J):
    """FRACAS KSGAIN: K_x = A J⁻¹, K_s = B J⁻¹ (dense solve)."""
    return np.linalg.solve(J.T, A.T).T, np.linalg.solve(J.T, B.T).T


def filter_update_literal(P, A, B, D, E, F, J, Kx, Ks, L, general):
    """FILTER eqs. 7-14 (+18-21) for the Kalman-Schmidt gain of this P, or eqs. 15-21 with
    9, 10, 12, 13, 14 for any gain (``general``)."""
    b = blocks(P, L)
    o = dict(b)
    o["xx"] = b["xx"] - Kx @ A.T  # (7)
    o["xs"] = b["xs"] - Kx @ B.T  # (8)
    o["xu"] = b["xu"] - Kx @ D.T  # (9)
    o["xv"] = b["xv"] - Kx @ E.T  # (10)
    o["ss"] = b["ss"] - Ks @ B.T  # (11)
    o["su"] = b["su"] - Ks @ D.T  # (12)
    o["sv"] = b["sv"] - Ks @ E.T  # (13)
    # (14) C_uv unchanged
    if general:
        o["xx"] = o["xx"] - A @ Kx.T + Kx @ J @ Kx.T  # (15)
        o["xs"] = o["xs"] - A @ Ks.T + Kx @ J @ Ks.T  # (16)
        o["ss"] = b["ss"] - Ks @ B.T - B @ Ks.T + Ks @ J @ Ks.T  # (17)
    o["xw"] = b["xw"] - Kx @ F.T  # (18)
    o["sw"] = b["sw"] - Ks @ F.T  # (19)
    # (20), (21): C_uw, C_vw unchanged; U_o, V_o, W_o unchanged.
    for a in "suvw":
        o[a + "x"] = o["x" + a].T
    for a, c in (("s", "u"), ("s", "v"), ("s", "w")):
        o[c + a] = o[a + c].T
    return assemble(o, L)


def wlsgan_literal_prop(Pnc, phi, Ts, L):
    """WLSGAN eqs. 1-3 (non-consider propagation)."""
    P, Cxs, Ps = Pnc[L.x, L.x], Pnc[L.x, L.s], Pnc[L.s, L.s]
    Cxs_m = phi @ Cxs + Ts @ Ps  # (2)
    P_m = (phi @ P + Ts @ Cxs.T) @ phi.T + Cxs_m @ Ts.T  # (1)
    return np.block([[P_m, Cxs_m], [Cxs_m.T, Ps]])  # (3)


def wlsgan_literal_gain(Pnc, H, R, L):
    """WLSGAN eqs. 4-11 (gain and non-consider update; signs rebuilt)."""
    P, Cxs, Ps = Pnc[L.x, L.x], Pnc[L.x, L.s], Pnc[L.s, L.s]
    Hx, Hs = H[:, L.x], H[:, L.s]
    A = P @ Hx.T + Cxs @ Hs.T  # (4)
    B = Ps @ Hs.T + Cxs.T @ Hx.T  # (5)
    J = Hx @ A + Hs @ B + R  # (6)
    Kx, Ks = ksgain_literal(A, B, J)  # (7), (8)
    Pp = P - Kx @ A.T  # (9)
    Cxsp = Cxs - Kx @ B.T  # (10)
    Psp = Ps - Ks @ B.T  # (11)
    return Kx, Ks, np.block([[Pp, Cxsp], [Cxsp.T, Psp]])


# Tolerance for every literal-vs-matrix comparison: both sides are the same sums of
# products in a different association order, so they differ by rounding only: ~n·eps times
# the condition number of J (< 1e3 here) in the scale-free metric -> 1e-12.
TOL = 1e-12


# ----------------------------------------------------------------------------- tests
@pytest.mark.parametrize("L,m", CASES)
def test_augmented_transition_is_prop_eq3(L, m):
    rng = np.random.default_rng(1)
    phi = rng.normal(size=(L.nx, L.nx))
    theta = rng.normal(size=(L.nx, L.n - L.nx))
    F = np.asarray(augmented_transition(f64(phi), f64(theta), L))
    nx = L.nx
    ref = np.eye(L.n)
    ref[:nx, :nx] = phi
    for r in "suw":  # v columns of Θ are dropped (Θ_xv = 0 in eq. 3)
        sl = getattr(L, r)
        ref[:nx, sl] = theta[:, sl.start - nx : sl.stop - nx]
    assert np.array_equal(F, ref)  # pure placement: exact
    assert not np.any(F[:nx, L.v])


@pytest.mark.parametrize("L,m", CASES)
def test_time_update_equals_prop_eqs_5_16(L, m):
    rng = np.random.default_rng(2)
    for _ in range(3):
        P, phi, theta, Q, H, R = random_problem(rng, L, m)
        F = augmented_transition(f64(phi), f64(theta), L)
        got = np.asarray(time_update(f64(P), F, f64(Q)))
        Ts, Tu, Tw = (theta[:, getattr(L, r).start - L.nx : getattr(L, r).stop - L.nx] for r in "suw")
        ref = prop_literal(P, phi, Ts, Tu, Tw, Q, L)
        assert scaled_err(got, ref, ref) < TOL
        assert np.array_equal(got, got.T)


@pytest.mark.parametrize("L,m", CASES)
def test_innovation_and_ks_gain_equal_filter_eqs_1_6_and_ksgain(L, m):
    rng = np.random.default_rng(3)
    for _ in range(3):
        P, phi, theta, Q, H, R = random_problem(rng, L, m)
        A, B, D, E, F, J = filter_residuals(P, H, R, L)
        A_all, J_got = innovation(f64(P), f64(H), f64(R))
        ref_all = np.vstack([A, B, D, E, F])
        # A_all rows have the unit of the state times measurement: scale per row and column.
        sr = np.sqrt(np.diag(P))[:, None] * np.sqrt(np.diag(J))[None, :]
        assert np.max(np.abs(np.asarray(A_all) - ref_all) / sr) < TOL
        assert scaled_err(J_got, J, J) < TOL
        Kx, Ks = ksgain_literal(A, B, J)
        K = np.asarray(kalman_schmidt_gain(f64(P), f64(H), f64(R), L))
        gs = np.sqrt(np.diag(P))[:, None] / np.sqrt(np.diag(J))[None, :]
        assert np.max(np.abs(K[L.x] - Kx) / gs[L.x]) < TOL
        assert np.max(np.abs(K[L.s] - Ks) / gs[L.s], initial=0.0) < TOL
        assert not np.any(K[L.n_est :])  # consider/ignore rows exactly zero


@pytest.mark.parametrize("L,m", CASES)
def test_ks_update_equals_filter_eqs_7_14_and_18_21(L, m):
    rng = np.random.default_rng(4)
    for _ in range(3):
        P, phi, theta, Q, H, R = random_problem(rng, L, m)
        A, B, D, E, F, J = filter_residuals(P, H, R, L)
        Kx, Ks = ksgain_literal(A, B, J)
        ref = filter_update_literal(P, A, B, D, E, F, J, Kx, Ks, L, general=False)
        K = kalman_schmidt_gain(f64(P), f64(H), f64(R), L)
        got = np.asarray(joseph_update(f64(P), f64(H), f64(R), K))
        # reference: the ~1e-12 literal tolerance, scaled by the prior variances (the update
        # subtracts O(prior) terms, so rounding is relative to the prior, not the posterior).
        assert scaled_err(got, ref, P) < TOL
        assert np.array_equal(got, got.T)
        # consider/ignore blocks are untouched (eqs. 14, 20, 21 and U_o, V_o, W_o)
        c = slice(L.n_est, L.n)
        assert np.allclose(got[c, c], P[c, c], rtol=0, atol=1e-14 * np.abs(P[c, c]).max())


@pytest.mark.parametrize("L,m", CASES)
def test_general_update_equals_filter_eqs_15_21(L, m):
    """True covariance (with w) updated with the gain of an ASSUMED covariance (w zeroed,
    different a-priori) and a different (true) R: eqs. 15-21."""
    rng = np.random.default_rng(5)
    for _ in range(3):
        P_true, phi, theta, Q, H, R_true = random_problem(rng, L, m)
        P_ass = random_cov(rng, L.n, np.sqrt(np.diag(P_true)) * 0.7)
        P_ass[L.w, :] = 0.0
        P_ass[:, L.w] = 0.0
        R_ass = 0.5 * R_true
        K = kalman_schmidt_gain(f64(P_ass), f64(H), f64(R_ass), L)
        Kn = np.asarray(K)
        A, B, D, E, F, J = filter_residuals(P_true, H, R_true, L)
        ref = filter_update_literal(P_true, A, B, D, E, F, J, Kn[L.x], Kn[L.s], L, general=True)
        got = np.asarray(joseph_update(f64(P_true), f64(H), f64(R_true), K))
        assert scaled_err(got, ref, P_true) < TOL
        assert np.array_equal(got, got.T)
        assert bool(psd_check(f64(got))[1])


@pytest.mark.parametrize("L,m", CASES)
def test_wls_equals_wlsgan_eqs_1_11(L, m):
    rng = np.random.default_rng(6)
    P, phi, theta, Q, H, R = random_problem(rng, L, m)
    Pnc = P[L.est, L.est].copy()
    F = augmented_transition(f64(phi), f64(theta), L)
    Ts = theta[:, : L.ns]
    for _ in range(3):
        ref = wlsgan_literal_prop(Pnc, phi, Ts, L)
        Pnc_got = np.asarray(wls_time_update(f64(Pnc), F, L))
        assert scaled_err(Pnc_got, ref, ref) < TOL
        Kx, Ks, Pnc_ref = wlsgan_literal_gain(ref, H, R, L)
        K, Pnc_plus = wls_gain(f64(Pnc_got), f64(H), f64(R), L)
        K = np.asarray(K)
        gs = np.sqrt(np.diag(ref))[:, None] / np.sqrt(np.diag(R))[None, :]
        assert np.max(np.abs(K[L.est] - np.vstack([Kx, Ks])) / gs) < TOL
        assert not np.any(K[L.n_est :])
        # Joseph form vs eqs. 9-11 (P - K Aᵀ): equal for the optimal gain; rounding is
        # relative to the prior.
        assert scaled_err(Pnc_plus, Pnc_ref, ref) < TOL
        # the knowledge covariance takes the WLS gain through eqs. 15-21
        A, B, D, E, Fw, J = filter_residuals(P, H, R, L)
        Pk_ref = filter_update_literal(P, A, B, D, E, Fw, J, K[L.x], K[L.s], L, general=True)
        Pk = np.asarray(joseph_update(f64(P), f64(H), f64(R), f64(K)))
        assert scaled_err(Pk, Pk_ref, P) < TOL
        Pnc = np.asarray(Pnc_plus)
        P = np.asarray(time_update(f64(Pk), F, f64(Q)))


def test_ks_gain_minimises_est_variance():
    """Optimality of KSGAIN, against the exact quadratic identity
    tr P⁺(K + δ)_est - tr P⁺(K)_est = tr(δ J δᵀ) > 0 (for K the KS gain, any est-row δ)."""
    L, m = CASES[0]
    rng = np.random.default_rng(7)
    P, phi, theta, Q, H, R = random_problem(rng, L, m)
    K = kalman_schmidt_gain(f64(P), f64(H), f64(R), L)
    _, J = innovation(f64(P), f64(H), f64(R))
    t0 = np.trace(np.asarray(joseph_update(f64(P), f64(H), f64(R), K))[L.est, L.est])
    for _ in range(5):
        d = np.zeros((L.n, m))
        d[L.est] = 1e-2 * rng.normal(size=(L.n_est, m)) * np.abs(np.asarray(K)[L.est]).max()
        t1 = np.trace(np.asarray(joseph_update(f64(P), f64(H), f64(R), K + f64(d)))[L.est, L.est])
        expect = np.trace(d @ np.asarray(J) @ d.T)
        assert expect > 0
        # the difference of two O(tr P) traces: rounding ~1e-15 tr P, and expect ~1e-4 tr P
        assert abs((t1 - t0) - expect) < 1e-9 * np.trace(P[L.est, L.est])


def test_symmetry_and_psd_kept_through_a_long_sequence():
    L, m = CASES[1]
    rng = np.random.default_rng(8)
    P, phi, theta, Q, H, R = random_problem(rng, L, m)
    F = augmented_transition(f64(phi * 0.9), f64(theta), L)  # stable, so the sequence settles
    Pj = f64(P)
    for _ in range(30):
        Pj = time_update(Pj, F, f64(Q))
        Hk = f64(rng.normal(size=(m, L.n)) / np.sqrt(np.diag(P))[None, :])
        Pj = joseph_update(Pj, Hk, f64(R), kalman_schmidt_gain(Pj, Hk, f64(R), L))
        Pn = np.asarray(Pj)
        assert np.array_equal(Pn, Pn.T)
        min_eig, ok = psd_check(Pj)
        assert bool(ok)
        # independent: numpy's eigenvalues of the correlation form are non-negative to rounding
        d = np.sqrt(np.diag(Pn))
        assert np.linalg.eigvalsh(Pn / np.outer(d, d)).min() > -1e-12


def test_psd_check_flags_indefinite_and_non_finite():
    rng = np.random.default_rng(9)
    s = np.array([1e4, 1.0, 1e-6, 3.0])  # 10 decades of units
    C = random_cov(rng, 4)
    P = C * np.outer(s, s)
    min_eig, ok = psd_check(f64(P))
    assert bool(ok) and float(min_eig) > 0
    assert np.isclose(float(min_eig), np.linalg.eigvalsh(P).min(), rtol=1e-6, atol=1e-20)
    # zero-variance row (mass with zero sigma) and a zero w block: PSD, ok
    Pz = P.copy()
    Pz[2, :] = Pz[:, 2] = 0.0
    assert bool(psd_check(f64(Pz))[1])
    # correlation 1 + 1e-3 between the 1e-6 and the 3.0 variables: indefinite, caught even
    # though the negative eigenvalue (~ -1e-9) is tiny next to the 1e8 variance
    Pb = np.diag(s**2)
    Pb[2, 3] = Pb[3, 2] = (1 + 1e-3) * s[2] * s[3]
    min_eig, ok = psd_check(f64(Pb))
    assert not bool(ok) and float(min_eig) < 0
    assert np.isclose(float(min_eig), np.linalg.eigvalsh(Pb).min(), rtol=1e-6)
    # correlation 1 - 1e-9 (rounding-level, legitimate): not flagged
    Pb[2, 3] = Pb[3, 2] = (1 - 1e-9) * s[2] * s[3]
    assert bool(psd_check(f64(Pb))[1])
    # rounding-level indefiniteness well inside the threshold: 1 + 0.1·PSD_TOLERANCE
    Pb[2, 3] = Pb[3, 2] = (1 + 0.1 * PSD_TOLERANCE) * s[2] * s[3]
    assert bool(psd_check(f64(Pb))[1])
    # a negative variance and a NaN
    Pn = P.copy()
    Pn[1, 1] = -1.0
    assert not bool(psd_check(f64(Pn))[1])
    Pn = P.copy()
    Pn[0, 3] = Pn[3, 0] = np.nan
    assert not bool(psd_check(f64(Pn))[1])


def test_correlations_by_hand():
    P = np.array([[4.0, 2.0, 0.0], [2.0, 9.0, 0.0], [0.0, 0.0, 0.0]])
    sigma, corr = correlations(f64(P))
    assert np.array_equal(np.asarray(sigma), [2.0, 3.0, 0.0])
    ref = np.array([[1.0, 2.0 / 6.0, 0.0], [2.0 / 6.0, 1.0, 0.0], [0.0, 0.0, 0.0]])
    assert np.allclose(np.asarray(corr), ref, rtol=0, atol=1e-15)  # one division: rounding
    assert np.all(np.isfinite(np.asarray(corr)))
