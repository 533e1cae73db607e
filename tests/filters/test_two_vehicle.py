"""The two-vehicle filter algebra (fracas.filters.two_vehicle) against independent forms:
the digest's C.3 list of identities (``shared/seeds/digests/unf-apollo.md`` §C.3 item 1).

References and tolerances:

* the augmented Schmidt-Kalman update of [x_A; x_T; beta] written directly from
  E[(e - k dQ)(e - k dQ)'] (an independent derivation, not the module's scalar_joseph);
* Potter's square-root update (fracas.filters.square_root) vs the Kalman formula;
* the identities omega_T - omega_A = omega_R (R-649 Eq. 16), Eq. 16 = Eq. 8 under b_T = -b_A
  and GRb = GTb - GAb, E_R = E_A + E_T - G - G' preserved through the update, and SSU with
  E_T = 0 equal to the optimum filter (§B.9).

The covariances are random, well conditioned (condition number < 1e4) with km/km/s-like
scales; every comparison is relative to the largest entry and uses 1e-10, about 1e5
machine epsilons: a few hundred flops of products of numbers of condition <= 1e4.  A
transcription error in any term of Eqs. 18-24 changes entries at O(1) relative.

Scan defects rebuilt (asserted here by the equality with the augmented update): Eq. 18's
truncated bracket, Eq. 22's missing transpose, App. B-6's b_a (see the module docstring).
"""

import numpy as np
import pytest

from fracas.filters import two_vehicle as tv
from fracas.filters.square_root import potter_update

TOL = 1e-10


def _random_case(seed, nb=3):
    rng = np.random.default_rng(seed)
    n = 12 + nb
    scale = np.concatenate([[3.0] * 3, [3e-3] * 3, [5.0] * 3, [5e-3] * 3, [1e-3] * nb])
    A = rng.standard_normal((n, n))
    Q, _ = np.linalg.qr(A)
    eig = np.exp(rng.uniform(np.log(1e-2), np.log(1e2), n))
    C = Q @ np.diag(eig) @ Q.T
    P = scale[:, None] * C * scale[None, :]
    g = rng.standard_normal(6) * np.concatenate([[1.0] * 3, [100.0] * 3])
    bA, bT = -g, g  # b_T = -b_A = b_R (R-649 §II.B)
    bb = rng.standard_normal(nb)
    alpha2 = 0.5 * float(np.concatenate([bA, bT, bb]) @ P @ np.concatenate([bA, bT, bb]))
    return P, np.asarray(bA), np.asarray(bT), bb, alpha2


def _rel(a, b):
    a, b = np.asarray(a), np.asarray(b)
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300))


def _augmented_update(P, h, alpha2, k):
    """E[(e - k dQ)(e - k dQ)'] with dQ = h'e + alpha: P - k h'P - P h k' + k (h'P h + alpha^2) k'."""
    Ph = P @ h
    return P - np.outer(k, Ph) - np.outer(Ph, k) + (h @ Ph + alpha2) * np.outer(k, k)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_eq20_block_update_equals_augmented_schmidt_update(seed):
    P, bA, bT, bb, a2 = _random_case(seed)
    blocks = tv.unstack(P)
    wA, wT, A = tv.optimum_gains(*blocks, bA, bT, bb, a2)
    h = np.concatenate([bA, bT, bb])
    mask = np.r_[np.ones(12), np.zeros(len(bb))]
    k_ref = mask * (P @ h) / (h @ P @ h + a2)  # Schmidt: biases considered
    assert _rel(np.concatenate([wA, wT]), k_ref[:12]) < TOL
    assert abs(float(A) - (h @ P @ h + a2)) / (h @ P @ h + a2) < TOL
    P_ref = _augmented_update(P, h, a2, k_ref)
    P_blk = np.asarray(tv.stack(*tv.block_update(*blocks, bA, bT, bb, a2, wA, wT)))
    assert _rel(P_blk, P_ref) < TOL


@pytest.mark.parametrize("seed", [3, 4])
def test_block_update_with_arbitrary_gains_equals_augmented_update(seed):
    """Eqs. 18-24 hold for any gains (the generalized-covariance use): random omega's."""
    P, bA, bT, bb, a2 = _random_case(seed)
    rng = np.random.default_rng(seed + 100)
    wA, wT = rng.standard_normal(6) * 0.1, rng.standard_normal(6) * 0.1
    k = np.concatenate([wA, wT, np.zeros(len(bb))])
    P_ref = _augmented_update(P, np.concatenate([bA, bT, bb]), a2, k)
    P_blk = np.asarray(tv.stack(*tv.block_update(*tv.unstack(P), bA, bT, bb, a2, wA, wT)))
    assert _rel(P_blk, P_ref) < TOL


