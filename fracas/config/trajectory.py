"""The trajectory deck: a TOML file describing one propagation (FRACAS TOM ``$DATA``, sec. 3.1).

Validated into frozen pydantic models in the units a user writes (days, degrees, kW,
Isp in s); :mod:`fracas.build` is the one place these convert to the core's km, s, kg,
rad.  No JAX here.  Layout (every section but ``[epoch]``, ``[initial_state]``,
``[spacecraft]`` and ``[stop]`` is optional)::

    title = "LEO with J2"                      # free text
    [epoch]           iso = "2030-01-01T00:00:00"   (TDB)   | julian_date = 2462502.5 (TDB)
    [initial_state]   centre = "earth", frame = "EME2000" | "ECLIPJ2000" | "BODY_EQUATOR"
                      and exactly one of the tables
      [initial_state.cartesian]  r_km = [x, y, z], v_km_s = [vx, vy, vz]
      [initial_state.elements]   a_km, e, i_deg, raan_deg, argp_deg,
                                 mean_anomaly_deg | true_anomaly_deg
      [initial_state.spherical]  r_km, lat_deg, lon_deg, v_km_s, gamma_deg, sigma_deg
      [initial_state.oem]        path = "x.oem", at = "start" | "end" | ISO TDB epoch
                                 (a CCSDS OEM record; [epoch] and centre may then be left
                                 out: docs/exchange.md)
    [spacecraft]      mass_kg, area_m2 = 0, cr = 1
    [propulsion]      power_source = "solar" | "nuclear", power_kw, decay_days (nuclear),
                      efficiency, exhaust_velocity_km_s | isp_s, thrust_scale = 1
    [[thrust_arc]]    start_days, stop_days, frame = "velocity" | "inertial" | "velocity_yaw_switch",
                      alpha_deg = 0, beta_deg = 0, throttle = 1
    [[impulse]]       time_days, dv_km_s = [3], frame = "velocity" | "inertial", isp_s = 300
    [forces]          third_bodies = [], j2 = false, srp = false, change_primary_at_soi = false
      [forces.overrides.BODY]     mu_km3_s2, j2, radius_km   (each optional)
      [forces.conic_bodies.BODY]  a_km, e, i_deg, raan_deg, argp_deg, mean_anomaly_deg,
                                  epoch = ISO string | Julian date (TDB),
                                  frame = "EME2000" | "ECLIPJ2000" (of the angles)
    [integrator]      method = "auto" | "dprkn12" | "dprkn8" | "dop853" | "rkn4",
                      formulation = "auto" | "cowell" | "encke", step_control = "auto" |
                      "tolerance" | "c_nom", tolerance = 1e-12, c_nom = 0.3, dt_max_s,
                      rect_ratio = 0.01, eps_t_s = 1e-6, max_steps = 200000
    [stop]            duration_days | final_epoch (ISO string or Julian date, TDB),
                      condition = "time" | "soi_entry" | "closest_approach" | "radius",
                      body, radius_km
    [output]          times_days = [], step_days, include_final = true
                      (t = 0 is always the first output), sensitivities = ["mu[earth]", ...], stm = false

Backward propagation: ``duration_days < 0`` or a ``final_epoch`` before ``[epoch]``.  Every
time (thrust arcs, impulses, output times) is then in ``[duration, 0]`` days, still measured
from the epoch; lists stay in increasing time order (an arc is on for start <= t < stop);
``step_days`` is a magnitude applied in the direction of propagation (a sign, if written,
must agree with it) and outputs run from t = 0 backward.  Stop conditions "time" and
"radius" work in both directions; "soi_entry", "closest_approach", primary changes and an
impulse at t = 0 are refused on a backward deck.

The primary body of the propagation (centre of the Encke conic) is the initial-state
centre.  :func:`load_deck` turns every problem into :class:`fracas.errors.DeckError` with
one line ``path: field.path = value: what was expected``.
"""

from __future__ import annotations

import datetime as _dt
import difflib
import functools
import hashlib
import json
import math
import re
import types
import typing
from pathlib import Path
from typing import Annotated, Any, Literal

import tomllib
from pydantic import (
    AfterValidator,
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    PlainValidator,
    PrivateAttr,
    ValidationError,
    ValidationInfo,
    field_validator,
    model_validator,
)

from fracas.config.limits import Limits, count_text
from fracas.constants import BODIES, DAY_S, DE421_END_JD, DE421_START_JD, J2000_JD
from fracas.errors import ConfigError, DeckError
from fracas.timescales import calendar_to_et, epoch_to_et, et_to_calendar

__all__ = [
    "TrajectoryDeck",
    "load_deck",
    "parse_deck",
    "FieldProblem",
    "FieldProblems",
    "load_toml",
    "validation_problems",
    "MAX_NESTING",
    "BACKWARD_TEAM_PROBLEM",
    "MAX_DECK_BYTES",
    "deck_bodies",
    "needs_ephemeris",
    "initial_radius_km",
]

#: deepest nesting of arrays / inline tables a deck may use (the schema needs 3)
MAX_NESTING = 16
#: largest deck file (a deck is a page of text; this only stops a runaway file)
MAX_DECK_BYTES = 16 * 1024 * 1024
#: TOML integers are 64-bit signed (TOML 1.0); tomllib accepts any size
_INT_MIN, _INT_MAX = -(2**63), 2**63 - 1
#: longest echo of a value in an error line
ECHO_CHARS = 40

BODY_NAMES = tuple(BODIES)


class FieldProblem(ValueError):
    """A validation failure that knows which (sub)field it concerns and its offending value.

    ``field`` is a path relative to the model being validated (``("stop", "radius_km")``);
    :func:`format_validation_error` appends it to pydantic's location.
    """

    def __init__(self, field: tuple[str | int, ...] | str, value: Any, expected: str):
        self.field = (field,) if isinstance(field, str) else tuple(field)
        self.value = value
        self.expected = expected
        super().__init__(expected)


class FieldProblems(ValueError):
    """Several :class:`FieldProblem` found by one validator (all of them are reported)."""

    def __init__(self, problems: list[FieldProblem]):
        self.problems = list(problems)
        super().__init__("; ".join(p.expected for p in problems))


def raise_problems(problems: list[FieldProblem]) -> None:
    """Raise the problems a cross-check collected (nothing if none)."""
    if len(problems) == 1:
        raise problems[0]
    if problems:
        raise FieldProblems(problems)


class _Given(str):
    """A value printed as is in an error line (the set of keys given in a table)."""


def _given(model: BaseModel, keys: tuple[str, ...]) -> _Given:
    return _Given("{" + ", ".join(k for k in keys if getattr(model, k) is not None) + "}")


# --------------------------------------------------------------------------- helpers


