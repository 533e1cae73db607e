"""Small safe vector helpers of :mod:`fracas.dynamics.elements` (norms with finite gradients at
zero, angle wrapping), shared by its conic and frame modules.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from fracas import _jax  # noqa: F401  (float64 + compilation cache before any array)

TWO_PI = 2.0 * jnp.pi


def _dot(x: jax.Array, y: jax.Array) -> jax.Array:
    return jnp.sum(x * y, axis=-1)


def _norm(x: jax.Array) -> jax.Array:
    """Euclidean norm for vectors known to be non-zero."""
    return jnp.sqrt(_dot(x, x))


def _safe_norm(x: jax.Array) -> jax.Array:
    """Euclidean norm with a zero (not NaN) gradient at x == 0."""
    sq = _dot(x, x)
    pos = sq > 0.0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, sq, 1.0)), 0.0)


def _wrap_2pi(x: jax.Array) -> jax.Array:
    """Angle in [0, 2 pi) (gradient 1)."""
    y = jnp.mod(x, TWO_PI)
    return jnp.where(y >= TWO_PI, y - TWO_PI, y)


def _stack3(x: jax.Array, y: jax.Array, z: jax.Array) -> jax.Array:
    return jnp.stack([x, y, z], axis=-1)
