"""Eigenvector events (fracas.team.eigen) against direct numpy reconstruction."""

import numpy as np

from fracas.team.eigen import eigen_summary


def _random_cov(n, seed):
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(n, n)) * np.logspace(3, -6, n)[:, None]  # km .. km/s .. parameters
    return A @ A.T


def test_eigen_summary_reconstructs_blocks():
    """sigma and correlations are the textbook sqrt(P_ii), P_ij/(s_i s_j); the position and
    velocity eigen-pairs rebuild their 3x3 blocks.  Tolerance 1e-12 relative to the block
    norm: one eigendecomposition of a 3x3 symmetric matrix loses a few ulps."""
    P = _random_cov(9, 1)
    e = eigen_summary(P)
    s = np.sqrt(np.diag(P))
    np.testing.assert_allclose(e.sigma, s, rtol=1e-14)
    np.testing.assert_allclose(e.corr, P / np.outer(s, s), rtol=0, atol=1e-13)
    for blk, w, ax, V in (
        (slice(0, 3), e.pos_eigval, e.pos_axes, e.pos_eigvec),
        (slice(3, 6), e.vel_eigval, e.vel_axes, e.vel_eigvec),
    ):
        B = P[blk, blk]
        assert np.all(np.diff(w) >= 0)  # ascending
        np.testing.assert_allclose(V @ np.diag(w) @ V.T, B, rtol=0, atol=1e-12 * np.linalg.norm(B))
        np.testing.assert_allclose(V.T @ V, np.eye(3), atol=1e-13)
        np.testing.assert_allclose(ax, np.sqrt(w), rtol=1e-14)
        big = np.argmax(np.abs(V), axis=0)
        assert np.all(V[big, np.arange(3)] > 0)  # sign convention: largest component positive
    assert np.isclose(e.pos_rss, np.sqrt(np.trace(P[:3, :3])), rtol=1e-14)


def test_eigen_summary_zero_variance_row():
    """A parameter with zero variance (an assumed covariance's ignore block) gets sigma 0 and
    zero correlations, never NaN."""
    P = _random_cov(8, 2)
    P[7, :] = P[:, 7] = 0.0
    e = eigen_summary(P)
    assert e.sigma[7] == 0.0 and np.all(e.corr[7] == 0.0) and np.all(np.isfinite(e.corr))