def _exactly_one(model: BaseModel, keys: tuple[str, ...], what: str = "") -> None:
    """Raise the one-line deck error unless exactly one of ``keys`` is given."""
    if sum(getattr(model, k) is not None for k in keys) != 1:
        raise FieldProblem((), _given(model, keys), f"give exactly one of {what}{', '.join(keys)}")


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


# --------------------------------------------------------------------------- sections


class Epoch(_Section):
    """Propagation epoch, TDB: an ISO calendar string or a Julian date (exactly one)."""

    iso: IsoEpoch | None = None
    julian_date: Annotated[float, Field(gt=1_000_000.0, lt=5_000_000.0)] | None = None

    @model_validator(mode="after")
    def _one(self) -> Epoch:
        _exactly_one(self, ("iso", "julian_date"))
        return self

    @property
    def et(self) -> float:
        """TDB seconds past J2000."""
        return epoch_to_et(self.iso if self.iso is not None else self.julian_date)


class Cartesian(_Section):
    r_km: Vector3
    v_km_s: Vector3

    @field_validator("r_km")
    @classmethod
    def _nonzero(cls, v: list[float]) -> list[float]:
        if math.hypot(*v) == 0.0:
            raise ValueError("must not be the zero vector")
        return v


class Elements(_Section):
    """Classical elements about the centre (a < 0 for hyperbolas, e >= 0, e != 1)."""

    a_km: float
    e: Annotated[float, Field(ge=0)]
    i_deg: Annotated[float, Field(ge=0, le=180)]
    raan_deg: float = 0.0
    argp_deg: float = 0.0
    mean_anomaly_deg: float | None = None
    true_anomaly_deg: float | None = None

    @model_validator(mode="after")
    def _consistent(self) -> Elements:
        _exactly_one(self, ("mean_anomaly_deg", "true_anomaly_deg"))
        if abs(self.e - 1.0) < 1e-12:
            raise FieldProblem("e", self.e, "parabolic orbits (e = 1) are not supported")
        if self.e < 1.0 and self.a_km <= 0.0:
            raise FieldProblem("a_km", self.a_km, "must be > 0 for an ellipse (e < 1)")
        if self.e > 1.0 and self.a_km >= 0.0:
            raise FieldProblem("a_km", self.a_km, "must be < 0 for a hyperbola (e > 1)")
        if self.e > 1.0 and self.true_anomaly_deg is not None:
            limit = math.degrees(math.acos(-1.0 / self.e))
            nu = (self.true_anomaly_deg + 180.0) % 360.0 - 180.0
            if abs(nu) >= limit:
                raise FieldProblem(
                    "true_anomaly_deg",
                    self.true_anomaly_deg,
                    f"must satisfy |nu| < {limit:.6g} deg (the hyperbola's asymptote) for e = {self.e:g}",
                )
        return self


class Spherical(_Section):
    """Position/velocity in spherical form: flight-path angle gamma from the local
    horizontal, azimuth sigma from north towards east."""

    r_km: PositiveFloat
    lat_deg: Annotated[float, Field(ge=-90, le=90)]
    lon_deg: float
    v_km_s: Annotated[float, Field(ge=0)]
    gamma_deg: Annotated[float, Field(ge=-90, le=90)]
    sigma_deg: float


def _oem_at(v: Any) -> str:
    if isinstance(v, str) and v.strip().lower() in ("start", "end"):
        return v.strip().lower()
    try:
        return _iso_value(v)
    except ValueError:
        raise ValueError('must be "start", "end" or an ISO calendar date such as "2030-01-01T00:00:00" (TDB)') from None


class OemState(_Section):
    """Initial state read from a CCSDS OEM (``fracas.io.ccsds``, docs/exchange.md): the record
    at ``at`` ("start", "end" or an ISO TDB epoch; default the deck's ``[epoch]``, else "start"),
    or the OEM's own interpolation between records.  ``path`` is relative to the deck's folder.
    ``[epoch]`` and ``initial_state.centre`` may then be left out (they come from the OEM); the
    state read is in ``r_km``, ``v_km_s`` (ICRF axes) after validation."""

    path: Annotated[str, Field(min_length=1)]
    at: Annotated[str, PlainValidator(_oem_at)] | None = None
    _r_km: tuple[float, ...] = PrivateAttr(())
    _v_km_s: tuple[float, ...] = PrivateAttr(())
    _et: float = PrivateAttr(math.nan)
    _how: str = PrivateAttr("")

    @property
    def r_km(self) -> list[float]:
        return list(self._r_km)

    @property
    def v_km_s(self) -> list[float]:
        return list(self._v_km_s)

    @property
    def record(self) -> str:
        """Which record was taken ("record 1 of segment 1", "interpolated (HERMITE 7) ...")."""
        return self._how


def _oem_file(path: str, source: str | None):
    """The OEM a deck names (relative to the deck's folder), read once per file version."""
    p = Path(path).expanduser()
    if not p.is_absolute() and source and not source.startswith("<"):
        p = Path(source).parent / p
    try:
        st = p.stat()
        key = (str(p), st.st_mtime_ns, st.st_size)
    except OSError:
        key = (str(p), 0, 0)
    return _read_oem_cached(*key)


@functools.lru_cache(maxsize=16)
def _read_oem_cached(path: str, _mtime: int, _size: int):
    from fracas.io.ccsds import read_oem

    return read_oem(path)


def _oem_sample(oem_data: dict, at: Any, source: str | None):
    """(et, r, v, segment, how) of the OEM a deck names; FieldProblem on initial_state.oem."""
    from fracas.errors import FracasError
    from fracas.io.ccsds import sample_oem

    path = oem_data.get("path")
    try:
        oem = _oem_file(path, source)
    except FracasError as exc:
        raise FieldProblem(("initial_state", "oem", "path"), path, str(exc)) from None
    try:
        return sample_oem(oem, at)
    except FracasError as exc:
        shown = at if isinstance(at, str) else f"{et_to_calendar(at, 6)} TDB ([epoch])"
        raise FieldProblem(("initial_state", "oem", "at"), _Given(shown), str(exc)) from None


class InitialState(_Section):
    centre: BodyName
    frame: Literal["EME2000", "ECLIPJ2000", "BODY_EQUATOR"] = "EME2000"
    cartesian: Cartesian | None = None
    elements: Elements | None = None
    spherical: Spherical | None = None
    oem: OemState | None = None

    @model_validator(mode="after")
    def _one_table(self) -> InitialState:
        tables = ("cartesian", "elements", "spherical")
        if self.oem is None:
            _exactly_one(self, tables, what="the tables ")
        elif any(getattr(self, k) is not None for k in tables):
            _exactly_one(self, (*tables, "oem"), what="the tables ")
        if self.oem is not None and "frame" in self.model_fields_set and self.frame != "EME2000":
            raise FieldProblem("frame", self.frame, "the OEM gives the axes (ICRF/EME2000); leave frame out")
        return self

    @property
    def kind(self) -> str:
        return next(k for k in ("cartesian", "elements", "spherical", "oem") if getattr(self, k) is not None)


