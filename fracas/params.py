"""The parameter catalogue: labels, units, bounds and roles of every study parameter (jax-free).

A label names one scalar a study can differentiate, estimate or disperse:

    mu[sun]  j2[earth]  radius[mars]                 per-body values (body names)
    body_elements[mars,a]  (a, e, i, raan, argp, M)  conic elements of an EPHEM body
    thrust_scale  bias_in_rad  bias_out_rad          overall thrust proportionality / pointing biases
    arc_thrust_scale[0]  arc_bias_in_rad[1] ...      the same per thrust arc
    arc_t_on[0] arc_t_off[0] arc_alpha[0] arc_beta[0] arc_throttle[0]   arc controls
    exhaust_velocity_km_s  power_kw  efficiency  cr  area_m2  power_decay_s  impulse_isp_s
    impulse_t[0]  impulse_dv[0,1]                    impulsive events

:data:`PARAMETER_KINDS` is the one table of these kinds (:class:`ParamKind`: index kind,
unit, description, a typical a-priori sigma, physical bounds and the
:class:`fracas.dynamics.model.Params` field).  The spacecraft state's labels and units
(:data:`STATE_LABELS`, :data:`STATE_UNITS`) and the role vocabularies (:data:`DECK_ROLES`,
:data:`AUGMENTED_ROLES`) live here too.  Measurement (consider) parameters are catalogued
in :mod:`fracas.measurements.kinds`.

Unknown labels raise ``KeyError`` with the list of what exists (the config layer turns that
into a DeckError naming the deck field).  This module imports neither JAX nor
:mod:`fracas.dynamics`: :func:`parse_label` and :func:`param_unit` only read
``model.bodies``, ``model.n_arcs`` and ``model.n_impulses``.  Reading and writing labelled
values of a ``Params`` (JAX) is :mod:`fracas.dynamics.parameters`.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import TYPE_CHECKING, cast

if TYPE_CHECKING:
    from collections.abc import Sequence
    from typing import Protocol

    class _ModelShape(Protocol):
        """What the label functions read of a force model (:class:`fracas.dynamics.model.ForceModel`
        has it; so may any object with these three attributes)."""

        @property
        def bodies(self) -> Sequence[str]: ...

        @property
        def n_arcs(self) -> int: ...

        @property
        def n_impulses(self) -> int: ...


__all__ = [
    "ParamKind",
    "PARAMETER_KINDS",
    "INDEX_SCALAR",
    "INDEX_BODY",
    "INDEX_BODY_ELEMENT",
    "INDEX_ARC",
    "INDEX_IMPULSE",
    "INDEX_IMPULSE_AXIS",
    "INDEX_KINDS",
    "ELEMENT_NAMES",
    "ELEMENT_UNITS",
    "STATE_LABELS",
    "STATE_UNITS",
    "THRUST_NOISE_LABELS",
    "ROLE_SOLVE_FOR",
    "ROLE_CONSIDER",
    "ROLE_DYNAMIC_CONSIDER",
    "ROLE_MEASUREMENT_CONSIDER",
    "ROLE_IGNORE",
    "DECK_ROLES",
    "AUGMENTED_ROLES",
    "parse_label",
    "param_unit",
    "parameter_kind",
    "ControlKind",
    "CONTROL_KINDS",
    "STATE_CONTROLS",
    "VINF_CONTROLS",
    "parse_control",
]

# --- index kinds: how a label's [..] part addresses its Params field ------------------
INDEX_SCALAR = "scalar"  # name                 () field
INDEX_BODY = "body"  # name[<body>]           (nb,) field, body name from model.bodies
INDEX_BODY_ELEMENT = "body_element"  # name[<body>,<element>]  (nb, 6) field
INDEX_ARC = "arc"  # name[<k>]              (na,) field, k < model.n_arcs
INDEX_IMPULSE = "impulse"  # name[<k>]              (ni,) field, k < model.n_impulses
INDEX_IMPULSE_AXIS = "impulse_axis"  # name[<k>,<0|1|2>]      (ni, 3) field
INDEX_KINDS = (INDEX_SCALAR, INDEX_BODY, INDEX_BODY_ELEMENT, INDEX_ARC, INDEX_IMPULSE, INDEX_IMPULSE_AXIS)

ELEMENT_NAMES = ("a", "e", "i", "raan", "argp", "M")
ELEMENT_UNITS = ("km", "1", "rad", "rad", "rad", "rad")
_ELEMENT_UNITS = ELEMENT_UNITS  # former private name

# --- the spacecraft state (rows of every STM, columns of every covariance) ------------
STATE_LABELS = ("x", "y", "z", "vx", "vy", "vz", "mass")
STATE_UNITS = ("km", "km", "km", "km/s", "km/s", "km/s", "kg")

#: Gauss-Markov thrust error components (FRACAS DYNO's eta; App. 9.3): overall thrust
#: proportionality (the ``thrust_scale`` factor, dimensionless; a 2 % error is sigma = 0.02
#: when the nominal scale is 1), in-plane and out-of-plane pointing (rad).
THRUST_NOISE_LABELS = ("thrust_scale", "bias_in_rad", "bias_out_rad")

# --- roles ---------------------------------------------------------------------------
ROLE_SOLVE_FOR = "solve_for"
ROLE_CONSIDER = "consider"
ROLE_DYNAMIC_CONSIDER = "dynamic_consider"
ROLE_MEASUREMENT_CONSIDER = "measurement_consider"
ROLE_IGNORE = "ignore"
#: roles a TEAM deck's [[parameter]] may give
DECK_ROLES = (ROLE_SOLVE_FOR, ROLE_CONSIDER, ROLE_IGNORE)
#: roles of the augmented-state layout (a deck "consider" splits by whether the parameter
#: acts on the dynamics or on the measurements)
AUGMENTED_ROLES = (ROLE_SOLVE_FOR, ROLE_DYNAMIC_CONSIDER, ROLE_MEASUREMENT_CONSIDER, ROLE_IGNORE)


@dataclass(frozen=True)
class ParamKind:
    """One kind of study parameter.

    ``name``: the label's name (before any ``[..]``); ``index``: one of :data:`INDEX_KINDS`;
    ``unit``: canonical unit (for ``body_element`` a tuple, one per element of
    :data:`ELEMENT_NAMES`); ``sigma``: a typical a-priori 1-sigma in ``unit`` (as in the
    example decks; informational, never applied by the program), None where no default makes
    sense; ``bounds``: physical (lower, upper), None for an open side (informational: the
    deck validators enforce their own); ``field``: the :class:`fracas.dynamics.model.Params`
    field the label addresses; ``max_sigma``: the largest a-priori sigma a deck may give,
    in ``unit`` (for ``body_element`` one per element, None for no bound), or with
    ``relative`` a fraction of the body's catalogue value (:mod:`fracas.constants`): a
    proportionality or a fraction at most 1 (100 %), an angle at most pi rad, a GM or a
    radius at most itself; None where no range exists (times, dV, power, areas).
    """

    name: str
    index: str
    unit: str | tuple[str, ...]
    description: str
    sigma: float | None = None
    bounds: tuple[float | None, float | None] = (None, None)
    field: str = ""
    max_sigma: float | tuple[float | None, ...] | None = None
    relative: bool = False

    def __post_init__(self) -> None:
        if self.index not in INDEX_KINDS:
            raise ValueError(f"parameter kind {self.name!r}: index {self.index!r} not in {INDEX_KINDS}")
        if not self.field:
            object.__setattr__(self, "field", self.name)

    def unit_at(self, idx: tuple[int, ...]) -> str:
        """Unit of the entry at ``idx`` (the index tuple :func:`parse_label` returns)."""
        return self.unit[idx[1]] if self.index == INDEX_BODY_ELEMENT else cast(str, self.unit)


#: the Params fields of an arc's pointing law (``ForceModel.steering``), in the core's order: the
#: Legendre P1..P3 coefficients of alpha, then of beta (rad)
POINTING_LAW_FIELDS = tuple(f"arc_{a}_p{n}" for a in ("alpha", "beta") for n in (1, 2, 3))
_LAW_ANGLE = {name: "in-plane" if "alpha" in name else "out-of-plane" for name in POINTING_LAW_FIELDS}
_INF = float("inf")
_PI = 3.141592653589793
_KINDS = (
    # spacecraft and propulsion (scalars)
    ParamKind("area_m2", INDEX_SCALAR, "m^2", "SRP reference area", None, (0.0, None)),
    ParamKind(
        "cr", INDEX_SCALAR, "1", "SRP reflectivity coefficient (1 absorber .. 2 mirror)", 0.1, (0.0, 2.0), max_sigma=2.0
    ),
    ParamKind("power_kw", INDEX_SCALAR, "kW", "base power: at 1 AU (solar) or at t = 0 (nuclear)", None, (0.0, None)),
    ParamKind("power_decay_s", INDEX_SCALAR, "s", "nuclear power e-folding time", None, (0.0, None)),
    ParamKind("efficiency", INDEX_SCALAR, "1", "thruster efficiency eta", None, (0.0, 1.0), max_sigma=1.0),
    ParamKind("exhaust_velocity_km_s", INDEX_SCALAR, "km/s", "exhaust velocity c", None, (0.0, None)),
    ParamKind(
        "thrust_scale",
        INDEX_SCALAR,
        "1",
        "overall thrust proportionality (1 nominal)",
        0.01,
        (0.0, None),
        max_sigma=1.0,
    ),
    ParamKind("bias_in_rad", INDEX_SCALAR, "rad", "overall in-plane pointing bias", 0.005, max_sigma=_PI),
    ParamKind("bias_out_rad", INDEX_SCALAR, "rad", "overall out-of-plane pointing bias", 0.005, max_sigma=_PI),
    ParamKind("impulse_isp_s", INDEX_SCALAR, "s", "specific impulse of the impulsive engine", None, (0.0, None)),
    # per body
    ParamKind(
        "mu",
        INDEX_BODY,
        "km^3/s^2",
        "gravitational parameter GM of a body",
        None,
        (0.0, None),
        max_sigma=1.0,
        relative=True,
    ),
    ParamKind("j2", INDEX_BODY, "1", "unnormalised J2 of a body", max_sigma=1.0),
    ParamKind(
        "radius",
        INDEX_BODY,
        "km",
        "equatorial (J2 reference) radius of a body",
        None,
        (0.0, None),
        max_sigma=1.0,
        relative=True,
    ),
    ParamKind(
        "body_elements",
        INDEX_BODY_ELEMENT,
        ELEMENT_UNITS,
        "heliocentric conic element (a, e, i, raan, argp, M) of an EPHEM body",
        max_sigma=(None, 1.0, _PI, _PI, _PI, _PI),
    ),
    # per thrust arc
    ParamKind("arc_t_on", INDEX_ARC, "s", "arc start, s from the propagation epoch"),
    ParamKind("arc_t_off", INDEX_ARC, "s", "arc end, s from the propagation epoch"),
    ParamKind("arc_alpha", INDEX_ARC, "rad", "arc in-plane angle / right ascension", max_sigma=_PI),
    ParamKind("arc_beta", INDEX_ARC, "rad", "arc out-of-plane angle / declination", max_sigma=_PI),
    ParamKind("arc_throttle", INDEX_ARC, "1", "arc thrust level factor", None, (0.0, 1.0), max_sigma=1.0),
    ParamKind(
        "arc_thrust_scale",
        INDEX_ARC,
        "1",
        "per-arc thrust proportionality (1 nominal)",
        0.01,
        (0.0, None),
        max_sigma=1.0,
    ),
    ParamKind("arc_bias_in_rad", INDEX_ARC, "rad", "per-arc in-plane pointing bias", 0.005, max_sigma=_PI),
    ParamKind("arc_bias_out_rad", INDEX_ARC, "rad", "per-arc out-of-plane pointing bias", 0.005, max_sigma=_PI),
    *(
        ParamKind(
            name, INDEX_ARC, "rad", f"arc {_LAW_ANGLE[name]} angle's Legendre P{name[-1]} coefficient", max_sigma=_PI
        )
        for name in POINTING_LAW_FIELDS
    ),
    # impulsive events
    ParamKind("impulse_t", INDEX_IMPULSE, "s", "time of an impulsive dV, s from the propagation epoch"),
    ParamKind("impulse_dv", INDEX_IMPULSE_AXIS, "km/s", "impulsive dV component in its impulse frame"),
)
#: name -> :class:`ParamKind`
PARAMETER_KINDS: dict[str, ParamKind] = {k.name: k for k in _KINDS}
_BY_FIELD = {k.field: k for k in _KINDS}


def _units(index: str) -> dict[str, str | tuple[str, ...]]:
    return {k.name: k.unit for k in _KINDS if k.index == index}


# Former private tables (name -> unit), derived from the catalogue.
_SCALAR_UNITS = _units(INDEX_SCALAR)
_BODY_UNITS = _units(INDEX_BODY)
_ARC_UNITS = _units(INDEX_ARC)
_IMPULSE_UNITS = {**_units(INDEX_IMPULSE), **_units(INDEX_IMPULSE_AXIS)}
_LABEL = re.compile(r"^([a-z_0-9]+)(?:\[([^\]]+)\])?$")


def parse_label(label: str, model: _ModelShape) -> tuple[str, tuple[int, ...]]:
    """(Params field, index tuple) of a label; KeyError with a helpful message if unknown.

    ``model``: anything with ``bodies`` (names), ``n_arcs`` and ``n_impulses`` (a
    :class:`fracas.dynamics.model.ForceModel`).
    """
    m = _LABEL.match(label.strip())
    if not m:
        raise KeyError(f"malformed parameter label {label!r}: expected name or name[index]")
    name, idx = m.group(1), m.group(2)
    parts = [s.strip() for s in idx.split(",")] if idx else []
    kind = PARAMETER_KINDS.get(name)
    index = kind.index if kind is not None else None
    field = kind.field if kind is not None else ""  # "" never returned: each return needs a known kind
    if index == INDEX_SCALAR and not parts:
        return field, ()
    if index == INDEX_BODY and len(parts) == 1:
        if parts[0] not in model.bodies:
            raise KeyError(f"parameter {label!r}: body {parts[0]!r} is not in the force model {model.bodies}")
        return field, (model.bodies.index(parts[0]),)
    if index == INDEX_BODY_ELEMENT and len(parts) == 2:
        if parts[0] not in model.bodies or parts[1] not in ELEMENT_NAMES:
            raise KeyError(f"parameter {label!r}: expected body_elements[<body>,<{'|'.join(ELEMENT_NAMES)}>]")
        return field, (model.bodies.index(parts[0]), ELEMENT_NAMES.index(parts[1]))
    if index == INDEX_ARC and len(parts) == 1 and parts[0].isdigit():
        k = int(parts[0])
        if k >= model.n_arcs:
            raise KeyError(f"parameter {label!r}: arc {k} does not exist ({model.n_arcs} thrust arcs)")
        return field, (k,)
    if index in (INDEX_IMPULSE, INDEX_IMPULSE_AXIS) and parts and parts[0].isdigit():
        k = int(parts[0])
        if k >= model.n_impulses:
            raise KeyError(f"parameter {label!r}: impulse {k} does not exist ({model.n_impulses} impulses)")
        if index == INDEX_IMPULSE and len(parts) == 1:
            return field, (k,)
        if index == INDEX_IMPULSE_AXIS and len(parts) == 2 and parts[1] in "012" and len(parts[1]) == 1:
            return field, (k, int(parts[1]))
    raise KeyError(
        f"unknown parameter {label!r}; known: {sorted(_SCALAR_UNITS)}, "
        f"{sorted(_BODY_UNITS)}[body], body_elements[body,element], {sorted(_ARC_UNITS)}[arc], "
        "impulse_t[k], impulse_dv[k,axis]"
    )


def parameter_kind(label: str, model: _ModelShape) -> ParamKind:
    """The :class:`ParamKind` of a label (validated against ``model`` like :func:`parse_label`)."""
    parse_label(label, model)
    m = _LABEL.match(label.strip())
    assert m is not None  # parse_label accepted it
    return PARAMETER_KINDS[m.group(1)]


def param_unit(label: str, model: _ModelShape) -> str:
    """Unit string of a label (canonical units)."""
    field, idx = parse_label(label, model)
    return _BY_FIELD[field].unit_at(idx)


# --- TOM controls (FRACAS $DATA control codes) ------------------------------------------
@dataclass(frozen=True)
class ControlKind:
    """One kind of TOM control: the decision-vector entries a TOM deck may name.

    ``name``: as a deck spells it (before any ``[..]``); ``index``: "none", "arc", "impulse"
    or "impulse_axis" (like :class:`ParamKind`); ``unit``: the unit a deck writes (days for
    times, deg for angles), ``canonical``: the core's unit, ``to_canonical``: the factor
    between them; ``label``: the :data:`PARAMETER_KINDS` name it sets ("" for the initial
    state and the final time, which are not parameters); ``bounds``: physical bounds in the
    deck unit (None: open).
    """

    name: str
    index: str
    unit: str
    canonical: str
    to_canonical: float
    description: str
    label: str = ""
    bounds: tuple[float | None, float | None] = (None, None)


_DEG = _PI / 180.0
_DAY = 86400.0
_CONTROLS = (
    ControlKind("x0", "none", "km", "km", 1.0, "initial position x relative to the deck's centre (ICRF)"),
    ControlKind("y0", "none", "km", "km", 1.0, "initial position y relative to the deck's centre (ICRF)"),
    ControlKind("z0", "none", "km", "km", 1.0, "initial position z relative to the deck's centre (ICRF)"),
    ControlKind("vx0", "none", "km/s", "km/s", 1.0, "initial velocity x relative to the deck's centre (ICRF)"),
    ControlKind("vy0", "none", "km/s", "km/s", 1.0, "initial velocity y relative to the deck's centre (ICRF)"),
    ControlKind("vz0", "none", "km/s", "km/s", 1.0, "initial velocity z relative to the deck's centre (ICRF)"),
    ControlKind(
        "vinf", "none", "km/s", "km/s", 1.0, "launch excess speed relative to the departure body", bounds=(0.0, None)
    ),
    ControlKind("vinf_ra", "none", "deg", "rad", _DEG, "right ascension of the launch excess velocity (ICRF)"),
    ControlKind(
        "vinf_dec", "none", "deg", "rad", _DEG, "declination of the launch excess velocity (ICRF)", bounds=(-90.0, 90.0)
    ),
    ControlKind("final_time", "none", "days", "s", _DAY, "final (arrival) time from the epoch; stop = time only"),
    ControlKind(
        "exhaust_velocity_km_s", "none", "km/s", "km/s", 1.0, "exhaust velocity c", "exhaust_velocity_km_s", (0.0, None)
    ),
    ControlKind("thrust_scale", "none", "1", "1", 1.0, "overall thrust level", "thrust_scale", (0.0, None)),
    ControlKind("arc_t_on", "arc", "days", "s", _DAY, "arc start", "arc_t_on"),
    ControlKind("arc_t_off", "arc", "days", "s", _DAY, "arc end", "arc_t_off"),
    ControlKind(
        "arc_duration",
        "arc",
        "days",
        "s",
        _DAY,
        "arc duration (moves the end; the start stays)",
        "arc_t_off",
        (0.0, None),
    ),
    ControlKind("arc_alpha", "arc", "deg", "rad", _DEG, "arc in-plane angle / right ascension", "arc_alpha"),
    ControlKind(
        "arc_beta", "arc", "deg", "rad", _DEG, "arc out-of-plane angle / declination", "arc_beta", (-90.0, 90.0)
    ),
    ControlKind("arc_throttle", "arc", "1", "1", 1.0, "arc thrust level", "arc_throttle", (0.0, 1.0)),
    *(
        ControlKind(
            name, "arc", "deg", "rad", _DEG, f"arc {_LAW_ANGLE[name]} angle's Legendre P{name[-1]} coefficient", name
        )
        for name in POINTING_LAW_FIELDS
    ),
    ControlKind("impulse_t", "impulse", "days", "s", _DAY, "time of an impulse", "impulse_t"),
    ControlKind("impulse_dv", "impulse_axis", "km/s", "km/s", 1.0, "impulse dV component (its frame)", "impulse_dv"),
)
#: name -> :class:`ControlKind`
CONTROL_KINDS: dict[str, ControlKind] = {k.name: k for k in _CONTROLS}
STATE_CONTROLS = ("x0", "y0", "z0", "vx0", "vy0", "vz0")
VINF_CONTROLS = ("vinf", "vinf_ra", "vinf_dec")


def parse_control(name: str, n_arcs: int, n_impulses: int) -> tuple[ControlKind, tuple[int, ...]]:
    """(kind, index) of a TOM control name such as ``arc_t_off[1]`` or ``impulse_dv[0,2]``.

    KeyError naming what exists when the name or its index is unknown."""
    m = _LABEL.match(name.strip())
    kind = CONTROL_KINDS.get(m.group(1)) if m else None
    if kind is None:
        raise KeyError(f"unknown control {name!r}; known: {', '.join(CONTROL_KINDS)} (arc and impulse kinds take [k])")
    assert m is not None  # the kind came from it
    parts = [s.strip() for s in m.group(2).split(",")] if m.group(2) else []
    want = {"none": 0, "arc": 1, "impulse": 1, "impulse_axis": 2}[kind.index]
    if len(parts) != want or not all(p.isdigit() for p in parts):
        form = {"none": kind.name, "arc": f"{kind.name}[k]", "impulse": f"{kind.name}[k]"}.get(
            kind.index, f"{kind.name}[k,axis]"
        )
        raise KeyError(f"control {name!r}: expected {form}")
    idx = tuple(int(p) for p in parts)
    if kind.index == "arc" and idx[0] >= n_arcs:
        raise KeyError(f"control {name!r}: arc {idx[0]} does not exist ({n_arcs} thrust arcs)")
    if kind.index in ("impulse", "impulse_axis") and idx[0] >= n_impulses:
        raise KeyError(f"control {name!r}: impulse {idx[0]} does not exist ({n_impulses} impulses)")
    if kind.index == "impulse_axis" and idx[1] > 2:
        raise KeyError(f"control {name!r}: axis must be 0, 1 or 2")
    return kind, idx
