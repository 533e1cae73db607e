"""Correlated a-priori orbit covariance from energy and angular-momentum pseudo-measurements
(Shuttle UNF W initialization, digest unf-apollo.md A.6.1-A.6.3, A.3.10; docs/process_noise.md).

The UNF starts from a diagonal filter-weighting matrix W (E = W W^T) with position and
velocity sigmas, optionally with separate (smaller) crosstrack values given in local-vertical
(LV) axes and rotated to the reference axes (A.6.1), then incorporates a pseudo measurement
of the orbital energy and one of the angular-momentum magnitude as W-only updates (no state
correction, s_Wcorr = 1; A.6.3) with the standard sequential scalar square-root update
(A.4.1; here :func:`fracas.filters.square_root.potter_update`), so that

    E' = E - E b b^T E / (b^T E b + sigma^2)

for each pseudo measurement, b its partials (A.3.10, [R] in the digest)::

    E = v^2/2 - mu/r :  dE/dr = mu r / r^3,   dE/dv = v                        (km^2/s^2)
    H = |r x v|      :  dH/dr = v x i_h,      dH/dv = i_h x r,   i_h = r x v / H  (km^2/s)

LV axes (Draper convention, digest A.6.1): i_z = -unit(r), i_y = -unit(r x v),
i_x = i_y x i_z; M_R-LV has rows i_x, i_y, i_z, and E_ref = T E_LV T^T with
T = blockdiag(M_LV-R, M_LV-R), M_LV-R = M_R-LV^T (crosstrack is the LV y axis).

The result is an orbit covariance shaped by the dynamics from four numbers (sigma_r,
sigma_v, sigma_E, sigma_H): the along-track/radial errors that change the period are
suppressed, those that do not are kept.  r km and v km/s are relative to the central body
of gravitational parameter mu km^3/s^2; the 6x6 covariance is in km^2, km^2/s, km^2/s^2.
Pure jnp; the array functions are jit-able (sigma arguments of None are static choices).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from fracas import _jax  # noqa: F401  (float64 before any array exists)
from fracas.dynamics.relative_motion import hill_axes
from fracas.filters.square_root import factor, potter_update

__all__ = [
    "energy",
    "energy_partials",
    "momentum",
    "momentum_partials",
    "lv_axes",
    "lv_to_reference",
    "lv_covariance",
    "pseudo_update",
    "shaped_covariance",
]


def _f64(a):
    return jnp.asarray(a, dtype=jnp.float64)


@jax.jit
def energy(r, v, mu):
    """Specific orbital energy E = v^2/2 - mu/|r| (km^2/s^2); r km, v km/s, mu km^3/s^2."""
    r, v = _f64(r), _f64(v)
    return 0.5 * v @ v - _f64(mu) / jnp.linalg.norm(r)


@jax.jit
def energy_partials(r, v, mu):
    """b (6,) = dE/d[r, v] = [mu r / |r|^3, v] (UNF energy pseudo-measurement, digest A.3.10);
    units km/s^2 and km/s."""
    r, v = _f64(r), _f64(v)
    rn = jnp.linalg.norm(r)
    return jnp.concatenate([_f64(mu) * r / rn**3, v])


@jax.jit
def momentum(r, v):
    """Angular-momentum magnitude H = |r x v| (km^2/s)."""
    return jnp.linalg.norm(jnp.cross(_f64(r), _f64(v)))


@jax.jit
def momentum_partials(r, v):
    """b (6,) = dH/d[r, v] = [v x i_h, i_h x r], i_h = r x v / H (UNF angular-momentum
    pseudo-measurement, digest A.3.10); units km/s and km."""
    r, v = _f64(r), _f64(v)
    h = jnp.cross(r, v)
    ih = h / jnp.linalg.norm(h)
    return jnp.concatenate([jnp.cross(v, ih), jnp.cross(ih, r)])


@jax.jit
def lv_axes(r, v):
    """M_R-LV (3, 3), rows i_x, i_y, i_z of the Draper local-vertical frame (digest A.6.1):
    i_z = -unit(r) (down), i_y = -unit(r x v) (crosstrack, minus the orbit normal),
    i_x = i_y x i_z (along track, forward for a circular orbit).  x_LV = M_R-LV x_ref."""
    C = hill_axes(_f64(r), _f64(v))[0]  # rows radial, along, normal
    return jnp.stack([C[1], -C[2], -C[0]])


@jax.jit
def lv_to_reference(r, v):
    """T (6, 6) = blockdiag(M_LV-R, M_LV-R), M_LV-R = M_R-LV^T: x_ref = T x_LV and
    E_ref = T E_LV T^T (digest A.6.1; orthogonal, so the transform preserves the covariance:
    T^T E_ref T = E_LV)."""
    m = lv_axes(r, v).T
    z = jnp.zeros((3, 3))
    return jnp.block([[m, z], [z, m]])


def lv_covariance(sigma_r, sigma_v, sigma_r_ct=None, sigma_v_ct=None):
    """The diagonal LV covariance diag(s_r, s_rCT, s_r, s_v, s_vCT, s_v)^2 (6, 6) (UNF
    sigma_rI, sigma_rICT, sigma_vI, sigma_vICT; digest A.6.1): the crosstrack (LV y) sigmas
    default to the in-plane ones.  km, km/s."""
    src = sigma_r if sigma_r_ct is None else sigma_r_ct
    svc = sigma_v if sigma_v_ct is None else sigma_v_ct
    s = jnp.stack([_f64(x) for x in (sigma_r, src, sigma_r, sigma_v, svc, sigma_v)])
    return jnp.diag(s**2)


@jax.jit
def pseudo_update(P, b, variance):
    """Covariance-only (W-only, UNF s_Wcorr = 1) update by one scalar pseudo measurement of
    partials ``b`` (n,) and variance ``variance`` (measurement unit^2), in square-root form
    (W = factor(P), Potter/UNF update W' = W - gamma omega z^T; digest A.4.1), returned as
    P' = W' W'^T = P - P b b^T P / (b^T P b + variance), symmetrized."""
    W = potter_update(factor(_f64(P)), _f64(b), _f64(variance))
    Pn = W @ W.T
    return 0.5 * (Pn + Pn.T)


def shaped_covariance(
    r,
    v,
    mu,
    sigma_r,
    sigma_v,
    sigma_energy=None,
    sigma_h=None,
    sigma_r_ct=None,
    sigma_v_ct=None,
):
    """The UNF correlated a-priori orbit covariance (6, 6) in reference axes (digest A.6.3).

    1. the diagonal LV covariance of :func:`lv_covariance` (sigma_r km, sigma_v km/s; the
       LV crosstrack sigma_r_ct, sigma_v_ct default to them) rotated to the reference axes
       (:func:`lv_to_reference`; with no crosstrack values it is sigma_r^2 I, sigma_v^2 I);
    2. the energy pseudo measurement, variance sigma_energy^2 (km^2/s^2)^2, W-only;
    3. the angular-momentum-magnitude pseudo measurement, variance sigma_h^2 (km^2/s)^2.

    A sigma of None skips its pseudo measurement.  r (3,) km, v (3,) km/s relative to the
    central body, mu km^3/s^2 (the UNF eta scale of A.6.3 is folded into the sigmas).
    """
    r, v = _f64(r), _f64(v)
    P = lv_covariance(sigma_r, sigma_v, sigma_r_ct, sigma_v_ct)
    if sigma_r_ct is not None or sigma_v_ct is not None:  # isotropic otherwise: no rotation needed
        T = lv_to_reference(r, v)
        P = T @ P @ T.T
        P = 0.5 * (P + P.T)
    if sigma_energy is not None:
        P = pseudo_update(P, energy_partials(r, v, mu), _f64(sigma_energy) ** 2)
    if sigma_h is not None:
        P = pseudo_update(P, momentum_partials(r, v), _f64(sigma_h) ** 2)
    return P