class Spacecraft(_Section):
    mass_kg: PositiveFloat
    area_m2: Annotated[float, Field(ge=0)] = 0.0
    cr: Annotated[float, Field(ge=0, le=2)] = 1.0


class Propulsion(_Section):
    """Electric propulsion: thrust T = 2 eta P / c, mass flow T / c (FRACAS EP)."""

    power_source: Literal["solar", "nuclear"] = "solar"
    power_kw: PositiveFloat
    decay_days: PositiveFloat | None = None
    efficiency: Annotated[float, Field(gt=0, le=1)]
    exhaust_velocity_km_s: PositiveFloat | None = None
    isp_s: PositiveFloat | None = None
    thrust_scale: Annotated[float, Field(ge=0)] = 1.0

    @model_validator(mode="after")
    def _consistent(self) -> Propulsion:
        _exactly_one(self, ("exhaust_velocity_km_s", "isp_s"))
        if self.decay_days is not None and self.power_source != "nuclear":
            raise FieldProblem("decay_days", self.decay_days, 'only for power_source = "nuclear"')
        return self


class ThrustArc(_Section):
    """Thrust on for start_days <= t < stop_days (days from the epoch); alpha/beta are the
    in-plane/out-of-plane angles in the velocity frame, or right ascension/declination
    of an inertial (ICRF) direction; ``velocity_yaw_switch`` is the velocity frame with
    beta's sign following cos u (the argument of latitude), flipping at the antinodes
    (Edelbaum's plane-change steering: beta > 0 raises the inclination, < 0 lowers it)."""

    start_days: float
    stop_days: float
    frame: Literal["velocity", "inertial", "velocity_yaw_switch"] = "velocity"
    alpha_deg: float = 0.0
    beta_deg: Annotated[float, Field(ge=-90, le=90)] = 0.0
    throttle: Annotated[float, Field(ge=0, le=1)] = 1.0
    # pointing that varies within the arc: Legendre coefficients (P1, P2, P3) of alpha and beta in
    # the arc's normalised time s = (2t - start - stop)/(stop - start); alpha_deg/beta_deg stay the
    # arc's mean angles.  Up to three each; [] (the default) is constant pointing.
    alpha_legendre_deg: Annotated[list[float], Field(max_length=3)] = []
    beta_legendre_deg: Annotated[list[float], Field(max_length=3)] = []

    @model_validator(mode="after")
    def _ordered(self) -> ThrustArc:
        # a zero-length arc is allowed (an optimizer may switch a burn off by closing it)
        if self.stop_days < self.start_days:
            raise FieldProblem("stop_days", self.stop_days, f"must be >= start_days = {self.start_days:g}")
        for name in ("alpha_legendre_deg", "beta_legendre_deg"):
            if not all(math.isfinite(c) for c in getattr(self, name)):
                raise FieldProblem(name, getattr(self, name), "finite numbers")
        return self

    @property
    def steered(self) -> bool:
        """Does the pointing vary within the arc (any nonzero Legendre coefficient)?"""
        return any(c != 0.0 for c in (*self.alpha_legendre_deg, *self.beta_legendre_deg))


class Impulse(_Section):
    time_days: float
    dv_km_s: Vector3
    frame: Literal["velocity", "inertial"] = "velocity"
    isp_s: PositiveFloat = 300.0


class BodyOverride(_Section):
    mu_km3_s2: PositiveFloat | None = None
    j2: float | None = None
    radius_km: PositiveFloat | None = None


class ConicBody(_Section):
    """Heliocentric conic elements standing in for the body's ephemeris (FRACAS EPHEM)."""

    a_km: PositiveFloat
    e: Annotated[float, Field(ge=0, lt=1)]
    i_deg: Annotated[float, Field(ge=0, le=180)]
    raan_deg: float
    argp_deg: float
    mean_anomaly_deg: float
    epoch: EpochValue
    frame: Literal["EME2000", "ECLIPJ2000"] = "EME2000"


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


class Forces(_Section):
    third_bodies: list[BodyName] = []
    j2: bool = False
    srp: bool = False
    change_primary_at_soi: bool = False
    overrides: Annotated[dict[str, BodyOverride], AfterValidator(_check_body_keys)] = {}
    conic_bodies: Annotated[dict[str, ConicBody], AfterValidator(_check_body_keys)] = {}

    _unique = field_validator("third_bodies")(classmethod(lambda cls, v: _no_repeats(v)))


class Integrator(_Section):
    """How the propagation steps (see fracas.dynamics.model.IntegratorSettings, docs/integrators.md).

    method: "auto" (DPRKN12 without thrust, DOP853 with thrust -- the special RKN methods
    need accelerations independent of velocity and mass), "dprkn12", "dprkn8", "dop853" or
    "rkn4" (FRACAS's 4th-order Nystrom); formulation: "auto" (Cowell for the high-order
    methods, Encke for rkn4), "cowell" or "encke"; step_control: "auto" (tolerance for the
    embedded methods, c_nom for rkn4), "tolerance" or "c_nom"; tolerance: relative local
    error per step (position, velocity and mass errors each relative to their magnitude);
    dt_max_s: largest step (default: 4000 s under c_nom, none under tolerance control).
    """

    method: Literal["auto", "dprkn12", "dprkn8", "dop853", "rkn4"] = "auto"
    formulation: Literal["auto", "cowell", "encke"] = "auto"
    step_control: Literal["auto", "tolerance", "c_nom"] = "auto"
    tolerance: Annotated[float, Field(ge=1e-15, le=1e-3)] = 1e-12
    c_nom: Annotated[float, Field(gt=0, le=2)] = 0.3
    dt_max_s: PositiveFloat | None = None
    rect_ratio: Annotated[float, Field(gt=0, lt=1)] = 0.01
    eps_t_s: PositiveFloat = 1e-6
    max_steps: Annotated[int, Field(ge=1, le=100_000_000)] = 200_000

    @model_validator(mode="after")
    def _consistent(self) -> Integrator:
        if self.method == "rkn4" and self.step_control == "tolerance":
            raise FieldProblem(
                "step_control",
                "tolerance",
                'rkn4 has no embedded error estimate: use step_control = "c_nom" (or "auto")',
            )
        _, _, control = self.resolved(thrust=False)
        if "c_nom" in self.model_fields_set and control == "tolerance":
            raise FieldProblem(
                "c_nom", self.c_nom, 'applies only with step_control = "c_nom"; under tolerance control set tolerance'
            )
        if "tolerance" in self.model_fields_set and control == "c_nom":
            raise FieldProblem(
                "tolerance",
                self.tolerance,
                'applies only with step_control = "tolerance" (dprkn12, dprkn8, dop853); '
                "c_nom sets the steps of this deck",
            )
        return self

    @property
    def _c_nom_asked(self) -> bool:
        return "c_nom" in self.model_fields_set or self.step_control == "c_nom"

    def resolved(self, thrust: bool) -> tuple[str, str, str]:
        """(method, formulation, step_control) with every "auto" decided.

        method "auto": FRACAS's rkn4 when the deck sets c_nom (or step_control = "c_nom": the
        deck asks for FRACAS's step rule), else dop853 with thrust arcs and dprkn12 without;
        formulation "auto": Encke for rkn4 (FRACAS), Cowell for the high-order methods (faster
        at equal accuracy in the measured cases, benchmarks/results_highorder.txt);
        step_control "auto": c_nom for rkn4 or when c_nom is set, tolerance otherwise.
        """
        method = self.method
        if method == "auto":
            method = "rkn4" if self._c_nom_asked else ("dop853" if thrust else "dprkn12")
        formulation = self.formulation
        if formulation == "auto":
            formulation = "encke" if method == "rkn4" else "cowell"
        control = self.step_control
        if control == "auto":
            control = "c_nom" if (method == "rkn4" or "c_nom" in self.model_fields_set) else "tolerance"
        return method, formulation, control


