"""The parameter catalogue: labels, units and access into :class:`fracas.dynamics.model.Params`.

A label names one scalar a study can differentiate, estimate or disperse:

    mu[sun]  j2[earth]  radius[mars]                 per-body values (body names)
    body_elements[mars,a]  (a, e, i, raan, argp, M)  conic elements of an EPHEM body
    thrust_scale  bias_in_rad  bias_out_rad          overall thrust proportionality / pointing biases
    arc_thrust_scale[0]  arc_bias_in_rad[1] ...      the same per thrust arc
    arc_t_on[0] arc_t_off[0] arc_alpha[0] arc_beta[0] arc_throttle[0]   arc controls
    exhaust_velocity_km_s  power_kw  efficiency  cr  area_m2  power_decay_s  impulse_isp_s
    impulse_t[0]  impulse_dv[0,1]                    impulsive events

Unknown labels raise ``KeyError`` with the list of what exists (the config layer turns that
into a DeckError naming the deck field).
"""

from __future__ import annotations

import re
from typing import Sequence

from fracas import _jax  # noqa: F401
import jax.numpy as jnp

from fracas.dynamics.model import ForceModel, Params

STATE_LABELS = ("x", "y", "z", "vx", "vy", "vz", "mass")
STATE_UNITS = ("km", "km", "km", "km/s", "km/s", "km/s", "kg")
ELEMENT_NAMES = ("a", "e", "i", "raan", "argp", "M")
_ELEMENT_UNITS = ("km", "1", "rad", "rad", "rad", "rad")

_SCALAR_UNITS = {
    "area_m2": "m^2",
    "cr": "1",
    "power_kw": "kW",
    "power_decay_s": "s",
    "efficiency": "1",
    "exhaust_velocity_km_s": "km/s",
    "thrust_scale": "1",
    "bias_in_rad": "rad",
    "bias_out_rad": "rad",
    "impulse_isp_s": "s",
}
_BODY_UNITS = {"mu": "km^3/s^2", "j2": "1", "radius": "km"}
_ARC_UNITS = {
    "arc_t_on": "s",
    "arc_t_off": "s",
    "arc_alpha": "rad",
    "arc_beta": "rad",
    "arc_throttle": "1",
    "arc_thrust_scale": "1",
    "arc_bias_in_rad": "rad",
    "arc_bias_out_rad": "rad",
}
_IMPULSE_UNITS = {"impulse_t": "s", "impulse_dv": "km/s"}
_LABEL = re.compile(r"^([a-z_0-9]+)(?:\[([^\]]+)\])?$")


def parse_label(label: str, model: ForceModel) -> tuple[str, tuple[int, ...]]:
    """(Params field, index tuple) of a label; KeyError with a helpful message if unknown."""
    m = _LABEL.match(label.strip())
    if not m:
        raise KeyError(f"malformed parameter label {label!r}: expected name or name[index]")
    name, idx = m.group(1), m.group(2)
    parts = [s.strip() for s in idx.split(",")] if idx else []
    if name in _SCALAR_UNITS and not parts:
        return name, ()
    if name in _BODY_UNITS and len(parts) == 1:
        if parts[0] not in model.bodies:
            raise KeyError(f"parameter {label!r}: body {parts[0]!r} is not in the force model {model.bodies}")
        return name, (model.bodies.index(parts[0]),)
    if name == "body_elements" and len(parts) == 2:
        if parts[0] not in model.bodies or parts[1] not in ELEMENT_NAMES:
            raise KeyError(f"parameter {label!r}: expected body_elements[<body>,<{'|'.join(ELEMENT_NAMES)}>]")
        return name, (model.bodies.index(parts[0]), ELEMENT_NAMES.index(parts[1]))
    if name in _ARC_UNITS and len(parts) == 1 and parts[0].isdigit():
        k = int(parts[0])
        if k >= model.n_arcs:
            raise KeyError(f"parameter {label!r}: arc {k} does not exist ({model.n_arcs} thrust arcs)")
        return name, (k,)
    if name in _IMPULSE_UNITS and parts and parts[0].isdigit():
        k = int(parts[0])
        if k >= model.n_impulses:
            raise KeyError(f"parameter {label!r}: impulse {k} does not exist ({model.n_impulses} impulses)")
        if name == "impulse_t" and len(parts) == 1:
            return name, (k,)
        if name == "impulse_dv" and len(parts) == 2 and parts[1] in "012" and len(parts[1]) == 1:
            return name, (k, int(parts[1]))
    raise KeyError(
        f"unknown parameter {label!r}; known: {sorted(_SCALAR_UNITS)}, "
        f"{sorted(_BODY_UNITS)}[body], body_elements[body,element], {sorted(_ARC_UNITS)}[arc], "
        "impulse_t[k], impulse_dv[k,axis]"
    )


def param_unit(label: str, model: ForceModel) -> str:
    """Unit string of a label (canonical units)."""
    name, idx = parse_label(label, model)
    if name == "body_elements":
        return _ELEMENT_UNITS[idx[1]]
    for table in (_SCALAR_UNITS, _BODY_UNITS, _ARC_UNITS, _IMPULSE_UNITS):
        if name in table:
            return table[name]
    raise KeyError(label)  # pragma: no cover


def get_values(params: Params, labels: Sequence[str], model: ForceModel):
    """Current values of the labelled parameters as one float64 vector."""
    vals = []
    for label in labels:
        name, idx = parse_label(label, model)
        vals.append(jnp.asarray(getattr(params, name), jnp.float64)[idx])
    return jnp.stack(vals) if vals else jnp.zeros(0)


def set_values(params: Params, labels: Sequence[str], values, model: ForceModel) -> Params:
    """Params with the labelled entries replaced by ``values`` (differentiable in ``values``)."""
    upd = {}
    for j, label in enumerate(labels):
        name, idx = parse_label(label, model)
        cur = upd.get(name, jnp.asarray(getattr(params, name), jnp.float64))
        upd[name] = cur.at[idx].set(values[j]) if idx else values[j] + 0.0 * cur
    return params._replace(**upd)
