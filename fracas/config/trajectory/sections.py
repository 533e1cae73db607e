"""The trajectory deck's other tables: ``[spacecraft]``, ``[propulsion]``, ``[[thrust_arc]]``,
``[[impulse]]``, ``[forces]``, ``[integrator]``, ``[stop]``, ``[output]`` (FRACAS TOM ``$DATA``).
"""

from __future__ import annotations

import math
from typing import Annotated, Literal

from pydantic import AfterValidator, Field, PlainValidator, field_validator, model_validator

from fracas.config.fields import (
    MAX_AREA_M2,
    MAX_IMPULSE_KM_S,
    MAX_MU_KM3_S2,
    MAX_POWER_KW,
    MAX_SPEED_KM_S,
    MAX_THRUST_SCALE,
    MIN_TOLERANCE,
)
from fracas.config.trajectory.problems import FieldProblem, _exactly_one
from fracas.config.trajectory.values import (
    AngleDeg,
    BodyName,
    Days,
    DistanceKm,
    EpochValue,
    IspS,
    MassKg,
    ParamLabel,
    PositiveFloat,
    _check_body_keys,
    _no_repeats,
    _Section,
    _vector3,
    at_most,
    norm_at_most,
)

#: an impulsive ΔV (km/s): at most MAX_IMPULSE_KM_S long
ImpulseKmS = Annotated[
    list[float], PlainValidator(_vector3), norm_at_most(MAX_IMPULSE_KM_S, "km/s", "no impulsive engine gives more")
]


def _tolerance(v: float) -> float:
    if v < MIN_TOLERANCE:
        raise ValueError(
            f"must be >= {MIN_TOLERANCE:g}: float64 rounds every operation at 2.2e-16 (its epsilon), so a step's "
            "error estimate is itself a few epsilon and a tighter tolerance can never be met"
        )
    return v


class Spacecraft(_Section):
    mass_kg: MassKg
    area_m2: Annotated[float, Field(ge=0), at_most(MAX_AREA_M2, "m^2", "100 km^2")] = 0.0
    cr: Annotated[float, Field(ge=0, le=2)] = 1.0


class Propulsion(_Section):
    """Electric propulsion: thrust T = 2 eta P / c, mass flow T / c (FRACAS EP)."""

    power_source: Literal["solar", "nuclear"] = "solar"
    power_kw: Annotated[float, Field(gt=0), at_most(MAX_POWER_KW, "kW", "1 GW")]
    decay_days: PositiveFloat | None = None
    efficiency: Annotated[float, Field(gt=0, le=1)]
    exhaust_velocity_km_s: (
        Annotated[float, Field(gt=0), at_most(MAX_SPEED_KM_S, "km/s", "the speed of light", strict=True)] | None
    ) = None
    isp_s: IspS | None = None
    thrust_scale: Annotated[float, Field(ge=0), at_most(MAX_THRUST_SCALE, "")] = 1.0

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

    start_days: Days
    stop_days: Days
    frame: Literal["velocity", "inertial", "velocity_yaw_switch"] = "velocity"
    alpha_deg: AngleDeg = 0.0
    beta_deg: Annotated[float, Field(ge=-90, le=90)] = 0.0
    throttle: Annotated[float, Field(ge=0, le=1)] = 1.0
    # pointing that varies within the arc: Legendre coefficients (P1, P2, P3) of alpha and beta in
    # the arc's normalised time s = (2t - start - stop)/(stop - start); alpha_deg/beta_deg stay the
    # arc's mean angles.  Up to three each; [] (the default) is constant pointing.
    # Each coefficient is at most MAX_ANGLE_DEG (|P_n| <= 1: the law stays within a few turns).
    alpha_legendre_deg: Annotated[list[AngleDeg], Field(max_length=3)] = []
    beta_legendre_deg: Annotated[list[AngleDeg], Field(max_length=3)] = []

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
    time_days: Days
    dv_km_s: ImpulseKmS
    frame: Literal["velocity", "inertial"] = "velocity"
    isp_s: IspS = 300.0


class BodyOverride(_Section):
    mu_km3_s2: Annotated[float, Field(gt=0), at_most(MAX_MU_KM3_S2, "km^3/s^2", "10 x the Sun's")] | None = None
    j2: Annotated[float, Field(ge=-1, le=1)] | None = None
    radius_km: DistanceKm | None = None


class ConicBody(_Section):
    """Heliocentric conic elements standing in for the body's ephemeris (FRACAS EPHEM)."""

    a_km: DistanceKm
    e: Annotated[float, Field(ge=0, lt=1)]
    i_deg: Annotated[float, Field(ge=0, le=180)]
    raan_deg: AngleDeg
    argp_deg: AngleDeg
    mean_anomaly_deg: AngleDeg
    epoch: EpochValue
    frame: Literal["EME2000", "ECLIPJ2000"] = "EME2000"


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
    tolerance: Annotated[float, Field(gt=0, le=1e-3), AfterValidator(_tolerance)] = 1e-12
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
    duration_days: Days | None = None  # < 0: backward propagation
    final_epoch: EpochValue | None = None
    condition: Literal["time", "soi_entry", "closest_approach", "radius"] = "time"
    body: BodyName | None = None
    radius_km: DistanceKm | None = None

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


def _span_text(dur: float) -> str:
    return f"0-{dur:g}" if dur >= 0.0 else f"{dur:g}-0"


def output_count(out: Output, duration_days: float) -> float:
    """How many output times ``[output]`` asks for (an upper bound, computed without building them)."""
    n = 2.0 + len(out.times_days)
    if out.step_days is not None and out.step_days != 0.0:
        q = abs(duration_days / out.step_days) * (1.0 + 1e-12)
        n += (math.floor(q) + 1.0) if q < 1e18 else q
    return n