def test_stacked_engine_update_equals_augmented_update():
    """The engine's masked_gain + scalar_joseph against the direct expectation."""
    P, bA, bT, bb, a2 = _random_case(5)
    h = np.concatenate([bA, bT, bb])
    for mask in (np.r_[np.ones(12), np.zeros(3)], np.r_[np.ones(6), np.zeros(9)], np.ones(15)):
        k = np.asarray(tv.masked_gain(P, h, a2, mask))
        k_ref = mask * (P @ h) / (h @ P @ h + a2)
        assert _rel(k, k_ref) < TOL
        assert _rel(tv.scalar_joseph(P, h, a2, k), _augmented_update(P, h, a2, k_ref)) < TOL


@pytest.mark.parametrize("seed", [6, 7])
def test_eq16_is_omega_T_minus_omega_A_and_equals_eq8(seed):
    P, bA, bT, bb, a2 = _random_case(seed)
    E_A, E_T, G, GAb, GTb, E_b = tv.unstack(P)
    wA, wT, _ = tv.optimum_gains(E_A, E_T, G, GAb, GTb, E_b, bA, bT, bb, a2)
    w16 = tv.relative_gain_eq16(E_A, E_T, G, GAb, GTb, E_b, bA, bT, bb, a2)
    assert _rel(w16, np.asarray(wT) - np.asarray(wA)) < TOL
    w8, A8 = tv.relative_gain_eq8(tv.relative_covariance(E_A, E_T, G), GTb - GAb, E_b, bT, bb, a2)
    assert _rel(w8, w16) < TOL


@pytest.mark.parametrize("seed", [8, 9])
def test_relative_covariance_preserved_through_update(seed):
    """E_R after the two-vehicle update equals the relative-state Schmidt update (Eq. 7) of
    E_R before it: the optimum inertial updates give the optimum relative update (R-649 p. 382)."""
    P, bA, bT, bb, a2 = _random_case(seed)
    E_A, E_T, G, GAb, GTb, E_b = tv.unstack(P)
    wA, wT, _ = tv.optimum_gains(E_A, E_T, G, GAb, GTb, E_b, bA, bT, bb, a2)
    EA1, ET1, G1, *_ = tv.block_update(E_A, E_T, G, GAb, GTb, E_b, bA, bT, bb, a2, wA, wT)
    ER1 = tv.relative_covariance(EA1, ET1, G1)
    # relative-state Schmidt update, Eq. 7, on [x_R; beta] with h = [b_R; b_b]
    ER, GRb = np.asarray(tv.relative_covariance(E_A, E_T, G)), GTb - GAb
    Pr = np.block([[ER, GRb], [GRb.T, E_b]])
    hr = np.concatenate([bT, bb])
    kr = np.r_[np.ones(6), np.zeros(len(bb))] * (Pr @ hr) / (hr @ Pr @ hr + a2)
    Pr1 = _augmented_update(Pr, hr, a2, kr)
    assert _rel(ER1, Pr1[:6, :6]) < TOL


def test_ssu_with_zero_target_errors_equals_optimum_filter():
    P, bA, bT, bb, a2 = _random_case(10)
    P[6:12, :] = 0.0
    P[:, 6:12] = 0.0  # E_T = 0, G = 0, GTb = 0
    blocks = tv.unstack(P)
    wA_opt, wT_opt, _ = tv.optimum_gains(*blocks, bA, bT, bb, a2)
    wA_ssu, wT_ssu = tv.ssu_gains(*blocks, bA, bT, bb, a2)
    assert _rel(wA_ssu, wA_opt) < TOL
    assert np.max(np.abs(np.asarray(wT_opt))) == 0.0 and np.max(np.abs(np.asarray(wT_ssu))) == 0.0
    upd_opt = tv.stack(*tv.block_update(*blocks, bA, bT, bb, a2, wA_opt, wT_opt))
    upd_ssu = tv.stack(*tv.block_update(*blocks, bA, bT, bb, a2, wA_ssu, wT_ssu))
    assert _rel(upd_ssu, upd_opt) < TOL


def test_apollo_gain_is_eq26_and_the_ignore_role_gain():
    """Eq. 26 equals the stacked gain of an assumed covariance whose target rows are zero
    (the target as ignore parameter), with the biases absent (Apollo filter basis)."""
    P, bA, bT, bb, a2 = _random_case(11, nb=0)
    W = P[:6, :6]
    w26 = tv.apollo_gain(W, bA, a2)
    Pa = np.zeros_like(P)
    Pa[:6, :6] = W
    k = tv.masked_gain(Pa, np.concatenate([bA, bT]), a2, np.r_[np.ones(6), np.zeros(6)])
    assert _rel(k[:6], w26) < TOL
    assert float(np.max(np.abs(np.asarray(k[6:])))) == 0.0


def test_square_root_update_equals_kalman_update():
    """Potter's W' = W - gamma k z' (UNF's z, c, omega, gamma; digest §A.4.1) against
    E - E b b'E / (b'E b + alpha^2), all states estimated (biases solve-for)."""
    P, bA, bT, bb, a2 = _random_case(12)
    W = np.linalg.cholesky(P)
    h = np.concatenate([bA, bT, bb])
    W1 = np.asarray(potter_update(W, h, np.float64(a2)))
    K = P @ h / (h @ P @ h + a2)
    assert _rel(W1 @ W1.T, P - np.outer(K, P @ h)) < TOL