class Stop(_Section):
    duration_days: float | None = None  # < 0: backward propagation
    final_epoch: EpochValue | None = None
    condition: Literal["time", "soi_entry", "closest_approach", "radius"] = "time"
    body: BodyName | None = None
    radius_km: PositiveFloat | None = None

    @model_validator(mode="after")
    def _consistent(self) -> Stop:
        _exactly_one(self, ("duration_days", "final_epoch"))
        if self.duration_days == 0.0:
            raise FieldProblem("duration_days", self.duration_days, "must be nonzero (< 0 propagates backward)")
        if self.condition in ("soi_entry", "closest_approach") and self.body is None:
            raise FieldProblem("body", None, f'required for condition = "{self.condition}"')
        if self.condition == "radius" and self.radius_km is None:
            raise FieldProblem("radius_km", None, 'required for condition = "radius"')
        if self.condition != "radius" and self.radius_km is not None:
            raise FieldProblem("radius_km", self.radius_km, 'only for condition = "radius"')
        if self.condition == "time" and self.body is not None:
            raise FieldProblem("body", self.body, 'not used for condition = "time"')
        return self


class Output(_Section):
    times_days: list[float] = []
    step_days: float | None = None  # a magnitude, applied in the direction of propagation
    include_final: bool = True
    sensitivities: list[ParamLabel] = []
    stm: bool = False

    _unique = field_validator("sensitivities")(classmethod(lambda cls, v: _no_repeats(v)))


BACKWARD_TEAM_PROBLEM = "is a backward trajectory (final time before the epoch); TEAM needs a forward one"


class SourcedDeck(_Section):
    """A whole deck that remembers where it came from (``source_path``, ``source_text``)."""

    _source_path: str | None = PrivateAttr(None)
    _source_text: str | None = PrivateAttr(None)

    @property
    def source_path(self) -> str | None:
        return self._source_path

    def resolve(self, rel: str) -> Path:
        """A path named in the deck, relative to the deck's folder."""
        p = Path(rel)
        if p.is_absolute() or self._source_path is None:
            return p
        return Path(self._source_path).parent / p

    @property
    def source_text(self) -> str | None:
        return self._source_text


