"""The inputs and outputs of TRAKM + MENO (:mod:`fracas.measurements.trakm`, which re-exports
every name here): the scheduled observation and its onboard sensor, the nominal geometry at a
measurement epoch, and the batch of predicted values, H rows and noise.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from fracas.measurements import models
from fracas.measurements.kinds import KIND_UNITS

# Label tables and label checks live in the jax-free catalogue (re-exported by the package).
_KIND_UNITS = KIND_UNITS


@dataclass(frozen=True)
class OnboardSensor:
    """The configuration of an onboard (Shuttle UNF) observation, canonical units.

    ``count_interval_s``: dt_c of doppler_count_1way (s).  ``sensor_frame``: "inertial" (the
    rows of ``sensor_axes`` are i_xm, i_ym, i_zm in ICRF) or "lvlh" (components on the
    reference's (forward, orbit normal, up) rows, :func:`onboard.lvlh_axes`); the frame is
    evaluated at the reference and held fixed (attitude known inertially).  ``target``:
    "body" (the observed body's centre), "point" (``target_point_km`` from the body centre,
    ICRF) or "station" (``target_station``, on the Earth).  Horizon sensor:
    ``horizon_azimuth_rad`` (UNF phi), ``boresight_depression_rad`` (None: the spherical
    horizon's depression arccos(a_F/r) at the reference, so psi ~ 0), ``horizon_altitude_km``
    (nominal gamma_H), ``horizon_sigma_km`` (alpha_H: horizon-threshold noise, added as
    (alpha_H d psi/d gamma_H)^2 ~ alpha_H^2/rho_H^2, UNF s_psi).  Body shape:
    ``equatorial_radius_km``/``polar_radius_km`` (0: the body's radius / the equatorial one),
    ``pole`` (unit, ICRF).  Altitude: ``altitude_model`` "spherical" (h = |r| - r_ref,
    ``reference_radius_km``, 0: the equatorial radius) or "geodetic".
    """

    count_interval_s: float = 0.0
    sensor_frame: str = "inertial"
    sensor_axes: tuple[tuple[float, float, float], ...] = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    target: str = "body"
    target_point_km: tuple[float, float, float] = (0.0, 0.0, 0.0)
    target_station: str = ""
    horizon_azimuth_rad: float = 0.0
    boresight_depression_rad: float | None = None
    horizon_altitude_km: float = 0.0
    horizon_sigma_km: float = 0.0
    equatorial_radius_km: float = 0.0
    polar_radius_km: float = 0.0
    pole: tuple[float, float, float] = (0.0, 0.0, 1.0)
    altitude_model: str = "spherical"
    reference_radius_km: float = 0.0


@dataclass(frozen=True)
class Observation:
    """One scheduled measurement: ``kind`` (one of :data:`models.KINDS`), the participating
    station names (1 for range2/doppler2/azimuth/elevation, 2 for range3/doppler3/
    diff_range/diff_doppler, 0 for star_planet_angle/planet_diameter; for differenced kinds
    value = station 1 - station 2) and the white-noise sigma in the kind's unit (km, km/s
    or rad).  Onboard kinds (:data:`models.ONBOARD_KINDS`) take their ``sensor``
    configuration (doppler_count_1way: 1 station, the beacon; the others none).
    ``visibility``: (min elevation rad, max range km) of a station kind's beacon cone
    (:mod:`fracas.measurements.visibility`, applied by :mod:`fracas.team.measure`)."""

    kind: str
    stations: tuple[str, ...]
    sigma: float
    sensor: OnboardSensor | None = None
    visibility: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        if self.kind not in models.KINDS:
            raise ValueError(f"measurement kind {self.kind!r} unknown: expected one of {', '.join(models.KINDS)}")
        if isinstance(self.stations, str):
            raise ValueError(f"{self.kind}: stations must be a tuple of names, got the string {self.stations!r}")
        object.__setattr__(self, "stations", tuple(self.stations))
        need = models.N_STATIONS[self.kind]
        if len(self.stations) != need:
            raise ValueError(f"{self.kind} needs {need} station(s), got {len(self.stations)}: {self.stations}")
        if len(set(self.stations)) != len(self.stations):
            raise ValueError(f"{self.kind}: the two stations must differ, got {self.stations}")
        if not (math.isfinite(self.sigma) and self.sigma > 0.0):
            raise ValueError(
                f"{self.kind}: sigma must be positive and finite ({_KIND_UNITS[self.kind]}), got {self.sigma!r}"
            )
        if self.kind in models.ONBOARD_KINDS and self.sensor is None:
            object.__setattr__(self, "sensor", OnboardSensor())
        if self.kind == "doppler_count_1way" and not self.sensor.count_interval_s > 0.0:
            raise ValueError(
                f"doppler_count_1way: sensor.count_interval_s must be > 0, got {self.sensor.count_interval_s}"
            )


@dataclass
class Geometry:
    """Nominal geometry at one measurement epoch.

    ``et_s``: TDB s past J2000.  ``sc_r, sc_v`` (km, km/s): spacecraft relative to an origin
    O; ``earth_r, earth_v``: Earth centre relative to the same O (ICRF).  ``body_r, body_v``:
    target-body centre relative to O (needed by the spacecraft-based kinds), with radius
    ``body_radius_km`` (planet_diameter) and ``star_unit`` (star_planet_angle).
    ``body_r_partials``: label -> d body_r / d param (3,), supplied by the caller for
    ephemeris parameters and chained into H (TRAKM eqs. 35, 39).

    One-way Doppler count (start of the count interval t0 = t_M - dt_c): ``et0_s``,
    ``sc_r0``, ``earth_r0`` (as above, at t0), ``phi_0m`` (7, 7) Phi(t0, t_M) of the reference
    and ``dx0_dp``: label -> d x(t0)/d param at fixed x(t_M) (7,) (= -Phi(t0, t_M)
    Theta(t_M, t0) column) for the dynamic parameters.  The H row is the exact STM form
    dq/dx(t_M) = h(t_M) + h(t0) Phi(t0, t_M) (digest A.3.4).
    """

    et_s: float
    sc_r: np.ndarray
    sc_v: np.ndarray
    earth_r: np.ndarray
    earth_v: np.ndarray
    body_r: np.ndarray | None = None
    body_v: np.ndarray | None = None
    body_radius_km: float | None = None
    star_unit: np.ndarray | None = None
    body_r_partials: dict = field(default_factory=dict)
    et0_s: float | None = None
    sc_r0: np.ndarray | None = None
    earth_r0: np.ndarray | None = None
    phi_0m: np.ndarray | None = None
    dx0_dp: dict = field(default_factory=dict)


@dataclass
class ObservationBatch:
    """TRAKM + MENO output for m observations: ``values`` (m,) bias-free predicted values
    (km, km/s, rad), ``H`` (m, nx + n_labels), ``sigma`` (m,) white-noise 1σ with
    ``R`` (m, m) = diag(sigma^2), and ``elevation_deg`` (m,) the lowest elevation of the
    participating stations (nan for spacecraft-based kinds; negative = below the horizon,
    for the caller to report or skip).  ``extra_variance`` (m,): geometry-dependent noise
    already in ``sigma`` (the horizon sensor's alpha_H^2 (d psi/d gamma_H)^2), for a caller
    that substitutes its own white-noise sigma (true noise); zeros elsewhere."""

    values: np.ndarray
    H: np.ndarray
    sigma: np.ndarray
    elevation_deg: np.ndarray
    extra_variance: np.ndarray | None = None

    @property
    def R(self) -> np.ndarray:
        """MENO: the diagonal measurement-noise covariance (m, m)."""
        return np.diag(self.sigma * self.sigma)


def _vec3(name: str, x: object) -> np.ndarray:
    a = np.asarray(x, dtype=np.float64)
    if a.shape != (3,):
        raise ValueError(f"Geometry.{name}: expected shape (3,), got {a.shape}")
    return a
