"""The TEAM deck: one linear covariance study (FRACAS $ERRCON, $ERTRAJ, $ERANAL, $GENCOV, sec. 3.2).

Validated into frozen pydantic models in the units an analyst writes (days, hours, m,
mm/s, deg, µrad); :mod:`fracas.team.setup` converts to km, s, rad.  No JAX here.
Layout (only ``[ertraj]`` is required)::

    title = "Mercury approach"
    [errcon]       build_stm = false | true | "if_missing", analysis = true,  ($ERRCON)
                   propagation = "phi" | "pdot",  stm_file = "stm_files/x.h5"
                   process_noise = "grid" | "interval",  noise_step_hours = 1.0,
                   guidance_model = "report" | "orthogonal" | "tsim"  (the estimated-deviation
                   covariance that sizes corrections: P_c, P_c − P_k, P_c + P_k),
                   guidance_reset = "state" | "all"  (blocks of GUIDM's reset),
                   guidance_estimates = "state" | "state_and_solve_for"
                   (PHI mode's thrust-noise model: DYNO on fixed cells, default, or
                   FRACAS's DYNO per schedule interval; fracas.team.transitions)
    [ertraj]       deck = "trajectory.toml"   (relative to this file)      ($ERTRAJ)
                   pdot_step_hours = 2.4      (PDOT integration step)
    [stm]          parameters = [...]  (extra labels the STM file should carry for later
                   studies), grid_hours (extra uniform grid of file times)
    [filter]       type = "kalman_schmidt" | "wls" | "user", user_gain = "module:function",
                   square_root = false, min_elevation_deg = 0, start_days = 0, stop_days
    [a_priori]     position_sigma_km = [3] | position_rss_km, velocity_sigma_km_s = [3] |
                   velocity_rss_km_s, mass_sigma_kg = 0, from_punch = "file.h5"
    [[parameter]]  label, sigma (in the label's unit), role = "solve_for" | "consider" | "ignore"
    [thrust_noise] proportionality = {sigma, tau_days}, in_plane_deg = {sigma, tau_days},
                   out_of_plane_deg = {sigma, tau_days}     (Gauss-Markov, App. 9.3)
    [process_noise] white_acceleration_km2_s3 = 0, direction = "full" | "crosstrack" |
                   "radial" | "along", quadrature_step_hours   (white, UNF s_q)
    [a_priori.shaped] sigma_r_km, sigma_v_km_s, sigma_energy_km2_s2, sigma_h_km2_s,
                   lv_crosstrack_sigma_r_km, lv_crosstrack_sigma_v_km_s  (UNF pseudo-measurements)
    [[station]]    name, radius_km, latitude_deg, longitude_deg  (override/add; <= 9 in all)
    [[tracking]]   type, stations = [..], start_days, stop_days, interval_hours, sigma
                   (range types: m; Doppler types: mm/s; azimuth/elevation: deg;
                    star_planet_angle, planet_diameter: µrad), body, star_ra_deg, star_dec_deg,
                   visibility = {min_elevation_deg, max_range_km} (station kinds); onboard
                   kinds (docs/onboard_measurements.md): doppler_count_1way (m) count_interval_s;
                   sensor_beta/theta (mrad) sensor_frame, sensor_axes, target, target_point_km,
                   target_station; horizon_angle (mrad) horizon_azimuth_deg,
                   boresight_depression_deg, horizon_altitude_km, horizon_sigma_m; horizon_angle
                   and altitude (m) equatorial_radius_km, polar_radius_km; altitude
                   altitude_model, reference_radius_km
    [[event]]      type = "eigenvector" | "propagation" | "prediction" | "reset",
                   times_days = [..] | start_days + stop_days + interval_days,
                   predict_to_days (prediction); position_sigma_km, velocity_sigma_km_s
                   (reset: the ASSUMED covariance's state block restarts from these sigmas
                   with its correlations zeroed, the UNF/Apollo W reinitialization; the true
                   covariance continues; needs [gencov]; PHI propagation, Kalman-Schmidt)
    [print]        every = 1 (print every n-th measurement event), correlations = true,
                   process_noise = true
    [punch]        times_days = [..], file = "out/knowledge.h5"
    [gencov]       enabled = true, a_priori = {...}, [[gencov.parameter]] (true sigma of a study
                   parameter, or a new role = "ignore" one), thrust_noise = {...}, process_noise = {...},
                   measurement_sigma = {type = sigma}                         ($GENCOV)
    [control]      the initial control covariance (actual − reference: injection dispersions),
                   as [a_priori]; default the true a-priori
    [[guidance]]   name, type = "impulsive" | "primary" | "vernier" | "none", time_days,
                   targets = ["b_dot_t", ...], target_time_days, target_body, arc,
                   controls = ["proportionality", "alpha", "beta", "t_on", "t_off"],
                   weights, tolerances, execution = {proportionality, pointing_mrad,
                   resolution_m_s}                              (GUIDM, XGUID; §3.2)
    [budget]       enabled = true, at_days = [..]   (error budget by source)
    [output]       results = "out/x_team.h5", plot = "out/x_team.png"
    [limits]       max_measurements, max_events, ... (fracas.config.limits.Limits)

Station names and parameter labels are case-insensitive and stored as the catalogues spell
them (lower case).  Sigmas are bounded where a physical range exists: a [[tracking]] or
gencov sigma by its kind's ``max_sigma`` (fracas.measurements.kinds), a parameter sigma by
its catalogue entry's (fracas.params, fracas.measurements.kinds), thrust-noise
proportionality at most 1 (100 %) and pointing at most 180 deg, a-priori velocity below
the speed of light.  The implied sizes (observations per [[tracking]] entry and in all,
event times) are checked against ``[limits]`` here; those that need the trajectory's
duration by :func:`fracas.config.limits.check_team_sizes`.

Consider parameters are split by the catalogue: labels the dynamics depend on are dynamic
consider (u), measurement labels (station locations, biases) are measurement consider (v).
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Annotated, Literal

from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, field_validator, model_validator

from fracas.config.limits import Limits, count_text, event_count, tracking_count
from fracas.config.trajectory import (
    FieldProblem,
    ParamLabel,
    PositiveFloat,
    SourcedDeck,
    Vector3,
    canonical_name,
    load_toml,
    parse_sourced,
    raise_problems,
    read_deck_text,
)
from fracas.constants import BODIES
from fracas.errors import DeckError
from fracas.measurements.kinds import KINDS as MEASUREMENT_TYPES  # the data types, one catalogue
from fracas.measurements.kinds import MEASUREMENT_KINDS, MEASUREMENT_PARAMETERS, N_STATIONS, SIGMA_UNITS
from fracas.params import DECK_ROLES, INDEX_BODY, INDEX_BODY_ELEMENT, PARAMETER_KINDS

__all__ = ["TeamDeck", "load_team_deck", "parse_team_deck", "is_team_text", "MEASUREMENT_TYPES", "SIGMA_UNITS"]

# MEASUREMENT_TYPES, SIGMA_UNITS (unit of ``sigma`` in a [[tracking]] entry, per type, and
# the factor to km, km/s or rad) and N_STATIONS come from fracas.measurements.kinds.
MAX_STATIONS = 9
NonNeg = Annotated[float, Field(ge=0)]
#: a station name, case-insensitive (stored in lower case)
StationName = Annotated[str, BeforeValidator(canonical_name)]
#: the speed of light (km/s): no velocity uncertainty can exceed it
LIGHT_KM_S = 299_792.458
#: the largest a-priori position sigma (km): 1e12 km (~6,700 AU) is no knowledge at all
MAX_POSITION_SIGMA_KM = 1e12
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


def _check_sigma(label: str, sigma: float, field) -> FieldProblem | None:
    bound = sigma_bound(label)
    if bound is not None and sigma > bound[0]:
        return FieldProblem(field, sigma, f"must be <= {bound[0]:g} {bound[1]} for {label}")
    return None


def _kind_sigma(kind: str, sigma: float, field) -> FieldProblem | None:
    mk = MEASUREMENT_KINDS.get(kind)
    if mk is not None and mk.max_sigma is not None and sigma > mk.max_sigma:
        return FieldProblem(field, sigma, f'must be <= {mk.max_sigma:g} {mk.sigma_unit} for type "{kind}"')
    return None


class _Section(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid", strict=True, allow_inf_nan=False)


class ErrCon(_Section):
    """$ERRCON: what this run does."""

    build_stm: bool | Literal["if_missing"] = False
    analysis: bool = True
    propagation: Literal["phi", "pdot"] = "phi"
    stm_file: str | None = None
    # PHI mode's Gauss-Markov thrust-noise model: "exact" (default; fracas.team.gm_exact)
    # carries the three noise states through the filter with their exact transition and
    # noise (within 1e-3 of the augmented covariance equation; docs/process_noise.md).
    # FRACAS DYNO's effective Q̃ (fracas.team.transitions) stays available: "grid" computes
    # it on fixed noise cells (a grid anchored at the epoch, cut at the thrust switches;
    # event times leave it unchanged), "interval" over each schedule interval (FRACAS's
    # own: every event time changes it).  DYNO is off by factors on short correlation
    # times (0.5x to 2.8x by component on the issue-24 case).
    process_noise: Literal["exact", "grid", "interval"] = "exact"
    guidance_model: Literal[GUIDANCE_MODELS] = "report"  # type: ignore[valid-type]
    # which blocks GUIDM's reset of the control covariance to the knowledge touches (report
    # model): "state" (default, digest P-B2) the state and state-parameter blocks, keeping
    # the parameters' own dispersion (estimating a bias does not change it); "all" also
    # the parameter block (the literal reading, which shrinks the actual dispersion)
    guidance_reset: Literal["state", "all"] = "state"
    # what the guidance law corrects (digest (G-4)): "state" (default, GUIDM: the estimated
    # state only) or "state_and_solve_for" (also the estimated solve-for parameters, e.g. a
    # thrust bias, whose effect on the target the correction then cancels; the post-maneuver
    # control covariance is then the exact (G-7) form with the model's C_xe)
    guidance_estimates: Literal["state", "state_and_solve_for"] = "state"
    noise_step_hours: PositiveFloat = 1.0


class ErTraj(_Section):
    """$ERTRAJ: the reference trajectory deck (the core's TOML) and PDOT's integration step."""

    deck: str
    # PDOT's largest RK4 step.  RK4 converges at 4th order: on tests/data/team_small.toml the
    # max relative sigma error against a 0.15 h step is 1.7e-5 (4.8 h), 1.0e-6 (2.4 h, the
    # default: better than 1e-5), 6.1e-8 (1.2 h) (tests/team/test_noise_invariance.py).
    # The step taken is this capped by the dynamics (0.015 / sqrt(mu / r^3) on an orbit,
    # 0.07 tau for Gauss-Markov noise: fracas.team.pdot_step; about 14 s in LEO).
    pdot_step_hours: PositiveFloat = 2.4


class StmSection(_Section):
    parameters: list[ParamLabel] = []
    grid_hours: PositiveFloat | None = None


class FilterSection(_Section):
    type: Literal["kalman_schmidt", "wls", "user"] = "kalman_schmidt"
    user_gain: str | None = None
    square_root: bool = False
    min_elevation_deg: Annotated[float, Field(ge=-90, le=90)] = 0.0
    start_days: NonNeg = 0.0
    stop_days: PositiveFloat | None = None

    @model_validator(mode="after")
    def _user(self) -> FilterSection:
        if self.type == "user" and not self.user_gain:
            raise FieldProblem("user_gain", None, 'required for type = "user" (a "module:function" name)')
        if self.user_gain and not re.match(r"^[A-Za-z_][\w.]*:[A-Za-z_]\w*$", self.user_gain):
            raise FieldProblem("user_gain", self.user_gain, 'must be "module:function"')
        if self.stop_days is not None and self.stop_days <= self.start_days:
            raise FieldProblem("stop_days", self.stop_days, "must be after start_days")
        return self


class ShapedAPriori(_Section):
    """[a_priori.shaped]: the UNF correlated a-priori (digest unf-apollo.md A.6.1-A.6.3;
    fracas.filters.apriori): sigma_r_km, sigma_v_km_s on every axis (LV crosstrack sigmas
    optional), then W-only pseudo measurements of the energy v^2/2 - mu/r (sigma km^2/s^2) and
    of |r x v| (sigma km^2/s) at the filter's start, relative to the primary body there."""

    sigma_r_km: Annotated[float, Field(gt=0, le=MAX_POSITION_SIGMA_KM)]
    sigma_v_km_s: Annotated[float, Field(gt=0, lt=LIGHT_KM_S)]
    sigma_energy_km2_s2: PositiveFloat | None = None
    sigma_h_km2_s: PositiveFloat | None = None
    lv_crosstrack_sigma_r_km: Annotated[float, Field(gt=0, le=MAX_POSITION_SIGMA_KM)] | None = None
    lv_crosstrack_sigma_v_km_s: Annotated[float, Field(gt=0, lt=LIGHT_KM_S)] | None = None


class APriori(_Section):
    """A-priori knowledge of the spacecraft state (1σ, ICRF axes), or ``shaped`` (UNF)."""

    position_sigma_km: Vector3 | None = None
    position_rss_km: Annotated[float, Field(gt=0, le=MAX_POSITION_SIGMA_KM)] | None = None
    velocity_sigma_km_s: Vector3 | None = None
    velocity_rss_km_s: Annotated[float, Field(gt=0, lt=LIGHT_KM_S)] | None = None
    mass_sigma_kg: NonNeg = 0.0
    from_punch: str | None = None
    shaped: ShapedAPriori | None = None

    @model_validator(mode="after")
    def _consistent(self) -> APriori:
        if self.shaped is not None:
            fields = ("position_sigma_km", "position_rss_km", "velocity_sigma_km_s", "velocity_rss_km_s", "from_punch")
            given = [a for a in fields if getattr(self, a) is not None]
            if given:
                raise FieldProblem(given[0], None, "not with [a_priori.shaped] (its sigma_r_km, sigma_v_km_s)")
        elif self.from_punch is None:
            for a, b in (("position_sigma_km", "position_rss_km"), ("velocity_sigma_km_s", "velocity_rss_km_s")):
                if (getattr(self, a) is None) == (getattr(self, b) is None):
                    raise FieldProblem((), None, f"give exactly one of {a}, {b} (or from_punch)")
        for a, hi, why in (
            ("position_sigma_km", MAX_POSITION_SIGMA_KM, ""),
            ("velocity_sigma_km_s", LIGHT_KM_S, " (the speed of light)"),
        ):
            v = getattr(self, a)
            if v is not None and min(v) < 0:
                raise FieldProblem(a, v, "sigmas must be >= 0")
            if v is not None and max(v) >= hi:
                raise FieldProblem(a, v, f"sigmas must be < {hi:g}{why}")
        return self

    def sigmas(self) -> tuple[list[float], list[float]]:
        """(position sigma km (3), velocity sigma km/s (3)); an RSS value is split equally; the
        diagonal before shaping for ``shaped``."""
        if self.shaped is not None:
            return [self.shaped.sigma_r_km] * 3, [self.shaped.sigma_v_km_s] * 3
        s3 = 3.0**0.5
        pos = self.position_sigma_km or [self.position_rss_km / s3] * 3
        vel = self.velocity_sigma_km_s or [self.velocity_rss_km_s / s3] * 3
        return list(pos), list(vel)


class Parameter(_Section):
    label: ParamLabel
    sigma: NonNeg
    role: Literal[DECK_ROLES]  # type: ignore[valid-type]

    @model_validator(mode="after")
    def _bounded(self) -> Parameter:
        raise_problems([p for p in [_check_sigma(self.label, self.sigma, "sigma")] if p])
        return self


class NoiseComponent(_Section):
    sigma: NonNeg
    tau_days: PositiveFloat


class ThrustNoise(_Section):
    """Gauss-Markov thrust errors: proportionality (fraction, <= 1), pointing (deg, <= 180); τ in days."""

    proportionality: NoiseComponent | None = None
    in_plane_deg: NoiseComponent | None = None
    out_of_plane_deg: NoiseComponent | None = None

    @model_validator(mode="after")
    def _bounded(self) -> ThrustNoise:
        problems = []
        for name, hi, why in (
            ("proportionality", 1.0, "(100 %)"),
            ("in_plane_deg", 180.0, "deg"),
            ("out_of_plane_deg", 180.0, "deg"),
        ):
            c = getattr(self, name)
            if c is not None and c.sigma > hi:
                problems.append(FieldProblem((name, "sigma"), c.sigma, f"must be <= {hi:g} {why}"))
        raise_problems(problems)
        return self


class WhiteNoise(_Section):
    """[process_noise]: white acceleration noise on the velocity (Shuttle UNF s_q, digest
    unf-apollo.md A.5.4; fracas.filters.process_noise): spectral density
    white_acceleration_km2_s3 (km^2/s^3), direction "full" (q I3, s_q = 1), "crosstrack"
    (q zeta zeta^T, s_q = 2), "radial" or "along"; quadrature_step_hours: the longest piece
    of its Gauss-Legendre quadrature (default errcon.noise_step_hours; a small fraction of an
    orbit period about a planet).  In [gencov] an omitted field keeps the filter's value."""

    white_acceleration_km2_s3: Annotated[float, Field(ge=0, le=1.0)] | None = None
    direction: Literal["full", "crosstrack", "radial", "along"] | None = None
    quadrature_step_hours: PositiveFloat | None = None


class StationDef(_Section):
    name: Annotated[str, BeforeValidator(canonical_name), Field(pattern=r"^[a-z][a-z0-9_]*$")]
    radius_km: Annotated[float, Field(gt=6000, lt=7000)]
    latitude_deg: Annotated[float, Field(ge=-90, le=90)]
    longitude_deg: Annotated[float, Field(ge=-360, le=360)]


class Visibility(_Section):
    """A station kind's beacon visibility cone (UNF; fracas.measurements.visibility)."""

    min_elevation_deg: Annotated[float, Field(ge=-90, le=90)] = 0.0
    max_range_km: PositiveFloat = 1e12


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
    star_ra_deg: float | None = None
    star_dec_deg: float | None = None
    # onboard kinds (Shuttle UNF; fracas.measurements.onboard, docs/onboard_measurements.md)
    count_interval_s: PositiveFloat | None = None
    sensor_frame: Literal["inertial", "lvlh"] | None = None
    sensor_axes: list[Vector3] | None = None
    target: Literal["body", "point", "station"] | None = None
    target_point_km: Vector3 | None = None
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

    def _check_onboard(self) -> None:
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
    position_sigma_km: Annotated[list[Annotated[float, Field(gt=0)]], Field(min_length=3, max_length=3)] | None = None
    velocity_sigma_km_s: Annotated[list[Annotated[float, Field(gt=0)]], Field(min_length=3, max_length=3)] | None = None

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


from fracas.guidance.target_kinds import LOW_THRUST_CONTROLS, TARGET_KINDS  # noqa: E402  (jax-free catalogue)

GUIDANCE_TYPES = ("impulsive", "primary", "vernier", "none")
GUIDANCE_MODELS = ("report", "orthogonal", "tsim")


class GuidanceExecution(_Section):
    """Execution errors of a guidance event (App. 9.1 high-thrust defaults, report L2722).

    Impulsive: proportionality (fraction of |ΔV|), two pointing angles of pointing_mrad each,
    resolution_m_s (isotropic); low thrust: proportionality is the fractional 1σ error of
    each control correction (a fracas choice: the report gives no low-thrust model)."""

    proportionality: Annotated[float, Field(ge=0, le=1)] = 0.01
    pointing_mrad: Annotated[float, Field(ge=0, le=1000)] = 7.0
    resolution_m_s: Annotated[float, Field(ge=0, le=1000)] = 0.01


class Guidance(_Section):
    """One [[guidance]] event (GUIDM §5.3.6, XGUID §5.3.25), computed statistically.

    type: "impulsive" (ΔV at time_days), "primary" (low-thrust correction of thrust arc
    ``arc`` from time_days to the arc's end, the cutoff), "vernier" (a later update of a
    primary on the same arc), "none" (target covariance only).  targets: names of
    :data:`fracas.guidance.target_kinds.TARGET_KINDS` at target_time_days (default: the
    reference trajectory's end) about target_body (default: the central body there).
    controls (low thrust): a subset of proportionality, alpha, beta, t_on, t_off.
    weights: one per control (impulsive: per ΔV component); tolerances: one per target.
    """

    name: Annotated[str, Field(pattern=r"^[A-Za-z][A-Za-z0-9_\-]*$", max_length=32)]
    type: Literal[GUIDANCE_TYPES]  # type: ignore[valid-type]
    time_days: NonNeg
    targets: list[str]
    target_time_days: PositiveFloat | None = None
    target_body: str | None = None
    arc: Annotated[int, Field(ge=0)] | None = None
    controls: list[str] = ["proportionality", "alpha", "beta"]
    weights: list[PositiveFloat] | None = None
    tolerances: list[PositiveFloat] | None = None
    execution: GuidanceExecution = GuidanceExecution()

    @model_validator(mode="after")
    def _consistent(self) -> Guidance:
        problems = []
        if not self.targets and self.type != "none":
            problems.append(FieldProblem("targets", [], "give at least one target"))
        for j, t in enumerate(self.targets):
            if t not in TARGET_KINDS:
                problems.append(
                    FieldProblem(("targets", j), t, f"unknown target (expected one of: {', '.join(TARGET_KINDS)})")
                )
        if len(set(self.targets)) != len(self.targets):
            problems.append(FieldProblem("targets", self.targets, "targets must not repeat"))
        low = self.type in ("primary", "vernier")
        if low:
            if self.arc is None:
                problems.append(
                    FieldProblem("arc", None, f'required for type "{self.type}" (the thrust arc it corrects)')
                )
            if not self.controls:
                problems.append(FieldProblem("controls", [], "give at least one control"))
            for j, c in enumerate(self.controls):
                if c not in LOW_THRUST_CONTROLS:
                    problems.append(
                        FieldProblem(
                            ("controls", j), c, f"unknown control (expected one of: {', '.join(LOW_THRUST_CONTROLS)})"
                        )
                    )
            if len(set(self.controls)) != len(self.controls):
                problems.append(FieldProblem("controls", self.controls, "controls must not repeat"))
            if self.type == "vernier" and "t_on" in self.controls:
                problems.append(FieldProblem("controls", self.controls, "a vernier cannot move the arc's start (t_on)"))
        elif self.arc is not None:
            problems.append(FieldProblem("arc", self.arc, "only for low-thrust guidance (primary, vernier)"))
        n_controls = len(self.controls) if low else 3
        if self.weights is not None and len(self.weights) != n_controls:
            problems.append(
                FieldProblem(
                    "weights",
                    self.weights,
                    f"expected {n_controls} values (one per {'control' if low else 'ΔV component'})",
                )
            )
        if self.tolerances is not None and len(self.tolerances) != len(self.targets):
            problems.append(
                FieldProblem("tolerances", self.tolerances, f"expected {len(self.targets)} values (one per target)")
            )
        raise_problems(problems)
        return self

    @property
    def n_controls(self) -> int:
        return len(self.controls) if self.type in ("primary", "vernier") else 3


class BudgetSection(_Section):
    """[budget]: the error budget (contribution of each error source, exact by linearity).

    enabled: compute it (one extra covariance pass per source); at_days: epochs (within the
    study) whose position and velocity σ are budgeted besides the final time."""

    enabled: bool = True
    at_days: list[NonNeg] = []


class PrintSection(_Section):
    every: Annotated[int, Field(ge=1)] = 1
    correlations: bool = True
    process_noise: bool = True


class Punch(_Section):
    times_days: list[NonNeg]
    file: str


class GenCovParameter(_Section):
    label: ParamLabel
    sigma: NonNeg
    role: Literal["ignore"] | None = None

    @model_validator(mode="after")
    def _bounded(self) -> GenCovParameter:
        raise_problems([p for p in [_check_sigma(self.label, self.sigma, "sigma")] if p])
        return self


class GenCov(_Section):
    """$GENCOV: only what the real world does differently from the filter's assumptions."""

    enabled: bool = True
    a_priori: APriori | None = None
    parameter: list[GenCovParameter] = []
    thrust_noise: ThrustNoise | None = None
    process_noise: WhiteNoise | None = None
    measurement_sigma: dict[str, PositiveFloat] = {}

    @field_validator("measurement_sigma")
    @classmethod
    def _types(cls, v: dict[str, float]) -> dict[str, float]:
        for k in v:
            if k not in MEASUREMENT_TYPES:
                raise ValueError(f'unknown measurement type "{k}" (expected one of: {", ".join(MEASUREMENT_TYPES)})')
        raise_problems([p for k, s in v.items() if (p := _kind_sigma(k, s, (k,)))])
        return v


class OutputSection(_Section):
    results: str | None = None
    plot: str | None = None


class TeamDeck(SourcedDeck):
    """A whole TEAM deck (frozen)."""

    mode: Literal["team"] = "team"
    title: str = ""
    errcon: ErrCon = ErrCon()
    ertraj: ErTraj
    stm: StmSection = StmSection()
    filter: FilterSection = FilterSection()
    a_priori: APriori | None = None
    parameter: list[Parameter] = []
    thrust_noise: ThrustNoise = ThrustNoise()
    process_noise: WhiteNoise = WhiteNoise()
    station: list[StationDef] = []
    tracking: list[Tracking] = []
    event: list[Event] = []
    print: PrintSection = PrintSection()
    punch: Punch | None = None
    gencov: GenCov | None = None
    control: APriori | None = None
    guidance: list[Guidance] = []
    budget: BudgetSection = BudgetSection()
    output: OutputSection = OutputSection()
    limits: Limits = Limits()

    @model_validator(mode="after")
    def _cross_checks(self) -> TeamDeck:
        if self.errcon.analysis and self.a_priori is None:
            raise FieldProblem("a_priori", None, "required when errcon.analysis = true")
        seen: dict[str, int] = {}
        for k, p in enumerate(self.parameter):
            if p.label in seen:
                raise FieldProblem(("parameter", k, "label"), p.label, f"repeats parameter[{seen[p.label]}]")
            seen[p.label] = k
        if self.gencov is not None:
            for k, g in enumerate(self.gencov.parameter):
                if g.label not in seen and g.role != "ignore":
                    raise FieldProblem(
                        ("gencov", "parameter", k, "label"),
                        g.label,
                        'is not a study parameter; add role = "ignore" to make it an ignore parameter',
                    )
                if g.label in seen and g.role == "ignore":
                    raise FieldProblem(
                        ("gencov", "parameter", k, "role"),
                        "ignore",
                        f"{g.label} is already a study parameter (parameter[{seen[g.label]}])",
                    )
        for k, e in enumerate(self.event):
            if e.type != "reset":
                continue
            if self.gencov is None or not self.gencov.enabled:
                raise FieldProblem(
                    ("event", k, "type"),
                    "reset",
                    "a [gencov] section (a reset changes only the filter's assumed covariance; "
                    "without generalized covariance nothing would report the true errors)",
                )
            if self.errcon.propagation != "phi" or self.filter.type != "kalman_schmidt":
                raise FieldProblem(
                    ("event", k, "type"),
                    "reset",
                    'errcon.propagation = "phi" and filter.type = "kalman_schmidt" (reset events)',
                )
        names = [s.name for s in self.station]
        if len(set(names)) != len(names):
            raise FieldProblem("station", names, "station names must be unique")
        builtin = {"goldstone", "madrid", "canberra"}
        if len(builtin | set(names)) > MAX_STATIONS:
            raise FieldProblem(
                "station", names, f"at most {MAX_STATIONS} stations in all (including the 3 DSN defaults)"
            )
        known = builtin | set(names)
        for k, t in enumerate(self.tracking):
            for j, s in enumerate(t.stations):
                if s not in known:
                    raise FieldProblem(
                        ("tracking", k, "stations", j),
                        s,
                        f"unknown station (expected one of: {', '.join(sorted(known))})",
                    )
            if t.target_station is not None and t.target_station not in known:
                raise FieldProblem(
                    ("tracking", k, "target_station"),
                    t.target_station,
                    f"unknown station (expected one of: {', '.join(sorted(known))})",
                )
        self._check_guidance()
        self._check_sizes()
        return self

    def _check_guidance(self) -> None:
        """Guidance events: unique names, times inside the study, one-per-time, PHI only,
        verniers after a primary on the same arc, a control a-priori only with guidance."""
        problems = []
        seen: dict[str, int] = {}
        times: dict[float, int] = {}
        primaries: dict[int, float] = {}
        if self.guidance and self.errcon.propagation == "pdot":
            problems.append(
                FieldProblem(
                    ("errcon", "propagation"),
                    "pdot",
                    'guidance events need propagation = "phi" in this release',
                )
            )
        stop = self.filter.stop_days
        for k, g in enumerate(self.guidance):
            if g.name in seen:
                problems.append(FieldProblem(("guidance", k, "name"), g.name, f"repeats guidance[{seen[g.name]}]"))
            seen[g.name] = k
            if g.time_days < self.filter.start_days or (stop is not None and g.time_days > stop):
                problems.append(
                    FieldProblem(
                        ("guidance", k, "time_days"),
                        g.time_days,
                        f"outside the study ({self.filter.start_days:g} to "
                        f"{'the trajectory end' if stop is None else f'{stop:g}'} d)",
                    )
                )
            if g.time_days in times:
                problems.append(
                    FieldProblem(
                        ("guidance", k, "time_days"), g.time_days, f"guidance[{times[g.time_days]}] is at the same time"
                    )
                )
            times[g.time_days] = k
            if g.type == "primary":
                primaries[int(g.arc)] = g.time_days
            if g.type == "vernier" and (g.arc not in primaries or primaries[g.arc] >= g.time_days):
                problems.append(
                    FieldProblem(
                        ("guidance", k, "type"),
                        "vernier",
                        f"needs an earlier primary on arc {g.arc} (list guidance events in time order)",
                    )
                )
            if g.target_time_days is not None and g.target_time_days < g.time_days:
                problems.append(
                    FieldProblem(("guidance", k, "target_time_days"), g.target_time_days, "before the guidance time")
                )
        order = [g.time_days for g in self.guidance]
        if order != sorted(order):
            problems.append(FieldProblem("guidance", order, "list guidance events in time order"))
        if self.control is not None and self.control.from_punch is None and not self.guidance:
            problems.append(FieldProblem("control", None, "a control a-priori needs [[guidance]] events"))
        raise_problems(problems)

    def _check_sizes(self) -> None:
        """The sizes the deck alone implies (observations, event times) against ``[limits]``."""
        lim = self.limits
        problems = []
        total = 0.0
        for k, t in enumerate(self.tracking):
            n = tracking_count(t)
            total += n
            if n > lim.max_measurements:
                problems.append(
                    FieldProblem(
                        ("tracking", k, "interval_hours"),
                        t.interval_hours,
                        f"gives {count_text(n)} observation times over {t.start_days:g}-{t.stop_days:g} d "
                        f"(limit {lim.max_measurements}, [limits] max_measurements); use a longer interval",
                    )
                )
        if not problems and total > lim.max_measurements:
            problems.append(
                FieldProblem(
                    ("tracking",),
                    None,
                    f"the {len(self.tracking)} entries give {count_text(total)} observation times in all "
                    f"(limit {lim.max_measurements}, [limits] max_measurements); use longer intervals",
                )
            )
        total = 0.0
        for k, e in enumerate(self.event):
            n = event_count(e)
            total += n
            if n > lim.max_events:
                problems.append(
                    FieldProblem(
                        ("event", k, "interval_days" if e.interval_days else "times_days"),
                        e.interval_days if e.interval_days else None,
                        f"gives {count_text(n)} event times (limit {lim.max_events}, [limits] max_events); "
                        "use a longer interval",
                    )
                )
        if not any(p.field[0] == "event" for p in problems) and total > lim.max_events:
            problems.append(
                FieldProblem(
                    ("event",),
                    None,
                    f"the {len(self.event)} entries give {count_text(total)} event times in all "
                    f"(limit {lim.max_events}, [limits] max_events)",
                )
            )
        raise_problems(problems)


def parse_team_deck(text: str, source: str = "<deck>") -> TeamDeck:
    """Validate TEAM-deck TOML text; any problem -> one-line DeckError."""
    return parse_sourced(text, source, TeamDeck)


def is_team_text(text: str) -> bool:
    """Whether TOML text is a TEAM deck (it has an [ertraj] table) rather than a trajectory deck."""
    try:
        return "ertraj" in load_toml(text, "<deck>")
    except DeckError:
        return False


def load_team_deck(path: str | Path) -> TeamDeck:
    """Read and validate a TEAM deck; every failure is a one-line DeckError."""
    return parse_team_deck(read_deck_text(path), str(path))