class TrajectoryDeck(SourcedDeck):
    """A whole trajectory deck (frozen).  ``source_path``/``source_text`` say where it came from.

    ``mode = "propagate"`` may be written; a deck without ``mode`` is a trajectory deck."""

    mode: Literal["propagate"] = "propagate"
    title: str = ""
    epoch: Epoch
    initial_state: InitialState
    spacecraft: Spacecraft
    propulsion: Propulsion | None = None
    thrust_arc: list[ThrustArc] = []
    impulse: list[Impulse] = []
    forces: Forces = Forces()
    integrator: Integrator = Integrator()
    stop: Stop
    output: Output = Output()
    limits: Limits = Limits()

    @model_validator(mode="before")
    @classmethod
    def _from_oem(cls, data: Any, info: ValidationInfo) -> Any:
        """With ``[initial_state.oem]``: ``[epoch]`` and ``initial_state.centre`` from the OEM when left out."""
        ist = data.get("initial_state") if isinstance(data, dict) else None
        oem = ist.get("oem") if isinstance(ist, dict) else None
        if not isinstance(oem, dict) or not isinstance(oem.get("path"), str) or not oem["path"]:
            return data
        if "epoch" in data and "centre" in ist:
            return data
        try:
            at = _oem_at(oem["at"]) if "at" in oem else "start"
        except ValueError:
            return data  # the field's own validation reports it
        if "at" not in oem and "epoch" in data:
            try:
                at = Epoch.model_validate(data["epoch"]).et
            except ValidationError:
                return data
        source = (info.context or {}).get("source") if info is not None else None
        et, _, _, seg, _ = _oem_sample(oem, at, source)
        data = dict(data)
        if "epoch" not in data:
            data["epoch"] = {"iso": et_to_calendar(et, 9)}
        if "centre" not in ist:
            data["initial_state"] = {**ist, "centre": seg.centre}
        return data

    @model_validator(mode="after")
    def _oem_state(self, info: ValidationInfo) -> TrajectoryDeck:
        """Read the initial state of ``[initial_state.oem]`` at the deck's epoch."""
        source = (info.context or {}).get("source") if info is not None else None
        st = self.initial_state
        if st.oem is None:
            return self
        at = st.oem.at if st.oem.at is not None else self.epoch.et
        et, r, v, seg, how = _oem_sample(st.oem.model_dump(), at, source)
        if abs(et - self.epoch.et) > 1e-6:
            raise FieldProblem(
                ("initial_state", "oem", "at"),
                st.oem.at,
                f"is {et_to_calendar(et, 6)} TDB but [epoch] is {et_to_calendar(self.epoch.et, 6)} TDB: "
                "they must agree (or leave one out)",
            )
        if seg.centre != st.centre:
            raise FieldProblem(
                ("initial_state", "centre"),
                st.centre,
                f"the OEM's segment at that epoch has CENTER_NAME = {seg.centre.upper()}: they must agree",
            )
        st.oem._r_km, st.oem._v_km_s = tuple(map(float, r)), tuple(map(float, v))
        st.oem._et, st.oem._how = float(et), how
        return self

    @property
    def primary(self) -> str:
        return self.initial_state.centre

    @property
    def duration_days(self) -> float:
        """Final time in days from the epoch."""
        if self.stop.duration_days is not None:
            return self.stop.duration_days
        return (epoch_to_et(self.stop.final_epoch) - self.epoch.et) / DAY_S

    @property
    def backward(self) -> bool:
        """Whether the final time is before the epoch (backward propagation)."""
        return self.duration_days < 0.0

    def _span_problem(self, loc: tuple, t: float) -> FieldProblem | None:
        """The problem with a time ``t`` (days) outside the propagation span, if any."""
        dur = self.duration_days
        if dur > 0.0:
            if t < 0.0:
                return FieldProblem(loc, t, "must be >= 0 (the epoch)")
            if t > dur * (1 + 1e-12):
                return FieldProblem(loc, t, f"must be <= the final time, {dur:g} days")
        else:
            if t > 0.0:
                return FieldProblem(loc, t, f"must be <= 0 (the epoch; a backward propagation spans {dur:g} to 0 days)")
            if t < dur * (1 + 1e-12):
                return FieldProblem(loc, t, f"must be >= the final time, {dur:g} days (a backward propagation)")
        return None

    def _backward_checks(self) -> None:
        """What a backward deck cannot ask for (the core's event functions assume forward time)."""
        stop = self.stop
        if stop.condition in ("soi_entry", "closest_approach"):
            raise FieldProblem(
                ("stop", "condition"),
                stop.condition,
                'not supported on a backward propagation (duration < 0); use "time" or "radius"',
            )
        if self.forces.change_primary_at_soi:
            raise FieldProblem(
                ("forces", "change_primary_at_soi"), True, "not supported on a backward propagation (duration < 0)"
            )
        for k, imp in enumerate(self.impulse):
            if imp.time_days == 0.0:
                raise FieldProblem(
                    ("impulse", k, "time_days"),
                    imp.time_days,
                    "must be < 0 on a backward propagation (at the epoch it is ambiguous whether the "
                    "initial state is before or after the impulse)",
                )

    @model_validator(mode="after")
    def _cross_checks(self) -> TrajectoryDeck:
        dur = self.duration_days
        if not math.isfinite(dur) or dur == 0.0:
            field = ("stop", "final_epoch") if self.stop.final_epoch is not None else ("stop", "duration_days")
            value = self.stop.final_epoch if self.stop.final_epoch is not None else self.stop.duration_days
            raise FieldProblem(field, value, "must differ from the epoch (a finite, nonzero duration)")
        step = self.output.step_days
        if step is not None and (step == 0.0 or (step < 0.0 and dur > 0.0)):
            expected = "must be nonzero" if step == 0.0 else "must be > 0 on a forward propagation"
            raise FieldProblem(("output", "step_days"), step, expected + " (it runs in the direction of propagation)")
        if dur < 0.0:
            self._backward_checks()
        centre = self.initial_state.centre
        f = self.forces
        if centre in f.third_bodies:
            k = f.third_bodies.index(centre)
            raise FieldProblem(
                ("forces", "third_bodies", k),
                centre,
                f'is the primary (initial_state.centre = "{centre}"); it cannot also be a third body',
            )
        if self.thrust_arc and self.propulsion is None:
            raise FieldProblem(("propulsion",), None, "a [propulsion] section is required when thrust arcs are given")
        if self.thrust_arc and self.integrator.method in ("dprkn12", "dprkn8"):
            raise FieldProblem(
                ("integrator", "method"),
                self.integrator.method,
                "a special RKN method needs an acceleration independent of velocity and mass; with thrust arcs "
                'use "dop853" (or "auto"), or "rkn4"',
            )
        prev = None
        for k, arc in enumerate(self.thrust_arc):
            if prev is not None and arc.start_days < prev.stop_days:
                raise FieldProblem(
                    ("thrust_arc", k, "start_days"),
                    arc.start_days,
                    f"must be >= thrust_arc[{k - 1}].stop_days = {prev.stop_days:g} (arcs ordered, not overlapping)",
                )
            for name in ("start_days", "stop_days"):
                problem = self._span_problem(("thrust_arc", k, name), getattr(arc, name))
                if problem is not None:
                    raise problem
            prev = arc
        for k, imp in enumerate(self.impulse):
            problem = self._span_problem(("impulse", k, "time_days"), imp.time_days)
            if problem is not None:
                raise problem
            if k > 0 and imp.time_days < self.impulse[k - 1].time_days:
                raise FieldProblem(
                    ("impulse", k, "time_days"),
                    imp.time_days,
                    f"must be >= impulse[{k - 1}].time_days (impulses in time order)",
                )
            if imp.isp_s != self.impulse[0].isp_s:
                raise FieldProblem(
                    ("impulse", k, "isp_s"),
                    imp.isp_s,
                    f"must equal impulse[0].isp_s = {self.impulse[0].isp_s:g} (one impulsive engine)",
                )
        if f.srp and self.spacecraft.area_m2 <= 0.0:
            raise FieldProblem(("spacecraft", "area_m2"), self.spacecraft.area_m2, "must be > 0 when forces.srp = true")
        for name in f.conic_bodies:
            if name == "sun":
                raise FieldProblem(
                    ("forces", "conic_bodies", name), name, "the Sun cannot have heliocentric conic elements"
                )
            if name != centre and name not in f.third_bodies and name != self.stop.body:
                raise FieldProblem(
                    ("forces", "conic_bodies", name), name, "must be the centre, a third body or the stop body"
                )
        for k, t in enumerate(self.output.times_days):
            problem = self._span_problem(("output", "times_days", k), t)
            if problem is not None:
                raise problem
        if self.stop.condition == "soi_entry" and self.stop.body == centre:
            raise FieldProblem(("stop", "body"), self.stop.body, "must differ from the centre for soi_entry")
        n = output_count(self.output, dur)
        if n > self.limits.max_output_times:
            field = ("output", "step_days") if self.output.step_days is not None else ("output", "times_days")
            value = (
                self.output.step_days
                if self.output.step_days is not None
                else _Given(f"[{len(self.output.times_days)} times]")
            )
            raise FieldProblem(
                field,
                value,
                f"gives {count_text(n)} output times over {_span_text(dur)} d "
                f"(limit {self.limits.max_output_times}, [limits] max_output_times); use a longer step",
            )
        return self

    @model_validator(mode="after")
    def _run_checks(self) -> TrajectoryDeck:
        """What a propagation would refuse, checked here so that ``fracas validate`` refuses it
        too: a start inside the central body, a span outside the ephemeris, an override of a
        body the force model does not have."""
        bodies = deck_bodies(self)
        for name in self.forces.overrides:
            if name not in bodies:
                raise FieldProblem(
                    ("forces", "overrides", name),
                    _Given(name),
                    f"is not in the force model ({', '.join(bodies)}); add it to forces.third_bodies or remove it",
                )
        problem = self._inside_centre()
        if problem is not None:
            raise problem
        if needs_ephemeris(self):
            problem = self._outside_ephemeris(bodies)
            if problem is not None:
                raise problem
        return self

    def _inside_centre(self) -> FieldProblem | None:
        """A start below the centre's radius (constants.BODIES, or forces.overrides)."""
        st = self.initial_state
        centre = st.centre
        ov = self.forces.overrides.get(centre)
        radius = ov.radius_km if ov is not None and ov.radius_km is not None else BODIES[centre].radius_km
        r = initial_radius_km(st)
        if r is None or not r < radius:
            return None
        table = st.kind
        loc: tuple = ("initial_state", table)
        value: Any = None
        if table == "cartesian":
            loc, value = (*loc, "r_km"), st.cartesian.r_km
        elif table == "spherical":
            loc, value = (*loc, "r_km"), st.spherical.r_km
        elif table == "oem":
            loc, value = (*loc, "path"), st.oem.path
        return FieldProblem(
            loc,
            value,
            f"starts {r:.6g} km from the centre of {centre}, inside its radius {radius:.10g} km "
            "(fracas.constants; forces.overrides to change it): the initial state must be outside the centre",
        )

    def _outside_ephemeris(self, bodies: tuple[str, ...]) -> FieldProblem | None:
        """The epoch or the final time outside the DE421 span (constants.DE421_START_JD/END_JD)."""
        lo, hi = ((jd - J2000_JD) * DAY_S for jd in (DE421_START_JD, DE421_END_JD))
        span = f"{et_to_calendar(lo)[:10]} to {et_to_calendar(hi)[:10]} TDB"
        why = f"the DE421 ephemeris spans {span}, and the force model needs positions of {', '.join(bodies)}"
        t0 = self.epoch.et
        if not lo <= t0 <= hi:
            field = "iso" if self.epoch.iso is not None else "julian_date"
            value = self.epoch.iso if self.epoch.iso is not None else self.epoch.julian_date
            return FieldProblem(("epoch", field), value, f"is outside the ephemeris: {why}")
        t1 = t0 + self.duration_days * DAY_S
        if not lo <= t1 <= hi:
            if self.stop.final_epoch is not None:
                loc, value = ("stop", "final_epoch"), self.stop.final_epoch
            else:
                loc, value = ("stop", "duration_days"), self.stop.duration_days
            when = et_to_calendar(t1)[:19] if math.isfinite(t1) else "never"
            return FieldProblem(loc, value, f"ends the trajectory at {when} TDB, outside the ephemeris: {why}")
        return None


