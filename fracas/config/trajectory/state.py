"""The trajectory deck's ``[epoch]`` and ``[initial_state]`` (cartesian, elements, spherical,
or a CCSDS OEM record), and the initial radius computed without the core.
"""

from __future__ import annotations

import functools
import math
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import Field, PlainValidator, PrivateAttr, field_validator, model_validator

from fracas.config.fields import MAX_DISTANCE_KM
from fracas.config.trajectory.problems import FieldProblem, _exactly_one, _Given
from fracas.config.trajectory.values import (
    AngleDeg,
    BodyName,
    DistanceKm,
    IsoEpoch,
    PositionKm,
    SpeedKmS,
    VelocityKmS,
    _iso_value,
    _Section,
    at_most,
)
from fracas.timescales import epoch_to_et, et_to_calendar


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
    r_km: PositionKm
    v_km_s: VelocityKmS

    @field_validator("r_km")
    @classmethod
    def _nonzero(cls, v: list[float]) -> list[float]:
        if math.hypot(*v) == 0.0:
            raise ValueError("must not be the zero vector")
        return v


class Elements(_Section):
    """Classical elements about the centre (a < 0 for hyperbolas, e >= 0, e != 1)."""

    a_km: Annotated[float, at_most(MAX_DISTANCE_KM, "km", "about 6,700 AU")]
    e: Annotated[float, Field(ge=0, le=1e6)]
    i_deg: Annotated[float, Field(ge=0, le=180)]
    raan_deg: AngleDeg = 0.0
    argp_deg: AngleDeg = 0.0
    mean_anomaly_deg: float | None = None  # a hyperbola's grows without bound (e sinh H - H)
    true_anomaly_deg: AngleDeg | None = None

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

    r_km: DistanceKm
    lat_deg: Annotated[float, Field(ge=-90, le=90)]
    lon_deg: AngleDeg
    v_km_s: SpeedKmS
    gamma_deg: Annotated[float, Field(ge=-90, le=90)]
    sigma_deg: AngleDeg


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
    from fracas.io.inputs import note_input

    note_input(p)  # an input of the run: no output may replace it
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
