"""Bounds of the TEAM deck's sigmas: a parameter's from its catalogue entry, a measurement's
from its kind (:mod:`fracas.params`, :mod:`fracas.measurements.kinds`); the value types the
TEAM tables share.
"""

from __future__ import annotations

import re
from typing import Annotated

from pydantic import BeforeValidator, Field

from fracas.config.trajectory import FieldProblem, canonical_name
from fracas.constants import BODIES
from fracas.measurements.kinds import MEASUREMENT_KINDS, MEASUREMENT_PARAMETERS
from fracas.params import INDEX_BODY, INDEX_BODY_ELEMENT, PARAMETER_KINDS

MAX_STATIONS = 9
NonNeg = Annotated[float, Field(ge=0)]
#: a station name, case-insensitive (stored in lower case)
StationName = Annotated[str, BeforeValidator(canonical_name)]
_LABEL_PARTS = re.compile(r"^([a-z_0-9]+)(?:\[([^\]]+)\])?$")


def sigma_bound(label: str) -> tuple[float, str] | None:
    """(largest sigma, why) for a parameter label from the catalogues, None if unbounded or unknown.

    :data:`fracas.params.PARAMETER_KINDS` and :data:`fracas.measurements.kinds.MEASUREMENT_PARAMETERS`
    carry ``max_sigma``; a ``relative`` one is a fraction of the body's catalogue value."""
    m = _LABEL_PARTS.match(label)
    if m is None:
        return None
    name, idx = m.group(1), m.group(2)
    parts = [p.strip() for p in idx.split(",")] if idx else []
    kind = PARAMETER_KINDS.get(name)
    if kind is not None and kind.max_sigma is not None:
        if kind.index == INDEX_BODY_ELEMENT:
            if len(parts) == 2 and parts[1] in ("a", "e", "i", "raan", "argp", "M"):
                k = ("a", "e", "i", "raan", "argp", "M").index(parts[1])
                hi = kind.max_sigma[k]
                return None if hi is None else (hi, f"{kind.unit[k]} (the element's range)")
            return None
        if kind.relative:
            if kind.index != INDEX_BODY or len(parts) != 1 or parts[0] not in BODIES:
                return None
            body = BODIES[parts[0]]
            value = body.mu_km3_s2 if name == "mu" else body.radius_km
            return kind.max_sigma * value, f"{kind.unit} ({kind.max_sigma:g} x {parts[0]}'s {value:g})"
        return float(kind.max_sigma), (f"({kind.max_sigma * 100:g} %)" if kind.unit == "1" else kind.unit)
    mp = MEASUREMENT_PARAMETERS.get(name)
    if mp is not None and mp.max_sigma is not None:
        return mp.max_sigma, mp.unit
    return None


def _check_sigma(label: str, sigma: float, field: str | tuple) -> FieldProblem | None:
    bound = sigma_bound(label)
    if bound is not None and sigma > bound[0]:
        return FieldProblem(field, sigma, f"must be <= {bound[0]:g} {bound[1]} for {label}")
    return None


def _kind_sigma(kind: str, sigma: float, field: str | tuple) -> FieldProblem | None:
    mk = MEASUREMENT_KINDS.get(kind)
    if mk is not None and mk.max_sigma is not None and sigma > mk.max_sigma:
        return FieldProblem(field, sigma, f'must be <= {mk.max_sigma:g} {mk.sigma_unit} for type "{kind}"')
    return None