def deck_bodies(deck: TrajectoryDeck) -> tuple[str, ...]:
    """Bodies whose GM/position the propagation needs, in catalogue order.

    The centre; third bodies; conic bodies; the stop body; the Sun when solar power drives
    thrust arcs or SRP is on; with change_primary_at_soi, the parents of all of these (the
    primary a spacecraft leaving a sphere of influence falls back to).
    """
    need = {deck.initial_state.centre, *deck.forces.third_bodies, *deck.forces.conic_bodies}
    if deck.stop.body:
        need.add(deck.stop.body)
    solar = deck.propulsion is not None and deck.propulsion.power_source == "solar"
    if deck.forces.srp or (solar and deck.thrust_arc):
        need.add("sun")
    if deck.forces.change_primary_at_soi:
        for name in list(need):
            parent = BODIES[name].parent
            while parent is not None:
                need.add(parent)
                parent = BODIES[parent].parent
    return tuple(b for b in BODIES if b in need)


def needs_ephemeris(deck: TrajectoryDeck) -> bool:
    """Whether the propagation reads DE421 (a body other than the Sun and the conic bodies
    needs a position: fracas.build.trajectory builds the table then)."""
    bodies = deck_bodies(deck)
    return len(bodies) > 1 and any(b != "sun" and b not in deck.forces.conic_bodies for b in bodies)


def _eccentric_radius(a: float, e: float, m: float) -> float | None:
    """|r| on the conic (a, e) at mean anomaly ``m`` (rad), by Newton on Kepler's equation;
    None if it does not converge."""
    if e < 1.0:
        m = math.remainder(m, 2.0 * math.pi)
        ecc = m + e * math.sin(m) if e < 0.8 else math.copysign(math.pi, m) if m else 0.0
        for _ in range(100):
            step = (ecc - e * math.sin(ecc) - m) / (1.0 - e * math.cos(ecc))
            ecc -= step
            if abs(step) < 1e-14:
                return a * (1.0 - e * math.cos(ecc))
        return None
    h = math.asinh(m / e)
    for _ in range(200):
        f = e * math.sinh(h) - h - m
        step = f / (e * math.cosh(h) - 1.0)
        h -= step
        if not math.isfinite(h):
            return None
        if abs(step) < 1e-14 * max(1.0, abs(h)):
            return a * (1.0 - e * math.cosh(h))
    return None


def initial_radius_km(st: InitialState) -> float | None:
    """|r| of the initial state (km from the centre), from any form it is given in (None if it
    cannot be computed without the core, e.g. a Kepler solve that does not converge)."""
    if st.cartesian is not None:
        return math.hypot(*st.cartesian.r_km)
    if st.spherical is not None:
        return st.spherical.r_km
    if st.oem is not None:
        return math.hypot(*st.oem.r_km) if st.oem.r_km else None
    el = st.elements
    if el.true_anomaly_deg is not None:
        return el.a_km * (1.0 - el.e**2) / (1.0 + el.e * math.cos(math.radians(el.true_anomaly_deg)))
    try:
        r = _eccentric_radius(el.a_km, el.e, math.radians(el.mean_anomaly_deg))
    except (OverflowError, ZeroDivisionError, ValueError):
        return None
    return r if r is not None and math.isfinite(r) else None


def _span_text(dur: float) -> str:
    return f"0-{dur:g}" if dur >= 0.0 else f"{dur:g}-0"


def output_count(out: Output, duration_days: float) -> float:
    """How many output times ``[output]`` asks for (an upper bound, computed without building them)."""
    n = 2.0 + len(out.times_days)
    if out.step_days is not None and out.step_days != 0.0:
        q = abs(duration_days / out.step_days) * (1.0 + 1e-12)
        n += (math.floor(q) + 1.0) if q < 1e18 else q
    return n


# --------------------------------------------------------------------------- loading


def _fmt_value(v: Any) -> str:
    if isinstance(v, _Given):
        return str(v)
    if isinstance(v, (_dt.date, _dt.datetime)):
        s = v.isoformat()
    else:
        try:
            s = json.dumps(v, default=str)
        except (TypeError, ValueError, RecursionError):
            s = repr(v)
    return cut(s)


def cut(s: str, n: int = ECHO_CHARS) -> str:
    """``s`` cut to ``n`` characters with "…" (values echoed in error lines)."""
    return s if len(s) <= n else s[: n - 1] + "…"


def _fmt_loc(loc: tuple) -> str:
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        elif part == "[key]":
            continue
        else:
            out += ("." if out else "") + str(part)
    return out or "<deck>"


