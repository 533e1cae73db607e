"""Target values, the target transformation A_T and the target variation matrices (FRACAS
TARMAT §5.4.9, TARPRL §5.3.20).

Pure JAX functions of arrays, float64, jit- and vmap-able.  Equations from the seed digest
``tom-tsim-guidance.md`` §B.5:

* (G-2) Ψ = A_T Φ(t_f, t_c) and Ψ_p = A_T Θ(t_f, t_c), with A_T = ∂T/∂X_f the target
  transformation at the target time (:func:`target_matrix`).
* A_T is the forward-mode Jacobian of :func:`target_values` with respect to the 6-state
  relative to the target body, with a zero mass column appended (no target depends on the
  mass at t_f; the mass still enters Ψ through Φ's mass column when thrust follows t_c).
  Element targets are the inverse map of :func:`fracas.dynamics.elements.elements_to_cartesian`,
  so their rows of A_T are the rows of the inverse of d(cartesian)/d(elements); the TARPRL
  closed forms (:func:`element_position_partials`) are the independent check of its
  position block.

Targets are evaluated at the fixed target time t_f.  The time targets (``time_of_flight``,
``closest_approach_time``) are the linearized arrival time t_f + t_p(X_f), t_p the time from
the state to periapsis on the osculating conic, so a stopping condition (closest approach)
is represented through the conic, as FRACAS does, rather than by the stopping-condition
correction −(Ṫ/ġ)∂g/∂X_f of the digest [EXT].

Units: km, km/s, s, rad; μ in km³/s².  State order [x, y, z, vx, vy, vz] (then mass).
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import partial

import jax
import jax.numpy as jnp
from jax import Array
from jax.typing import ArrayLike

from fracas import _jax  # noqa: F401  (float64 before any array exists)
from fracas.dynamics.bplane import b_plane
from fracas.dynamics.elements import cartesian_to_elements, solve_kepler
from fracas.guidance.target_kinds import check_targets

__all__ = [
    "target_values",
    "target_jacobian",
    "target_matrix",
    "element_position_partials",
]

_ELEMENT_INDEX = {"a": 0, "e": 1, "i": 2, "raan": 3, "argp": 4, "M": 5}
_STATE_INDEX = {"x": 0, "y": 1, "z": 2, "vx": 3, "vy": 4, "vz": 5}
_BPLANE = ("b_dot_t", "b_dot_r")
_TIMES = ("time_of_flight", "closest_approach_time")


def _time_to_periapsis(el: Array, mu: ArrayLike) -> Array:
    """Time (s) from the state to periapsis on its conic: −M/n, elliptic M wrapped to [−π, π)
    (the nearest periapsis; negative once past it), hyperbolic M as it is."""
    a, e, m_anom = el[0], el[1], el[5]
    ell = e < 1.0
    m_w = jnp.where(ell, jnp.mod(m_anom + jnp.pi, 2.0 * jnp.pi) - jnp.pi, m_anom)
    n = jnp.sqrt(mu / jnp.abs(a) ** 3)
    return -m_w / n


@partial(jax.jit, static_argnums=(0,))
def target_values(
    names: tuple[str, ...],
    state_rel: ArrayLike,
    t_f_s: float | Array,
    mu: ArrayLike,
    ref_pole: ArrayLike | Sequence[float] = (0.0, 0.0, 1.0),
) -> jax.Array:
    """Values (m,) of the targets ``names`` (TARMAT; :data:`TARGET_KINDS`) at the target time.

    state_rel: (6,) or (7,) state relative to the target body (km, km/s[, kg]; mass unused);
    t_f_s: target time (s, any epoch; only the time targets use it); mu: the target body's
    gravitational parameter (km³/s²); ref_pole: B-plane reference pole (frame z by default).
    B-plane targets are NaN for a non-hyperbolic state (as :func:`b_plane`).
    """
    names = tuple(names)
    check_targets(names)
    x = jnp.asarray(state_rel, jnp.float64)
    r, v = x[0:3], x[3:6]
    el = cartesian_to_elements(r, v, mu)
    bp = b_plane(r, v, mu, ref_pole) if any(n in _BPLANE or n.startswith("vinf_") for n in names) else None
    out = []
    for name in names:
        if name in _STATE_INDEX:
            out.append(x[_STATE_INDEX[name]])
        elif name in _ELEMENT_INDEX:
            out.append(el[_ELEMENT_INDEX[name]])
        elif name == "b_dot_t":
            out.append(bp.b_dot_t)  # type: ignore[union-attr]  # bp is set for every B-plane target
        elif name == "b_dot_r":
            out.append(bp.b_dot_r)  # type: ignore[union-attr]
        elif name in _TIMES:
            out.append(t_f_s + _time_to_periapsis(el, mu))
        elif name == "closest_approach_radius":
            out.append(el[0] * (1.0 - el[1]))
        elif name == "radius":
            out.append(jnp.sqrt(jnp.sum(r * r)))
        elif name == "speed":
            out.append(jnp.sqrt(jnp.sum(v * v)))
        elif name == "radial_velocity":
            out.append(jnp.sum(r * v) / jnp.sqrt(jnp.sum(r * r)))
        elif name in ("e_cos_argp", "e_sin_argp"):
            # from the eccentricity vector in the node frame: smooth through e = 0
            h = jnp.cross(r, v)
            w = h / jnp.sqrt(jnp.sum(h * h))
            e_vec = jnp.cross(v, h) / mu - r / jnp.sqrt(jnp.sum(r * r))
            sin_i = jnp.sqrt(w[0] ** 2 + w[1] ** 2)
            eq = sin_i < 1e-15
            n_hat = jnp.where(eq, jnp.array([1.0, 0.0, 0.0]), jnp.stack([-w[1], w[0], 0.0]) / jnp.where(eq, 1.0, sin_i))
            m_hat = jnp.cross(w, n_hat)
            out.append(jnp.sum(e_vec * (n_hat if name == "e_cos_argp" else m_hat)))
        elif name == "vinf":
            out.append(jnp.sqrt(jnp.sum(v * v) - 2.0 * mu / jnp.sqrt(jnp.sum(r * r))))
        elif name in ("vinf_x", "vinf_y", "vinf_z"):
            out.append(bp.v_inf * bp.s_hat["xyz".index(name[-1])])  # type: ignore[union-attr]
        elif name == "final_time":
            out.append(jnp.asarray(t_f_s, jnp.float64))
        else:  # pragma: no cover  (check_targets covers TARGET_KINDS)
            raise KeyError(name)
    return jnp.stack(out) if out else jnp.zeros(0)


@partial(jax.jit, static_argnums=(0,))
def target_jacobian(
    names: tuple[str, ...],
    state_rel: ArrayLike,
    t_f_s: ArrayLike,
    mu: ArrayLike,
    ref_pole: ArrayLike | Sequence[float] = (0.0, 0.0, 1.0),
) -> jax.Array:
    """A_T = ∂T/∂X_f (m×7) by forward-mode AD of :func:`target_values` (TARMAT, digest (G-2)).

    Columns [x, y, z, vx, vy, vz, mass]; the mass column is zero.  Units: row unit of the
    target (:func:`fracas.guidance.target_kinds.target_unit`) per km, per km/s, per kg.
    """
    x6 = jnp.asarray(state_rel, jnp.float64)[:6]
    jac = jax.jacfwd(lambda s: target_values(names, s, t_f_s, mu, ref_pole))(x6)
    return jnp.concatenate([jac, jnp.zeros((jac.shape[0], 1))], axis=1)


@jax.jit
def target_matrix(a_t: ArrayLike, phi_f_c: ArrayLike, theta_f_c: ArrayLike) -> tuple[jax.Array, jax.Array]:
    """Ψ = A_T Φ(t_f, t_c) (m×7) and Ψ_p = A_T Θ(t_f, t_c) (m×p) (TARMAT §5.4.9, digest (G-2)).

    a_t: (m×7) from :func:`target_jacobian`; phi_f_c: the 7-state (r, v, m) transition
    matrix from the control epoch t_c to t_f; theta_f_c: (7×p) the parameter matrix over the
    same interval, ∂X(t_f)/∂p with X(t_c) held fixed.
    """
    a_t = jnp.asarray(a_t)
    return a_t @ jnp.asarray(phi_f_c), a_t @ jnp.asarray(theta_f_c)


@jax.jit
def element_position_partials(elements: ArrayLike, mu: ArrayLike) -> jax.Array:
    """∂(x, y, z)/∂(a, e, i, Ω, ω, M) (3×6) in closed form, FRACAS TARPRL §5.3.20 (ellipse).

    With u = ω + ν, r = a(1 − e cos E) and X/r = [cosΩ cos u − sinΩ sin u cos i,
    sinΩ cos u + cosΩ sin u cos i, sin u sin i]:

    * ∂X/∂a = X/a;  ∂X/∂i = r[sinΩ sin u sin i, −cosΩ sin u sin i, sin u cos i];
      ∂X/∂Ω = [−y, x, 0];  ∂X/∂ω = r ∂(X/r)/∂u;
    * ∂X/∂e = (X/r) q + r (∂ν/∂e) ∂(X/r)/∂u,  ∂X/∂M = (X/r) s + r (∂ν/∂M) ∂(X/r)/∂u,

    with the scan errors fixed as the digest (§B.5) gives them: q = ∂r/∂e|_M = −a cos ν
    (the scan prints r[r − a − ae²(1 + sin²ν)]/(ae(1 − e²))), s = ∂r/∂M = ae sin ν/(1 − e²)^{1/2}
    (printed /(1 − e²)²), ∂ν/∂e = sin ν (2 + e cos ν)/(1 − e²), ∂ν/∂M = (1 + e cos ν)²/(1 − e²)^{3/2},
    tan(ν/2) = [(1 + e)/(1 − e)]^{1/2} tan(E/2), and cos i (printed cos ω) in ∂x/∂ω.
    ``mu`` is unused (positions do not depend on it at fixed M) and kept for a uniform
    signature.  Units: km per km, per 1, per rad.
    """
    del mu
    a, e, inc, raan, argp, m_anom = (jnp.asarray(elements, jnp.float64)[k] for k in range(6))
    ecc_anom = solve_kepler(m_anom, e)
    nu = 2.0 * jnp.arctan(jnp.sqrt((1.0 + e) / (1.0 - e)) * jnp.tan(0.5 * ecc_anom))
    r = a * (1.0 - e * jnp.cos(ecc_anom))
    u = argp + nu
    co, so, ci, si, cu, su = jnp.cos(raan), jnp.sin(raan), jnp.cos(inc), jnp.sin(inc), jnp.cos(u), jnp.sin(u)
    xr = jnp.stack([co * cu - so * su * ci, so * cu + co * su * ci, su * si])
    dxr_du = jnp.stack([-co * su - so * cu * ci, -so * su + co * cu * ci, cu * si])
    pos = r * xr
    one_m_e2 = 1.0 - e * e
    q = -a * jnp.cos(nu)
    s = a * e * jnp.sin(nu) / jnp.sqrt(one_m_e2)
    dnu_de = jnp.sin(nu) * (2.0 + e * jnp.cos(nu)) / one_m_e2
    dnu_dm = (1.0 + e * jnp.cos(nu)) ** 2 / one_m_e2**1.5
    d_a = pos / a
    d_e = xr * q + r * dnu_de * dxr_du
    d_i = r * jnp.stack([so * su * si, -co * su * si, su * ci])
    d_raan = jnp.stack([-pos[1], pos[0], 0.0 * pos[0]])
    d_argp = r * dxr_du
    d_m = xr * s + r * dnu_dm * dxr_du
    return jnp.stack([d_a, d_e, d_i, d_raan, d_argp, d_m], axis=1)
