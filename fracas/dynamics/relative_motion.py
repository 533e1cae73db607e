"""Relative motion about a circular orbit: the Clohessy-Wiltshire transition matrix and the
inertial <-> local-vertical (Hill) transforms.

The UNF station-keeping phase extrapolates the relative state with a transition matrix
"derived by linearizing differential gravity" about a low-eccentricity target orbit
(CR-134276 Fig. 5-3, lost; digest ``unf-apollo.md`` §A.5.2): that matrix is the
Clohessy-Wiltshire (Hill) STM, rebuilt here.  fracas itself differences two float64
inertial states (each vehicle with its own STM), so this is the analytic check of that
machinery (``tests/dynamics/test_relative_motion.py``), and a quick tool for analysts.

Hill frame of a target at (r, v): x radial (r/|r|), z orbit normal ((r x v)/|r x v|),
y = z x x (along-track); the frame rotates at omega = (r x v)/r^2.  Units: km, km/s, s,
rad/s.  Pure JAX, float64.
"""

from __future__ import annotations

import jax.numpy as jnp
from jax import Array
from jax.typing import ArrayLike

from fracas import _jax  # noqa: F401  (float64 before any array exists)

__all__ = ["cw_stm", "hill_axes", "to_hill", "from_hill"]


def cw_stm(n: ArrayLike, dt: ArrayLike) -> Array:
    """Clohessy-Wiltshire STM (6, 6) for the Hill-frame state (x, y, z, xd, yd, zd) over dt s,
    mean motion n rad/s::

        xdd - 2 n yd - 3 n^2 x = 0,   ydd + 2 n xd = 0,   zdd + n^2 z = 0
    """
    n = jnp.asarray(n, dtype=jnp.float64)
    t = jnp.asarray(dt, dtype=jnp.float64)
    s, c = jnp.sin(n * t), jnp.cos(n * t)
    z = jnp.zeros((), dtype=jnp.float64)
    one = jnp.ones((), dtype=jnp.float64)
    rows = [
        [4 - 3 * c, z, z, s / n, 2 * (1 - c) / n, z],
        [6 * (s - n * t), one, z, -2 * (1 - c) / n, (4 * s - 3 * n * t) / n, z],
        [z, z, c, z, z, s / n],
        [3 * n * s, z, z, c, 2 * s, z],
        [-6 * n * (1 - c), z, z, -2 * s, 4 * c - 3, z],
        [z, z, -n * s, z, z, c],
    ]
    return jnp.stack([jnp.stack([jnp.asarray(e, dtype=jnp.float64) for e in row]) for row in rows])


def hill_axes(r: ArrayLike, v: ArrayLike) -> tuple[Array, Array]:
    """Rows (x radial, y along-track, z normal) of the Hill frame (3, 3) and its angular
    velocity omega (3,) rad/s, for a reference at r km, v km/s."""
    r = jnp.asarray(r, dtype=jnp.float64)
    v = jnp.asarray(v, dtype=jnp.float64)
    h = jnp.cross(r, v)
    ix = r / jnp.linalg.norm(r)
    iz = h / jnp.linalg.norm(h)
    iy = jnp.cross(iz, ix)
    return jnp.stack([ix, iy, iz]), h / jnp.dot(r, r)


def to_hill(x_ref: ArrayLike, x: ArrayLike) -> Array:
    """Hill-frame relative state (6,) of inertial state ``x`` about ``x_ref`` (both (6,))."""
    x_ref = jnp.asarray(x_ref, dtype=jnp.float64)
    x = jnp.asarray(x, dtype=jnp.float64)
    C, w = hill_axes(x_ref[:3], x_ref[3:6])
    dr, dv = x[:3] - x_ref[:3], x[3:6] - x_ref[3:6]
    return jnp.concatenate([C @ dr, C @ (dv - jnp.cross(w, dr))])


def from_hill(x_ref: ArrayLike, rel: ArrayLike) -> Array:
    """Inertial state (6,) whose Hill-frame state about ``x_ref`` is ``rel`` (inverse of to_hill)."""
    x_ref = jnp.asarray(x_ref, dtype=jnp.float64)
    rel = jnp.asarray(rel, dtype=jnp.float64)
    C, w = hill_axes(x_ref[:3], x_ref[3:6])
    dr = C.T @ rel[:3]
    dv = C.T @ rel[3:] + jnp.cross(w, dr)
    return jnp.concatenate([x_ref[:3] + dr, x_ref[3:6] + dv])
