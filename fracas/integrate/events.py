"""Event functions of the propagation loop (FRACAS DETECT): the stop condition and the
changes of primary body, as functions that fall through zero when the event happens.

Part of the Encke/Nystrom core (:mod:`fracas.integrate.encke`, which re-exports these names and
locates the events by Newton steps).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import jax
import jax.numpy as jnp

from fracas import _jax  # noqa: F401
from fracas.dynamics import forces
from fracas.dynamics.model import (
    STOP_CLOSEST_APPROACH,
    STOP_RADIUS,
    STOP_SOI_ENTRY,
    STOP_TIME,
    ForceModel,
    Params,
)

if TYPE_CHECKING:
    from jax.typing import ArrayLike

_INACTIVE = 1.0e30  # event-function value of an inactive event (never crosses zero)


def _n_events(model: ForceModel) -> int:
    return 1 + (len(model.bodies) if model.change_primary_at_soi else 0) + (1 if model.yaw_switch else 0)


def yaw_event_index(model: ForceModel) -> int:
    """Index of the yaw-switch flip in :func:`event_functions` (the last; -1 without one)."""
    return _n_events(model) - 1 if model.yaw_switch else -1


def event_functions(
    model: ForceModel,
    params: Params,
    r: jax.Array,
    v: jax.Array,
    primary: jax.Array,
    bodies_pos: jax.Array,
    bodies_vel: jax.Array,
    radius_sign: ArrayLike,
    yaw_sign: ArrayLike = 1.0,
) -> jax.Array:
    """Event functions g (ne,); an event happens when g falls through zero.

    g[0] is the stop condition: soi_entry |r_b| - R_soi(b); closest_approach -(r_b . v_b);
    radius s0(|r_b| - R) with s0 the side the propagation started on.  When primary changes
    are on, g[1 + b] is |r_b| - R_soi(b) for bodies whose parent is the primary (entry) and
    R_soi(p) - |r| for the primary itself (exit).  Inactive entries are +1e30.

    With ``model.yaw_switch`` the last entry is the yaw switch's flip,
    s (z x h) . r / (|h| |r|) = s sin(i) cos(u), with s = ``yaw_sign`` the sign of cos u held
    by the loop: positive while the held sign is right, falling through zero at an antinode
    (u = 90 or 270 deg), where the out-of-plane thrust reverses.  The dynamics are
    discontinuous there, so the flip is located like any other event and the state
    transition matrix takes the saltation jump (the saltation matrix of Aizerman & Gantmacher,
    Q. J. Mech. Appl. Math. 11, 1958; Mueller, Chaos Solitons Fractals 5, 1995)
    (``encke._saltation``).  It is tracked through coasts and non-switching arcs too (where
    the jump is zero), so the held sign is right whenever a switching arc turns on.
    """
    stop = model.stop
    rp, vp = bodies_pos[primary], bodies_vel[primary]
    g = []
    if stop.kind == STOP_TIME:
        g.append(jnp.asarray(_INACTIVE))
    else:
        b = stop.body
        rb = r + rp - bodies_pos[b]
        vb = v + vp - bodies_vel[b]
        dist = jnp.linalg.norm(rb)
        if stop.kind == STOP_SOI_ENTRY:
            gs = jnp.where(primary == b, _INACTIVE, dist - params.soi_radius[b])
        elif stop.kind == STOP_CLOSEST_APPROACH:
            gs = -forces.dot3(rb, vb)
        elif stop.kind == STOP_RADIUS:
            gs = radius_sign * (dist - stop.radius_km)
        else:  # pragma: no cover - validated upstream
            raise ValueError(stop.kind)
        g.append(gs)
    if model.change_primary_at_soi:
        for b in range(len(model.bodies)):
            rb = r + rp - bodies_pos[b]
            dist = jnp.linalg.norm(rb)
            soi = params.soi_radius[b]
            entry = jnp.where(params.parent[b] == primary.astype(jnp.float64), dist - soi, _INACTIVE)
            exit_ = jnp.where((primary == b) & (params.parent[b] >= 0), soi - jnp.linalg.norm(r), _INACTIVE)
            g.append(jnp.where(primary == b, exit_, entry))
    if model.yaw_switch:
        g.append(yaw_event_function(r, v, yaw_sign))
    return jnp.stack(g)


def yaw_event_function(r: jax.Array, v: jax.Array, yaw_sign: ArrayLike) -> jax.Array:
    """s (z x h) . r / (|h| |r|) = s sin(i) cos(u) (dimensionless): the yaw flip's event
    function (:func:`event_functions`), s = ``yaw_sign``."""
    h = jnp.cross(r, v)
    scale = jnp.sqrt(forces.dot3(h, h) * forces.dot3(r, r))
    return jnp.asarray(yaw_sign) * (h[0] * r[1] - h[1] * r[0]) / jnp.where(scale > 0.0, scale, 1.0)