def _strip(ann: Any) -> Any:
    """Drop Annotated and Optional wrappers from a type annotation."""
    while True:
        origin = typing.get_origin(ann)
        if origin is Annotated:
            ann = typing.get_args(ann)[0]
        elif origin in (typing.Union, types.UnionType):
            args = [a for a in typing.get_args(ann) if a is not type(None)]
            if len(args) != 1:
                return ann
            ann = args[0]
        else:
            return ann


def _model_at(loc: tuple, root: type[BaseModel] | None = None) -> type[BaseModel] | None:
    """The pydantic model class that the location ``loc`` points into (best effort)."""
    cur: Any = root or TrajectoryDeck
    for part in loc:
        cur = _strip(cur)
        origin = typing.get_origin(cur)
        if origin is list:
            cur = typing.get_args(cur)[0]
        elif origin is dict:
            cur = typing.get_args(cur)[1]
        elif isinstance(cur, type) and issubclass(cur, BaseModel) and part in cur.model_fields:
            cur = cur.model_fields[part].annotation
        else:
            return None
    cur = _strip(cur)
    return cur if isinstance(cur, type) and issubclass(cur, BaseModel) else None


def _num(x: Any) -> str:
    return f"{x:g}" if isinstance(x, (int, float)) else str(x)


def _expected(err: dict) -> str:
    typ, ctx = err["type"], err.get("ctx") or {}
    if typ == "missing":
        return "required"
    if typ == "greater_than":
        return f"must be > {_num(ctx['gt'])}"
    if typ == "greater_than_equal":
        return f"must be >= {_num(ctx['ge'])}"
    if typ == "less_than":
        return f"must be < {_num(ctx['lt'])}"
    if typ == "less_than_equal":
        return f"must be <= {_num(ctx['le'])}"
    if typ in ("too_short", "too_long"):
        lo, hi = ctx.get("min_length"), ctx.get("max_length")
        if lo is not None and lo == hi:
            return f"must have exactly {lo} entries"
        return err["msg"].replace("Input should have", "must have").replace("List should have", "must have")
    if typ in ("float_type", "float_parsing"):
        return "must be a number"
    if typ in ("int_type", "int_parsing", "int_from_float"):
        return "must be an integer"
    if typ == "bool_type":
        return "must be true or false"
    if typ == "string_type":
        return "must be a string"
    if typ == "list_type":
        return "must be a list"
    if typ in ("dict_type", "model_type", "model_attributes_type"):
        return "must be a table"
    if typ == "finite_number":
        return "must be a finite number"
    msg = err["msg"]
    for prefix in ("Value error, ", "Assertion failed, "):
        if msg.startswith(prefix):
            msg = msg[len(prefix) :]
    return msg.replace("Input should be", "must be")


def _data_at(data: Any, loc: tuple) -> Any:
    for part in loc:
        if isinstance(data, dict) and part in data:
            data = data[part]
        elif isinstance(data, list) and isinstance(part, int) and 0 <= part < len(data):
            data = data[part]
        else:
            return None
    return data


def _line(source: str, loc: tuple, value: Any, expected: str, missing: bool = False) -> str:
    field = _fmt_loc(loc)
    if value is None or missing:
        return f"{source}: {field}: {expected}"
    return f"{source}: {field} = {_fmt_value(value)}: {expected}"


def validation_problems(
    exc: ValidationError, source: str, root: type[BaseModel] | None = None, data: Any = None
) -> list[str]:
    """Every error of ``exc``, one line each (``source: field.path = value: expected``).

    Unknown keys come first (a typo usually also makes a required key "missing"); when a
    known key that the table does not give is close to the unknown one, the line says
    ``did you mean``.  ``data``: the TOML data validated (for the keys a table gives).
    """
    errs = sorted(exc.errors(), key=lambda e: e["type"] != "extra_forbidden")
    lines: list[str] = []
    for err in errs:
        loc = tuple(err["loc"])
        problem = (err.get("ctx") or {}).get("error")
        if isinstance(problem, FieldProblems):
            lines += [_line(source, loc + p.field, p.value, p.expected) for p in problem.problems]
            continue
        if isinstance(problem, FieldProblem):
            lines.append(_line(source, loc + problem.field, problem.value, problem.expected))
            continue
        value = err.get("input")
        expected = _expected(err)
        if err["type"] == "extra_forbidden":
            parent = _model_at(loc[:-1], root)
            known = list(parent.model_fields) if parent is not None else []
            given = _data_at(data, loc[:-1])
            free = [k for k in known if not (isinstance(given, dict) and k in given)]
            key = str(loc[-1]) if loc else ""
            close = difflib.get_close_matches(key.lower(), free, n=1, cutoff=0.6)
            if close:
                lines.append(f"{source}: {cut(_fmt_loc(loc), 80)}: unknown key; did you mean {close[0]}?")
                continue
            expected = "unknown field" + (f" (expected one of: {', '.join(known)})" if known else "")
        lines.append(_line(source, loc, value, expected, missing=err["type"] == "missing"))
    return lines


def first_and_count(problems: list[str]) -> str:
    """The first problem line, with " (and N more errors)" when there are more."""
    line = problems[0]
    if len(problems) > 1:
        n = len(problems) - 1
        line += f" (and {n} more error{'s' if n > 1 else ''})"
    return line


def format_validation_error(exc: ValidationError, source: str, root: type[BaseModel] | None = None) -> str:
    """One line for the first error of ``exc``: ``source: field.path = value: expected``."""
    return first_and_count(validation_problems(exc, source, root))


def deck_error(problems: list[str]) -> DeckError:
    """One DeckError carrying every problem line (``str`` is the first, counted)."""
    return DeckError(first_and_count(problems), problems=problems)


def _strip_bom(text: str) -> str:
    return text[1:] if text.startswith("\ufeff") else text


_HEADER_RE = re.compile(r"^\s*\[\[?\s*([^\]=]+?)\s*\]\]?\s*(#.*)?$")
_KEY_RE = re.compile(r"^\s*([^=\[\]{}#]+?)\s*=")


def _too_deep_line(text: str, source: str) -> str:
    """The line naming the key whose value nests too deeply (after tomllib's RecursionError)."""
    table, key, depth = "", "", 0
    for number, raw in enumerate(text.splitlines(), start=1):
        if depth == 0:
            m = _HEADER_RE.match(raw)
            if m:
                table = m.group(1).strip()
                continue
            m = _KEY_RE.match(raw)
            if m:
                key = m.group(1).strip().strip("\"'")
        for ch in raw:
            if ch in "[{":
                depth += 1
                if depth > MAX_NESTING:
                    field = f"{table}.{key}" if table else key
                    return (
                        f"{source}: {cut(field or f'line {number}', 80)} = {cut(raw.split('=', 1)[-1].strip())}: "
                        f"arrays / inline tables nested more than {MAX_NESTING} deep (line {number})"
                    )
            elif ch in "]}":
                depth = max(depth - 1, 0)
            elif ch == "#":
                break
    return f"{source}: arrays / inline tables nested more than {MAX_NESTING} deep"


