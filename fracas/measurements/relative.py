"""Relative (vehicle-to-vehicle) measurements of a two-vehicle study: range, range rate and
two line-of-sight angles, with their partials and noise models.

The Apollo rendezvous radar (Draper R-649 §II, Eqs. 4/12) and the Shuttle UNF's relative
codes c = 0-3 (NASA CR-134276 nomenclature; digest ``unf-apollo.md`` §A.3.2-A.3.5, B.1).
Everything is a function of the RELATIVE state (target minus chaser, "active")::

    r_rho = r_T - r_A  (km),   v_rho = v_T - v_A  (km/s),   rho = |r_rho|,  i_rho = r_rho / rho

    range          q = rho                                        (km)      UNF c = 0
    range_rate     q = i_rho . v_rho                              (km/s)    UNF c = 1
    los_beta       q = atan2(z, x)                                (rad)     UNF c = 2, beta
    los_theta      q = atan2(y, rho_a),  rho_a = sqrt(x^2 + z^2)  (rad)     UNF c = 3, theta

with (x, y, z) = M r_rho the components in the sensor axes (rows of ``M``: i_xm, i_ym, i_zm;
for the Apollo radar the IMU stable platform, an inertial frame; identity by default).  The
angle definitions are rebuilt ([R] in the digest: the UNF's Fig. 1-3 is lost): beta is the
angle of the projection on the xm-zm plane, theta the angle out of it toward i_ym.

Partials: ``g = dq/d(r_rho, v_rho)`` (6,).  R-649's rule b_T = -b_A = b_R: the chaser's
H row is -g and the target's is +g (:func:`vehicle_rows`).  The sensor-misalignment partial
(small rotation phi of the sensor axes, i' = i + phi x i) is dq/dphi = g_r x r_rho
(digest §A.3.5, [R, verified]) and is tested against central differences.

Noise (R-649 Fig. II-4): constant sigma (UNF) or proportional to the measured magnitude with
a floor, sigma = max(fraction |q|, floor) (Apollo: 1/3 % of range, 1.3/3 % of range rate,
1 mrad per angle; the floor keeps the range-rate variance from vanishing as rdot -> 0, as
the AGC's RVARMIN/VVARMIN did).

Pure JAX (float64); jit- and vmap-able; nothing raises.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax import Array
from jax.typing import ArrayLike

from fracas import _jax  # noqa: F401  (float64 before any array exists)

__all__ = [
    "RELATIVE_KINDS",
    "RELATIVE_UNITS",
    "relative_state",
    "relative_value",
    "relative_partials",
    "misalignment_partials",
    "vehicle_rows",
    "noise_sigma",
    "relative_measurement",
]

#: kind name -> (UNF code, canonical unit)
RELATIVE_KINDS = {"range": (0, "km"), "range_rate": (1, "km/s"), "los_beta": (2, "rad"), "los_theta": (3, "rad")}
RELATIVE_UNITS = {k: u for k, (_, u) in RELATIVE_KINDS.items()}
_INDEX = {k: i for i, k in enumerate(RELATIVE_KINDS)}


def _f64(x: ArrayLike) -> Array:
    return jnp.asarray(x, dtype=jnp.float64)


def relative_state(x_chaser: ArrayLike, x_target: ArrayLike) -> tuple[Array, Array]:
    """(r_rho km, v_rho km/s) = target - chaser, from two (6,) or (>=6,) states."""
    xa, xt = _f64(x_chaser), _f64(x_target)
    return xt[:3] - xa[:3], xt[3:6] - xa[3:6]


def _range(r: Array, v: Array, M: Array) -> Array:
    return jnp.linalg.norm(r)


def _range_rate(r: Array, v: Array, M: Array) -> Array:
    return jnp.dot(r, v) / jnp.linalg.norm(r)


def _beta(r: Array, v: Array, M: Array) -> Array:
    s = M @ r
    return jnp.arctan2(s[2], s[0])


def _theta(r: Array, v: Array, M: Array) -> Array:
    s = M @ r
    return jnp.arctan2(s[1], jnp.sqrt(s[0] ** 2 + s[2] ** 2))


_MODELS = (_range, _range_rate, _beta, _theta)


def relative_value(kind: str, r_rho: ArrayLike, v_rho: ArrayLike, axes: ArrayLike | None = None) -> Array:
    """The model value of ``kind`` (km, km/s or rad) at the relative state; ``axes`` (3, 3):
    rows i_xm, i_ym, i_zm of the sensor frame in inertial axes (identity when None)."""
    M = jnp.eye(3, dtype=jnp.float64) if axes is None else _f64(axes)
    return _MODELS[_INDEX[kind]](_f64(r_rho), _f64(v_rho), M)


def _g_range(r: Array, v: Array, M: Array) -> Array:
    u = r / jnp.linalg.norm(r)
    return jnp.concatenate([u, jnp.zeros(3, dtype=jnp.float64)])


def _g_range_rate(r: Array, v: Array, M: Array) -> Array:
    rho = jnp.linalg.norm(r)
    u = r / rho
    rdot = jnp.dot(u, v)
    return jnp.concatenate([(v - rdot * u) / rho, u])


def _g_beta(r: Array, v: Array, M: Array) -> Array:
    x, _, z = M @ r
    d = (x * M[2] - z * M[0]) / (x**2 + z**2)
    return jnp.concatenate([d, jnp.zeros(3, dtype=jnp.float64)])


def _g_theta(r: Array, v: Array, M: Array) -> Array:
    x, y, z = M @ r
    rho_a = jnp.sqrt(x**2 + z**2)
    i_rho_a = (x * M[0] + z * M[2]) / rho_a
    d = (rho_a * M[1] - y * i_rho_a) / jnp.dot(r, r)
    return jnp.concatenate([d, jnp.zeros(3, dtype=jnp.float64)])


_PARTIALS = (_g_range, _g_range_rate, _g_beta, _g_theta)


def relative_partials(kind: str, r_rho: ArrayLike, v_rho: ArrayLike, axes: ArrayLike | None = None) -> Array:
    """g = dq/d(r_rho, v_rho) (6,), in kind units per km and per km/s (UNF b-vector w.r.t. the
    relative state; digest §A.3.2-A.3.5):

    * range:       (i_rho, 0)
    * range_rate:  ((v_rho - rdot i_rho)/rho, i_rho)
    * los_beta:    ((x i_zm - z i_xm)/rho_a^2, 0)
    * los_theta:   ((rho_a i_ym - y i_rho_a)/rho^2, 0),   i_rho_a = (x i_xm + z i_zm)/rho_a
    """
    M = jnp.eye(3, dtype=jnp.float64) if axes is None else _f64(axes)
    return _PARTIALS[_INDEX[kind]](_f64(r_rho), _f64(v_rho), M)


def misalignment_partials(kind: str, r_rho: ArrayLike, v_rho: ArrayLike, axes: ArrayLike | None = None) -> Array:
    """dq/dphi (3,) rad per rad, for a small rotation phi of the sensor axes (i' = i + phi x i):
    g_r x r_rho (digest §A.3.5).  Zero for range and range rate, which do not depend on the axes."""
    if kind in ("range", "range_rate"):
        return jnp.zeros(3, dtype=jnp.float64)
    g = relative_partials(kind, r_rho, v_rho, axes)
    return jnp.cross(g[:3], _f64(r_rho))


def vehicle_rows(g: Array) -> tuple[Array, Array]:
    """(b_A, b_T): the chaser's and the target's H rows (6,) each, b_T = -b_A = g (R-649 §II.B)."""
    return -g, g


def noise_sigma(q: ArrayLike, sigma: ArrayLike, fraction: ArrayLike, floor: ArrayLike) -> Array:
    """White-noise sigma of a measurement of value ``q``: ``sigma`` when ``fraction`` is 0,
    else max(fraction |q|, floor) (R-649 Fig. II-4's proportional model with a floor).  Same
    unit as q."""
    q, sigma, fraction, floor = _f64(q), _f64(sigma), _f64(fraction), _f64(floor)
    return jnp.where(fraction > 0.0, jnp.maximum(fraction * jnp.abs(q), floor), sigma)


@jax.jit
def _all(x_chaser: Array, x_target: Array, axes: Array) -> tuple[Array, Array, Array]:
    r, v = relative_state(x_chaser, x_target)
    vals = jnp.stack([f(r, v, axes) for f in _MODELS])
    gs = jnp.stack([f(r, v, axes) for f in _PARTIALS])
    angle = jnp.array([0.0, 0.0, 1.0, 1.0], dtype=jnp.float64)[:, None]
    mis = angle * jnp.stack([jnp.cross(g[:3], r) for g in gs])
    return vals, gs, mis


def relative_measurement(
    x_chaser: ArrayLike, x_target: ArrayLike, axes: ArrayLike | None = None
) -> tuple[Array, Array, Array]:
    """Every relative kind at once (one compiled kernel): values (4,) in RELATIVE_KINDS order,
    partials g (4, 6) w.r.t. the relative state, misalignment partials (4, 3)."""
    M = jnp.eye(3, dtype=jnp.float64) if axes is None else _f64(axes)
    return _all(_f64(x_chaser), _f64(x_target), M)
