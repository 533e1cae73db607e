"""Shared helpers of the filter-algebra tests: random covariances and a scale-free error."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np


def f64(a):
    return jnp.asarray(a, dtype=jnp.float64)


def random_cov(rng, n, scales=None):
    """Random SPD matrix with correlations everywhere and condition number ~1e2; ``scales``
    (n,) or a scalar multiplies the standard deviations (default 1)."""
    B = rng.normal(size=(n, n))
    C = B @ B.T + 0.5 * n * np.eye(n)
    d = np.sqrt(np.diag(C))
    C = C / np.outer(d, d)
    s = np.ones(n) if scales is None else np.broadcast_to(np.asarray(scales, dtype=np.float64), (n,))
    return C * np.outer(s, s)


def scaled_err(P1, P2, ref):
    """max |P1 - P2| in the scale-free metric D^-1/2 (.) D^-1/2, D = diag(ref)."""
    d = np.sqrt(np.abs(np.diag(np.asarray(ref))))
    d = np.where(d > 0, d, 1.0)
    return np.max(np.abs(np.asarray(P1) - np.asarray(P2)) / np.outer(d, d))
