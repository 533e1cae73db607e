"""The TEAM deck's tables other than tracking, events and guidance: ``[errcon]``, ``[ertraj]``,
``[stm]``, ``[filter]``, ``[a_priori]`` (and ``[control]``), ``[[parameter]]``,
``[thrust_noise]``, ``[process_noise]``, ``[[station]]``, ``[budget]``, ``[print]``,
``[punch]``, ``[gencov]``, ``[output]`` (FRACAS $ERRCON, $ERTRAJ, $ERANAL, $GENCOV, sec. 3.2).

The thrust-noise and a-priori bounds come from :mod:`fracas.config.fields`.
"""

from __future__ import annotations

import re
from typing import Annotated, Literal

from pydantic import BeforeValidator, Field, field_validator, model_validator

from fracas.config.fields import (
    A_PRIORI_FIELDS,
    LIGHT_KM_S,
    MAX_MASS_KG,
    MAX_POSITION_SIGMA_KM,
    THRUST_NOISE_COMPONENTS,
)
from fracas.config.team.bounds import NonNeg, _check_sigma, _kind_sigma
from fracas.config.team.guidance import GUIDANCE_MODELS
from fracas.config.trajectory import (
    FieldProblem,
    ParamLabel,
    PositiveFloat,
    Vector3,
    _Section,
    canonical_name,
    raise_problems,
)
from fracas.config.trajectory.values import at_most
from fracas.measurements.kinds import KINDS as MEASUREMENT_TYPES
from fracas.params import DECK_ROLES


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


#: (field, upper bound, its unit's words) of the per-axis a-priori sigmas (fracas.config.fields)
_VECTOR_BOUNDS = tuple(
    (f.name, f.lt, f.bound_unit) for f in A_PRIORI_FIELDS if f.name in ("position_sigma_km", "velocity_sigma_km_s")
)


class APriori(_Section):
    """A-priori knowledge of the spacecraft state (1σ, ICRF axes), or ``shaped`` (UNF)."""

    position_sigma_km: Vector3 | None = None
    position_rss_km: Annotated[float, Field(gt=0, le=MAX_POSITION_SIGMA_KM)] | None = None
    velocity_sigma_km_s: Vector3 | None = None
    velocity_rss_km_s: Annotated[float, Field(gt=0, lt=LIGHT_KM_S)] | None = None
    mass_sigma_kg: Annotated[NonNeg, at_most(MAX_MASS_KG, "kg", "a million tonnes")] = 0.0
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
        for a, hi, why in _VECTOR_BOUNDS:
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
        for name, hi, why in ((f.name, f.le, f.bound_unit) for f in THRUST_NOISE_COMPONENTS):
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