def _scan(data: Any, loc: tuple, out: list[tuple[tuple, Any, str]], depth: int = 0) -> None:
    """Problems no schema can see: integers beyond 64 bits, nesting beyond MAX_NESTING."""
    if isinstance(data, bool):
        return
    if isinstance(data, int):
        if not (_INT_MIN <= data <= _INT_MAX):
            digits = len(str(abs(data)))
            out.append((loc, _Given(cut(str(data))), f"an integer of {digits} digits (TOML integers are 64-bit)"))
        return
    if isinstance(data, (list, dict)):
        if depth > MAX_NESTING:
            while len(loc) > 1 and isinstance(loc[-1], int) and isinstance(loc[-2], int):
                loc = loc[:-1]  # name the key (and its first index), not the whole way down
            out.append(
                (loc, _Given("[…]" if isinstance(data, list) else "{…}"), f"nested more than {MAX_NESTING} deep")
            )
            return
        items = data.items() if isinstance(data, dict) else enumerate(data)
        for k, v in items:
            _scan(v, loc + (k,), out, depth + 1)


def load_toml(text: str, source: str) -> dict:
    """TOML text (a leading BOM dropped) -> data; syntax errors, nesting beyond
    :data:`MAX_NESTING` and integers beyond 64 bits are one-line DeckErrors."""
    text = _strip_bom(text)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise DeckError(f"{source}: TOML syntax error: {exc}") from None
    except RecursionError:
        raise DeckError(_too_deep_line(text, source)) from None
    found: list[tuple[tuple, Any, str]] = []
    _scan(data, (), found)
    if found:
        raise deck_error([_line(source, loc, value, expected) for loc, value, expected in found])
    return data


def _named_mode(data: dict) -> str | None:
    """The mode the data evidently is, for a deck of the wrong kind (None: no evidence)."""
    mode = data.get("mode")
    if mode is not None:
        return mode if isinstance(mode, str) else None
    if "ertraj" in data:
        return "team"
    if any(k in data for k in ("epoch", "initial_state", "spacecraft", "stop")):
        return "propagate"
    return None


_KIND_NAMES = {
    "propagate": ("a trajectory deck", "fracas propagate"),
    "team": ("a TEAM deck", "fracas run"),
    "sweep": ("a sweep deck", "fracas sweep"),
    "tom": ("a TOM deck", "fracas run"),
    "tsim": ("a TSIM deck", "fracas run"),
    "rendezvous": ("a rendezvous deck", "fracas run"),
}


def _wrong_kind(data: dict, source: str, cls: type[SourcedDeck]) -> None:
    want = cls.model_fields["mode"].default
    got = _named_mode(data)
    if got is None or got == want or got not in _KIND_NAMES:
        return
    how = (
        f'mode = "{got}"'
        if "mode" in data
        else ("it has an [ertraj] table" if got == "team" else "it has no [ertraj] table")
    )
    what, command = _KIND_NAMES[got]
    raise DeckError(f"{source}: this is {what} ({how}), not {_KIND_NAMES[want][0]}: run it with {command}")


def parse_sourced(text: str, source: str, cls: type[SourcedDeck]) -> SourcedDeck:
    """Validate TOML text as a ``cls`` deck; any problem -> DeckError('source: field = value: expected').

    The DeckError's ``problems`` lists every problem found, one line each."""
    text = _strip_bom(text)
    data = load_toml(text, source)
    _wrong_kind(data, source, cls)
    try:
        deck = cls.model_validate(data, context={"source": source})
    except ValidationError as exc:
        raise deck_error(validation_problems(exc, source, cls, data)) from None
    except RecursionError:  # defensive: load_toml bounds the nesting
        raise DeckError(f"{source}: nested too deeply to validate") from None
    deck._source_path = source
    deck._source_text = text
    return deck


def parse_deck(text: str, source: str = "<deck>") -> TrajectoryDeck:
    """Validate trajectory-deck TOML text; any problem -> one-line DeckError."""
    return parse_sourced(text, source, TrajectoryDeck)


def read_deck_text(path: str | Path) -> str:
    """The UTF-8 text of a deck file; every failure is a one-line DeckError."""
    p = Path(path)
    source = str(path)
    try:
        raw = p.read_bytes()
    except FileNotFoundError:
        raise DeckError(f"{source}: no such file") from None
    except IsADirectoryError:
        raise DeckError(f"{source}: is a directory, expected a TOML deck file") from None
    except OSError as exc:
        raise DeckError(f"{source}: cannot read: {exc.strerror or exc}") from None
    if len(raw) > MAX_DECK_BYTES:
        raise DeckError(f"{source}: is {len(raw)} bytes; a deck is at most {MAX_DECK_BYTES} bytes") from None
    if raw.startswith(b"\xef\xbb\xbf"):
        raw = raw[3:]
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise DeckError(f"{source}: not UTF-8 text (byte {exc.start})") from None


def load_deck(path: str | Path) -> TrajectoryDeck:
    """Read and validate a trajectory deck; every failure is a one-line DeckError."""
    return parse_deck(read_deck_text(path), str(path))


_HASH_PREFIX = "fracas-trajectory-deck/1\n"


def trajectory_hash(deck) -> str:
    """SHA-256 (hex) of the canonical form of a validated :class:`TrajectoryDeck`.

    The canonical form is the validated model as JSON (defaults filled in, floats in
    shortest round-trip form, keys sorted, no whitespace) behind a version prefix, so
    comments, layout, key order, ``7000`` vs ``7000.0``, a default written out or left
    implicit and the file's name or place do not change the hash; any changed value does
    (with ``[initial_state.oem]``, the state read from the OEM counts too).
    Every section counts (title and ``[output]`` included): the file is tied to exactly
    the deck it was built from (FRACAS writes ERTRAJ at the head of the STM tape).  The
    ``mode`` line and ``[limits]`` do not count (they say what to do with the trajectory and
    how big a run may get, not what the trajectory is).
    """
    dump = deck.model_dump(mode="json", exclude={"mode", "limits"})
    oem = deck.initial_state.oem
    if oem is not None:  # the state read from the OEM counts, not only the file's name
        dump["initial_state"]["oem"]["state"] = [*oem.r_km, *oem.v_km_s]
    else:  # a deck without [initial_state.oem] keeps the hash it had before the option existed
        dump["initial_state"].pop("oem", None)
    for arc in dump.get("thrust_arc", []):  # constant-pointing arcs keep the hash they had before the laws
        for key in ("alpha_legendre_deg", "beta_legendre_deg"):
            if not arc.get(key):
                arc.pop(key, None)
    body = json.dumps(
        dump,
        sort_keys=True,
        separators=(",", ":"),
        ensure_ascii=True,
        allow_nan=False,
    )
    return hashlib.sha256((_HASH_PREFIX + body).encode("utf-8")).hexdigest()
