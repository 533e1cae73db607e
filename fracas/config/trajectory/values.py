"""Value types of the decks: epochs, body names, 3-vectors, parameter labels, and the frozen
section base every deck table derives from (pydantic annotated types; no JAX).
"""

from __future__ import annotations

import datetime as _dt
import math
import re
from typing import Annotated, Any

from pydantic import AfterValidator, BaseModel, BeforeValidator, ConfigDict, Field, PlainValidator

from fracas.config.fields import MAX_ANGLE_DEG, MAX_DAYS, MAX_DISTANCE_KM, MAX_ISP_S, MAX_MASS_KG, MAX_SPEED_KM_S
from fracas.config.trajectory.problems import FieldProblem
from fracas.constants import BODIES
from fracas.errors import ConfigError
from fracas.timescales import calendar_to_et

BODY_NAMES = tuple(BODIES)


def _iso_value(v: Any) -> str:
    """A TDB calendar epoch: an ISO string (or a TOML local date/datetime) -> 'YYYY-MM-DDTHH:MM:SS[.ffffff]'."""
    if isinstance(v, _dt.datetime):
        if v.tzinfo is not None:
            raise ValueError("must be a TDB calendar date without a UTC offset")
        return v.isoformat()
    if isinstance(v, _dt.date):
        return _dt.datetime(v.year, v.month, v.day).isoformat()
    if not isinstance(v, str):
        raise ValueError('must be an ISO calendar date string such as "2030-01-01T00:00:00" (TDB)')
    text = v.strip()
    try:
        calendar_to_et(text)  # the one calendar conversion (fracas.timescales)
    except ConfigError:
        raise ValueError('must be an ISO calendar date such as "2030-01-01T00:00:00" (TDB)') from None
    return re.sub(r"\s*TDB$", "", text, flags=re.IGNORECASE)


def _epoch_value(v: Any) -> str | float:
    """An epoch written either as an ISO TDB string/date or as a Julian date (TDB) number."""
    if isinstance(v, bool):
        raise ValueError("must be an ISO calendar date string (TDB) or a Julian date number")
    if isinstance(v, (int, float)):
        if not math.isfinite(v) or not (1_000_000.0 < v < 5_000_000.0):
            raise ValueError("a Julian date must lie between 1e6 and 5e6")
        return float(v)
    if isinstance(v, (str, _dt.date)):
        return _iso_value(v)
    raise ValueError("must be an ISO calendar date string (TDB) or a Julian date number")


def _body_name(v: Any) -> str:
    if not isinstance(v, str):
        raise ValueError(f"must be a body name, one of {', '.join(BODY_NAMES)}")
    name = v.strip().lower()
    if name not in BODIES:
        raise ValueError(f"must be a known body, one of {', '.join(BODY_NAMES)}")
    return name


BodyName = Annotated[str, PlainValidator(_body_name)]
IsoEpoch = Annotated[str, PlainValidator(_iso_value)]
EpochValue = Annotated[Any, PlainValidator(_epoch_value)]


def _vector3(v: Any) -> list[float]:
    ok = isinstance(v, list) and len(v) == 3
    ok = ok and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v)
    if not ok:
        raise ValueError("must be a list of 3 numbers")
    try:
        out = [float(x) for x in v]
    except OverflowError:
        raise ValueError("must be finite numbers") from None
    if not all(math.isfinite(x) for x in out):
        raise ValueError("must be finite numbers")
    return out


Vector3 = Annotated[list[float], PlainValidator(_vector3)]
PositiveFloat = Annotated[float, Field(gt=0)]


def at_most(limit: float, unit: str, why: str = "", strict: bool = False) -> AfterValidator:
    """A validator of a number's magnitude (|x| <= limit, or < with ``strict``) whose message
    names the bound, its unit and why: ``must be <= 720 deg in magnitude (two turns)``."""
    op = "<" if strict else "<="
    text = f"must be {op} {limit:.6g} {unit} in magnitude" + (f" ({why})" if why else "")

    def check(v: float) -> float:
        if not (abs(v) < limit if strict else abs(v) <= limit):
            raise ValueError(text)
        return v

    return AfterValidator(check)


def norm_at_most(limit: float, unit: str, why: str = "", strict: bool = False) -> AfterValidator:
    """A validator of a 3-vector's length (as :func:`at_most`), naming the length found."""
    op = "<" if strict else "<="

    def check(v: list[float]) -> list[float]:
        n = math.hypot(*v)
        if not (n < limit if strict else n <= limit):
            raise ValueError(
                f"its length {n:.4g} {unit} must be {op} {limit:.6g} {unit}" + (f" ({why})" if why else "")
            )
        return v

    return AfterValidator(check)


#: a free angle (deg): two turns either way at most (fracas.config.fields.MAX_ANGLE_DEG)
AngleDeg = Annotated[float, at_most(MAX_ANGLE_DEG, "deg", "two turns")]
#: a time from the epoch or a duration (days): ~2,700 years at most
Days = Annotated[float, at_most(MAX_DAYS, "d", "about 2,700 years")]
#: a distance from a centre (km, > 0): ~6,700 AU at most
DistanceKm = Annotated[float, Field(gt=0), at_most(MAX_DISTANCE_KM, "km", "about 6,700 AU")]
#: a position (km): within ~6,700 AU of its centre
PositionKm = Annotated[list[float], PlainValidator(_vector3), norm_at_most(MAX_DISTANCE_KM, "km", "about 6,700 AU")]
#: a velocity (km/s): below the speed of light
VelocityKmS = Annotated[
    list[float], PlainValidator(_vector3), norm_at_most(MAX_SPEED_KM_S, "km/s", "the speed of light", strict=True)
]
#: a speed (km/s, >= 0): below the speed of light
SpeedKmS = Annotated[float, Field(ge=0), at_most(MAX_SPEED_KM_S, "km/s", "the speed of light", strict=True)]
#: a mass (kg, > 0): a million tonnes at most
MassKg = Annotated[float, Field(gt=0), at_most(MAX_MASS_KG, "kg", "a million tonnes")]
#: a specific impulse (s, > 0): an exhaust below the speed of light
IspS = Annotated[float, Field(gt=0), at_most(MAX_ISP_S, "s", "an exhaust at the speed of light", strict=True)]

_LABEL_RE = re.compile(r"^[a-z][a-z0-9_]*(\[[A-Za-z0-9_]+(,[A-Za-z0-9_]+)*\])?$")


def _check_label(v: str) -> str:
    if not _LABEL_RE.match(v):
        raise ValueError('must be a parameter label such as "mu[sun]", "thrust_scale" or "arc_thrust_scale[0]"')
    return v


def canonical_name(v: Any) -> Any:
    """A name as the catalogues spell it (lower case, no surrounding blanks); other types as given."""
    return v.strip().lower() if isinstance(v, str) else v


#: a parameter label, case-insensitive: "Mu[Sun]" is stored as "mu[sun]" (the catalogue's spelling)
ParamLabel = Annotated[str, BeforeValidator(canonical_name), AfterValidator(_check_label)]


class _Section(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid", strict=True, allow_inf_nan=False)


def _check_body_keys(v: dict[str, Any]) -> dict[str, Any]:
    out = {}
    for key, val in v.items():
        try:
            name = _body_name(key)
        except ValueError as exc:
            raise FieldProblem((key,), key, str(exc)) from None
        out[name] = val
    return out


def _no_repeats(v: list[str]) -> list[str]:
    """A list field's entries must be distinct (names the index of the repeat)."""
    for k, item in enumerate(v):
        if item in v[:k]:
            raise FieldProblem((k,), item, "listed twice")
    return v
