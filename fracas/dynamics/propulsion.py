"""Low-thrust propulsion: power, thrust magnitude, mass flow and pointing (FRACAS EP, POWER).

Power (FRACAS POWER; its text did not survive the scan, rebuilt from sec. 3.1 and App. 9.1):
  solar array   P = P0 (1 AU / r_sun)^2           (P0 = power at 1 AU, kW)
  nuclear       P = P0 exp(-t / tau_decay)       (t s since the propagation epoch)
Thrust (FRACAS EP):  T = 2 eta P / c;  mass flow  mdot = -T / c.
Canonical units: P in kW = 1e-3 kg km^2/s^3, so T [kg km/s^2] = 2e-3 eta P_kW / c_km_s.

Pointing: in EP's velocity frame the thrust unit vector is
  u = A [cos(beta) cos(alpha), cos(beta) sin(alpha), sin(beta)]
with A = [v_hat, (h x v)_hat, h_hat] (columns), h = r x v (FRACAS EP matrix [A]); alpha is
the in-plane angle from the velocity toward (h x v) and beta the out-of-plane angle toward
h.  Inertially fixed pointing uses alpha = right ascension, beta = declination (ICRF).

Yaw switching (frame code 2, ``velocity_yaw_switch``; Edelbaum 1961's steering, used by TOM's
plane-change spirals): the velocity frame with the out-of-plane angle's sign following the
sign of cos u, u the argument of latitude, so it flips at the antinodes:
beta_eff = sign(cos u) beta, with sign(cos u) = sign(h_x r_y - h_y r_x) (the node vector
z x h = (-h_y, h_x, 0) dotted with r).  beta > 0 then raises the inclination on every half
revolution (di/dt = r cos u f_h / h), beta < 0 lowers it.
"""

from __future__ import annotations

import jax.numpy as jnp
from jax import Array

from fracas import (
    _jax,  # noqa: F401
    constants,
)
from fracas.dynamics.forces import dot3


def power_kw(p0_kw: Array, r_from_sun_km: Array | None, t_s: float | Array, decay_s: Array, solar: bool) -> Array:
    """Available power (kW): solar (1/r^2 from 1 AU) or nuclear (exponential decay) (FRACAS POWER)."""
    if solar:
        rr = dot3(r_from_sun_km, r_from_sun_km)  # type: ignore[arg-type]  # given whenever solar
        return p0_kw * constants.AU_KM**2 / rr
    return p0_kw * jnp.exp(-t_s / decay_s)


def thrust_magnitude(power: Array, efficiency: Array, exhaust_velocity_km_s: Array) -> Array:
    """Thrust T = 2 eta P / c in kg km/s^2 (= kN) for P in kW and c in km/s (FRACAS EP)."""
    return 2e-3 * efficiency * power / exhaust_velocity_km_s


def velocity_frame(r: Array, v: Array) -> Array:
    """EP's rotation matrix [v_hat, (h x v)_hat, h_hat] (columns), h = r x v (FRACAS EP)."""
    x, y, z = _frame_axes(r, v)
    return jnp.stack([x, y, z], axis=1)


def _frame_axes(r: Array, v: Array, h: Array | None = None) -> tuple[Array, Array, Array]:
    """The three axes of :func:`velocity_frame` (unit vectors by sqrt(1/|.|^2): no float64
    rsqrt, which XLA CPU does not vectorise; one division for both norms)."""
    h = jnp.cross(r, v) if h is None else h
    vv, hh = dot3(v, v), dot3(h, h)
    inv = 1.0 / (vv * hh)
    x = v * jnp.sqrt(hh * inv)
    z = h * jnp.sqrt(vv * inv)
    return x, jnp.cross(z, x), z


def angles_to_unit(alpha: Array, beta: Array) -> Array:
    """[cos b cos a, cos b sin a, sin b]: unit vector from in-plane / out-of-plane angles (rad)."""
    cb = jnp.cos(beta)
    return jnp.stack([cb * jnp.cos(alpha), cb * jnp.sin(alpha), jnp.sin(beta)])


def node_dot_r(r: Array, v: Array) -> Array:
    """(z x h) . r = h_x r_y - h_y r_x (km^3/s), h = r x v: the ascending-node vector dotted
    with the position, |h| |r| sin(i) cos(u); its sign is that of cos u (module docstring)."""
    h = jnp.cross(r, v)
    return h[0] * r[1] - h[1] * r[0]


def yaw_sign_of(r: Array, v: Array) -> Array:
    """sign(cos u) as +-1.0 (+1 on the boundary), the yaw switch's instantaneous sign."""
    return jnp.where(node_dot_r(r, v) >= 0.0, 1.0, -1.0)


def thrust_direction(
    r: Array,
    v: Array,
    alpha: Array,
    beta: Array,
    frame: Array,
    u_angles: Array | None = None,
    yaw_sign: Array | None = None,
) -> Array:
    """Unit thrust vector in the inertial frame.

    ``frame`` (float code, as ``Params.arc_frame``): 0 velocity frame, 1 inertial RA/Dec
    pointing, 2 velocity frame with the out-of-plane sign switched at the antinodes (module
    docstring).  ``u_angles``: ``angles_to_unit(alpha, beta)`` when already known (the
    integrator computes it once per step, so its stages do no trigonometry); the yaw switch
    flips its third component (sin beta is odd, cos beta even).  ``yaw_sign``: the sign of
    cos u held by the propagation loop (``ForceModel.yaw_switch``: the flip is a located
    event, so the dynamics are smooth within a step); None takes it from (r, v)."""
    inertial = (frame > 0.5) & (frame < 1.5)
    switch = frame > 1.5
    h = jnp.cross(r, v)
    if yaw_sign is None:
        sign_cos_u = jnp.where(h[0] * r[1] - h[1] * r[0] >= 0.0, 1.0, -1.0)
    else:
        sign_cos_u = yaw_sign
    u_fixed = angles_to_unit(alpha, beta) if u_angles is None else u_angles
    u_z = jnp.where(switch, sign_cos_u, 1.0) * u_fixed[2]
    x, y, z = _frame_axes(r, v, h)
    # the frame applied as a sum of axes, not a matrix product (a batched dot_general under vmap)
    u_vel = x * u_fixed[0] + y * u_fixed[1] + z * u_z
    return jnp.where(inertial, u_fixed, u_vel)
