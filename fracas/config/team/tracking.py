"""The TEAM deck's ``[[tracking]]`` (ground and onboard measurement schedules: FRACAS
$ERANAL; Shuttle UNF onboard kinds, docs/onboard_measurements.md) and ``[[event]]`` entries.
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field, model_validator

from fracas.config.fields import LIGHT_KM_S, MAX_POSITION_SIGMA_KM
from fracas.config.team.bounds import NonNeg, StationName, _kind_sigma
from fracas.config.team.sections import Visibility
from fracas.config.trajectory import FieldProblem, PositiveFloat, Vector3, _Section, raise_problems
from fracas.config.trajectory.values import AngleDeg, PositionKm, at_most
from fracas.measurements.kinds import KINDS as MEASUREMENT_TYPES
from fracas.measurements.kinds import MEASUREMENT_KINDS, N_STATIONS

#: a reset's sigmas: the a-priori's bounds (fracas.config.fields)
PositionSigma = Annotated[float, Field(gt=0), at_most(MAX_POSITION_SIGMA_KM, "km", "no knowledge at all")]
VelocitySigma = Annotated[float, Field(gt=0), at_most(LIGHT_KM_S, "km/s", "the speed of light", strict=True)]

# The onboard (Shuttle UNF) fields of a [[tracking]] entry and the kinds that take them.
_ONBOARD_FIELDS = {
    "count_interval_s": ("doppler_count_1way",),
    "sensor_frame": ("sensor_beta", "sensor_theta"),
    "sensor_axes": ("sensor_beta", "sensor_theta"),
    "target": ("sensor_beta", "sensor_theta"),
    "target_point_km": ("sensor_beta", "sensor_theta"),
    "target_station": ("sensor_beta", "sensor_theta"),
    "horizon_azimuth_deg": ("horizon_angle",),
    "boresight_depression_deg": ("horizon_angle",),
    "horizon_altitude_km": ("horizon_angle",),
    "horizon_sigma_m": ("horizon_angle",),
    "equatorial_radius_km": ("horizon_angle", "altitude"),
    "polar_radius_km": ("horizon_angle", "altitude"),
    "altitude_model": ("altitude",),
    "reference_radius_km": ("altitude",),
}


class Tracking(_Section):
    type: Literal[MEASUREMENT_TYPES]  # type: ignore[valid-type]
    stations: list[StationName] = []
    start_days: NonNeg
    stop_days: NonNeg
    interval_hours: PositiveFloat
    sigma: PositiveFloat
    body: str | None = None
    star_ra_deg: AngleDeg | None = None
    star_dec_deg: float | None = None
    # onboard kinds (Shuttle UNF; fracas.measurements.onboard, docs/onboard_measurements.md)
    count_interval_s: PositiveFloat | None = None
    sensor_frame: Literal["inertial", "lvlh"] | None = None
    sensor_axes: list[Vector3] | None = None
    target: Literal["body", "point", "station"] | None = None
    target_point_km: PositionKm | None = None
    target_station: StationName | None = None
    horizon_azimuth_deg: Annotated[float, Field(ge=-360, le=360)] | None = None
    boresight_depression_deg: Annotated[float, Field(ge=-90, le=90)] | None = None
    horizon_altitude_km: Annotated[float, Field(ge=0, le=1000)] | None = None
    horizon_sigma_m: NonNeg | None = None
    equatorial_radius_km: PositiveFloat | None = None
    polar_radius_km: PositiveFloat | None = None
    altitude_model: Literal["spherical", "geodetic"] | None = None
    reference_radius_km: PositiveFloat | None = None
    visibility: Visibility | None = None

    # C901 on purpose: a flat list of independent onboard-field checks
    def _check_onboard(self) -> None:  # noqa: C901
        """The onboard fields: only with the kinds that take them, required ones present,
        sensor axes orthonormal and right-handed, radii ordered."""
        for name, kinds in _ONBOARD_FIELDS.items():
            value = getattr(self, name)
            if value is not None and self.type not in kinds:
                raise FieldProblem(name, value, f'only for type {" / ".join(kinds)}, not "{self.type}"')
        if self.visibility is not None and N_STATIONS[self.type] == 0:
            raise FieldProblem("visibility", None, f'only for station kinds, not "{self.type}"')
        if self.type == "doppler_count_1way" and self.count_interval_s is None:
            raise FieldProblem("count_interval_s", None, 'required for type "doppler_count_1way" (s)')
        if self.count_interval_s is not None and self.count_interval_s > 86400.0:
            raise FieldProblem("count_interval_s", self.count_interval_s, "must be <= 86400 s")
        if self.sensor_axes is not None:
            a = self.sensor_axes
            if len(a) != 3:
                raise FieldProblem("sensor_axes", a, "must be 3 rows (i_xm, i_ym, i_zm)")
            dots = [[sum(a[i][k] * a[j][k] for k in range(3)) for j in range(3)] for i in range(3)]
            if any(abs(dots[i][j] - (1.0 if i == j else 0.0)) > 1e-9 for i in range(3) for j in range(3)):
                raise FieldProblem("sensor_axes", a, "rows must be orthonormal (to 1e-9)")
            cx = [a[0][1] * a[1][2] - a[0][2] * a[1][1], a[0][2] * a[1][0] - a[0][0] * a[1][2]]
            cx.append(a[0][0] * a[1][1] - a[0][1] * a[1][0])
            if sum(c * z for c, z in zip(cx, a[2])) < 0.0:
                raise FieldProblem("sensor_axes", a, "must be right-handed (i_xm x i_ym = i_zm)")
        target = self.target or "body"
        if target == "point" and self.target_point_km is None:
            raise FieldProblem("target_point_km", None, 'required with target = "point" (km from the body centre)')
        if target != "point" and self.target_point_km is not None:
            raise FieldProblem("target_point_km", self.target_point_km, 'only with target = "point"')
        if target == "station" and self.target_station is None:
            raise FieldProblem("target_station", None, 'required with target = "station"')
        if target == "station" and self.body != "earth":
            raise FieldProblem("body", self.body, 'must be "earth" with target = "station"')
        if target != "station" and self.target_station is not None:
            raise FieldProblem("target_station", self.target_station, 'only with target = "station"')
        if (
            self.equatorial_radius_km is not None
            and self.polar_radius_km is not None
            and self.polar_radius_km > self.equatorial_radius_km
        ):
            raise FieldProblem("polar_radius_km", self.polar_radius_km, "must be <= equatorial_radius_km")

    @model_validator(mode="after")
    def _consistent(self) -> Tracking:
        self._check_onboard()
        need = N_STATIONS[self.type]
        if len(self.stations) != need:
            raise FieldProblem(
                "stations", self.stations, f'type "{self.type}" needs {need} station{"s" if need != 1 else ""}'
            )
        if need == 2 and self.stations[0] == self.stations[1]:
            raise FieldProblem("stations", self.stations, "the two stations must differ")
        if self.stop_days < self.start_days:
            raise FieldProblem("stop_days", self.stop_days, "must be >= start_days")
        kind = MEASUREMENT_KINDS[self.type]
        if kind.needs_body and not self.body:
            raise FieldProblem("body", None, f'required for type "{self.type}" (the observed body)')
        if kind.needs_star and (self.star_ra_deg is None or self.star_dec_deg is None):
            raise FieldProblem("star_ra_deg", None, "star_ra_deg and star_dec_deg are required for star_planet_angle")
        raise_problems([p for p in [_kind_sigma(self.type, self.sigma, "sigma")] if p])
        return self


class Event(_Section):
    """An [[event]]: eigenvector, propagation, prediction (predict_to_days) or reset
    (position_sigma_km, velocity_sigma_km_s: the assumed-covariance reset, UNF/Apollo W
    reinitialization; generalized covariance only)."""

    type: Literal["eigenvector", "propagation", "prediction", "reset"]
    times_days: list[NonNeg] = []
    start_days: NonNeg | None = None
    stop_days: NonNeg | None = None
    interval_days: PositiveFloat | None = None
    predict_to_days: PositiveFloat | None = None
    position_sigma_km: Annotated[list[PositionSigma], Field(min_length=3, max_length=3)] | None = None
    velocity_sigma_km_s: Annotated[list[VelocitySigma], Field(min_length=3, max_length=3)] | None = None

    @model_validator(mode="after")
    def _consistent(self) -> Event:
        rng = (self.start_days, self.stop_days, self.interval_days)
        if not self.times_days and any(v is None for v in rng):
            raise FieldProblem((), None, "give times_days, or start_days + stop_days + interval_days")
        given = self.position_sigma_km is not None or self.velocity_sigma_km_s is not None
        if self.type == "reset" and (self.position_sigma_km is None or self.velocity_sigma_km_s is None):
            raise FieldProblem("position_sigma_km", self.position_sigma_km, "position_sigma_km and velocity_sigma_km_s")
        if self.type != "reset" and given:
            raise FieldProblem("position_sigma_km", self.position_sigma_km, "only for reset events")
        if self.type == "prediction" and self.predict_to_days is None:
            raise FieldProblem("predict_to_days", None, "required for a prediction event")
        if self.type != "prediction" and self.predict_to_days is not None:
            raise FieldProblem("predict_to_days", self.predict_to_days, "only for prediction events")
        return self

    def times(self) -> list[float]:
        """The event's times (days, sorted, unique); a validated deck bounds how many
        ([limits] max_events)."""
        out = list(self.times_days)
        if self.start_days is not None and self.stop_days is not None and self.interval_days:
            n = int((self.stop_days - self.start_days) / self.interval_days + 1e-9)
            out += [self.start_days + k * self.interval_days for k in range(n + 1)]
        return sorted(set(out))
