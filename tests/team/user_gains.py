"""A user gain for the TEAM tests (filter.type = "user"): the Kalman-Schmidt gain written
out with jax.numpy, so a run with it must equal the built-in Kalman-Schmidt run."""

import jax.numpy as jnp


def ks_gain(P, H, R, layout):
    """K_est (n_est, m) = P[est] Hᵀ (H P Hᵀ + R)⁻¹ (FRACAS KSGAIN; J⁻¹ applied by a solve)."""
    J = H @ P @ H.T + R
    A_est = P[: layout.n_est] @ H.T
    return jnp.linalg.solve(J, A_est.T).T
