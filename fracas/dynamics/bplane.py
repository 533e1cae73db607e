"""B-plane targeting parameters of a hyperbolic approach (FRACAS BPLANE).

Pure ``jax.numpy`` (jit/vmap/forward and reverse AD).  Units km, s, rad; the state is
relative to the target body, in any inertial frame (ICRF/EME2000 in fracas), and
``ref_pole`` is the reference pole in that same frame.

Conventions (standard, e.g. Kizner 1961; Vallado sec. 12.7):

* S = unit vector along the incoming asymptote (direction of the approach v_inf),
  S = e_vec/e^2 + (sqrt(e^2 - 1)/e) (h_hat x e_vec/e);
* T = (S x ref_pole)/|S x ref_pole| (in the reference equator plane), R = S x T;
* B = vector from the body centre to the point of the incoming asymptote nearest to
  it; it lies in the orbit plane normal to S: B = b (S x h_hat), with
  b = |B| = h/v_inf = |a| sqrt(e^2 - 1) = -a sqrt(e^2 - 1) for the a < 0 convention;
* theta = atan2(B . R, B . T): angle of B measured from T toward R;
* v_inf = sqrt(v^2 - 2 mu/r); periapsis radius r_p = p/(1 + e) with p = h^2/mu
  (equal to |a| (e - 1) without its cancellation at e ~ 1);
* time to periapsis from the hyperbolic mean anomaly: sinh H = (r . v)/(e sqrt(mu |a|)),
  M = e sinh H - H = (r . v)/sqrt(mu |a|) - H, t_ca = -M/n with n = sqrt(mu/|a|^3)
  (positive while approaching).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax import Array
from jax.typing import ArrayLike

from fracas import _jax  # noqa: F401  (float64 + compilation cache before any array)

__all__ = ["BPlane", "b_plane"]


class BPlane(NamedTuple):
    """Result of :func:`b_plane` (all float64 arrays; vectors have a trailing axis 3)."""

    b_dot_t: jnp.ndarray  # km
    b_dot_r: jnp.ndarray  # km
    b_mag: jnp.ndarray  # km, |B| (impact parameter)
    theta: jnp.ndarray  # rad, angle of B from T toward R, in (-pi, pi]
    v_inf: jnp.ndarray  # km/s, hyperbolic excess speed
    t_closest_approach: jnp.ndarray  # s from the given state to periapsis (>0 if ahead)
    r_closest_approach: jnp.ndarray  # km, periapsis radius
    s_hat: jnp.ndarray  # unit incoming-asymptote direction
    t_hat: jnp.ndarray  # unit T
    r_hat: jnp.ndarray  # unit R


def _dot(x: Array, y: Array) -> Array:
    return jnp.sum(x * y, axis=-1)


def _norm(x: Array) -> Array:
    return jnp.sqrt(_dot(x, x))


def _t_r_axes(s_hat: Array, pole: Array, shape: tuple[int, ...]) -> tuple[Array, Array]:
    """T = unit(S x pole) and R = S x T, with a fallback reference (x_hat, else y_hat) when
    S is (nearly) parallel to the pole; ``shape``: the states' (..., 3)."""
    sxp = jnp.cross(s_hat, pole)
    n_sxp = _dot(sxp, sxp)
    bad = n_sxp < 1e-24
    alt = jnp.where(
        (jnp.abs(s_hat[..., 0]) < 0.9)[..., None],
        jnp.broadcast_to(jnp.array([1.0, 0.0, 0.0]), shape),
        jnp.broadcast_to(jnp.array([0.0, 1.0, 0.0]), shape),
    )
    t_raw = jnp.where(bad[..., None], jnp.cross(s_hat, alt), sxp)
    t_hat = t_raw / _norm(t_raw)[..., None]
    return t_hat, jnp.cross(s_hat, t_hat)


@jax.jit
def b_plane(
    r: ArrayLike, v: ArrayLike, mu: ArrayLike, ref_pole: ArrayLike | Sequence[float] = (0.0, 0.0, 1.0)
) -> BPlane:
    """B-plane parameters of the hyperbolic approach state (r km, v km/s) relative to a
    body of gravitational parameter ``mu`` (km^3/s^2) (FRACAS BPLANE).

    See the module docstring for the conventions.  ``ref_pole`` (any non-zero vector, not
    parallel to S) defines T; if S is parallel to it to within 1e-12 rad, T falls back to
    S x x_hat (or S x y_hat) so the result stays finite.  States that are not hyperbolic
    (e <= 1) return NaN in every field; gradients are finite for hyperbolic states.
    """
    r = jnp.asarray(r, dtype=jnp.float64)
    v = jnp.asarray(v, dtype=jnp.float64)
    pole = jnp.asarray(ref_pole, dtype=jnp.float64)
    pole = jnp.broadcast_to(pole / _norm(pole)[..., None], r.shape)

    rmag = _norm(r)
    h = jnp.cross(r, v)
    hmag = _norm(h)
    w = h / hmag[..., None]
    e_vec = jnp.cross(v, h) / mu - r / rmag[..., None]
    e2 = _dot(e_vec, e_vec)
    v_inf2 = _dot(v, v) - 2.0 * mu / rmag

    hyp = (e2 > 1.0) & (v_inf2 > 0.0)
    e2s = jnp.where(hyp, e2, 4.0)
    e = jnp.sqrt(e2s)
    vinf = jnp.sqrt(jnp.where(hyp, v_inf2, 1.0))
    a_abs = mu / (vinf * vinf)
    sq = jnp.sqrt(e2s - 1.0)

    p_hat = e_vec / e[..., None]
    q_hat = jnp.cross(w, p_hat)
    s_hat = (p_hat + sq[..., None] * q_hat) / e[..., None]
    b_mag = hmag / vinf
    b_vec = b_mag[..., None] * jnp.cross(s_hat, w)

    t_hat, r_hat = _t_r_axes(s_hat, pole, r.shape)
    bt = _dot(b_vec, t_hat)
    br = _dot(b_vec, r_hat)
    theta = jnp.arctan2(br, bt)

    p = hmag * hmag / mu
    r_p = p / (1.0 + e)
    d = _dot(r, v)
    k = jnp.sqrt(mu * a_abs)
    H = jnp.arcsinh(d / (e * k))
    M = d / k - H
    n = jnp.sqrt(mu / a_abs**3)
    t_ca = -M / n

    nan = jnp.nan

    def sel(x: Array) -> Array:
        mask = hyp if x.ndim == hyp.ndim else hyp[..., None]
        return jnp.where(mask, x, nan)

    return BPlane(
        b_dot_t=sel(bt),
        b_dot_r=sel(br),
        b_mag=sel(b_mag),
        theta=sel(theta),
        v_inf=sel(vinf),
        t_closest_approach=sel(t_ca),
        r_closest_approach=sel(r_p),
        s_hat=sel(s_hat),
        t_hat=sel(t_hat),
        r_hat=sel(r_hat),
    )
