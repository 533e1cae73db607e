"""The measurement catalogue: data types (FRACAS TRAKM) and measurement-parameter labels (jax-free).

:data:`MEASUREMENT_KINDS` holds one :class:`MeasurementKind` per data type: the unit of its
value (km, km/s or rad), the unit a TEAM deck gives its sigma in and the factor from that
unit to the canonical one, how many stations take part, whether it needs a target body or
a star direction, and its unit bias partials.  :data:`MEASUREMENT_PARAMETERS` holds the
measurement (consider) parameters a study may carry, one :class:`MeasurementParam` per
label name:

    station_radius_km[NAME]   km     station geocentric radius   (via STAPRL)
    station_lat_rad[NAME]     rad    station geocentric latitude (via STAPRL)
    station_lon_rad[NAME]     rad    station east longitude      (via STAPRL)
    range_bias_km[NAME]       km     range bias of station NAME
    doppler_bias_km_s[NAME]   km/s   Doppler (range-rate) bias of station NAME
    azimuth_bias_rad[NAME]    rad    azimuth bias of station NAME
    elevation_bias_rad[NAME]  rad    elevation bias of station NAME
    qvlbi_timing_km           km     c dt   (+ in range3, - in diff_range; TRAKM eqs. 9, 11)
    qvlbi_frequency_km_s      km/s   c df/f (+ in doppler3, - in diff_doppler; eqs. 10, 12)
    star_planet_bias_rad      rad    star-planet angle bias
    diameter_bias_rad         rad    apparent-diameter bias
    doppler_count_bias_km[NAME]  km  one-way Doppler count bias of beacon NAME, as range change
                                     (an oscillator offset df over dt_c: c df dt_c / f_D)
    sensor_beta_bias_rad      rad    sensor_beta bias (UNF c = 2)
    sensor_theta_bias_rad     rad    sensor_theta bias (UNF c = 3)
    sensor_misalignment_{x,y,z}_rad  rad  small rotation of the sensor axes about i_xm, i_ym, i_zm
    horizon_angle_bias_rad    rad    horizon-sensor angle bias
    horizon_altitude_bias_km  km     horizon altitude gamma_H (UNF's horizon bias state)
    altitude_bias_km          km     altimeter bias (UNF c = 4)

The onboard kinds (Shuttle UNF; :mod:`fracas.measurements.onboard`) carry ``onboard = True``;
their partials w.r.t. the labels in ``geometry_partials`` come from the geometry
(misalignment g x r_rho, horizon altitude (g . N) dn/dgamma), not a unit coefficient.

The config layer (:mod:`fracas.config.team`), the models (:mod:`fracas.measurements.models`)
and the observation matrices (:mod:`fracas.measurements.trakm`) all read these tables.
This module imports no JAX.
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from dataclasses import dataclass

__all__ = [
    "MeasurementKind",
    "MeasurementParam",
    "MEASUREMENT_KINDS",
    "MEASUREMENT_PARAMETERS",
    "KINDS",
    "ONBOARD_KINDS",
    "N_STATIONS",
    "KIND_UNITS",
    "SIGMA_UNITS",
    "STATION_LABELS",
    "GLOBAL_LABELS",
    "is_measurement_label",
    "measurement_label_unit",
    "check_measurement_label",
]

_DEG = 0.017453292519943295  # rad per degree


@dataclass(frozen=True)
class MeasurementKind:
    """One measurement data type.

    ``name``: the deck's / program's name; ``unit``: canonical unit of the value and of the
    white-noise sigma (km, km/s, rad); ``sigma_unit``, ``sigma_factor``: the unit of a TEAM
    deck's ``sigma`` and the factor to ``unit``; ``n_stations``: participating stations (0:
    spacecraft-based); ``needs_body``: a target body (its position, for planet_diameter its
    radius); ``needs_star``: a star direction; ``bias_terms``: unit bias partials
    ((label name, station slot or None, coefficient), TRAKM eq. 8); ``trakm_name``: the
    FRACAS TRAKM data type and its equations.  ``max_sigma``: the largest white-noise
    sigma a deck may give, in ``sigma_unit`` (a generous physical bound: 10,000 km for a
    range, 1 km/s for a Doppler, 180 deg for an angle, pi rad for an optical angle; a larger
    sigma means no information, and is almost surely a unit mistake).
    """

    name: str
    unit: str
    sigma_unit: str
    sigma_factor: float
    n_stations: int
    description: str
    trakm_name: str
    bias_terms: tuple[tuple[str, int | None, float], ...] = ()
    needs_body: bool = False
    needs_star: bool = False
    max_sigma: float | None = None
    onboard: bool = False
    geometry_partials: tuple[str, ...] = ()


@dataclass(frozen=True)
class MeasurementParam:
    """One measurement-parameter label name: ``unit`` (canonical); ``per_station``: the
    label is ``name[STATION]`` (else plain ``name``); ``sigma``: a typical a-priori 1-sigma
    (as in the example decks; informational, never applied), None where none makes sense;
    ``max_sigma``: the largest a-priori sigma a deck may give (``unit``; the same generous
    bounds as the measurement kinds': 10,000 km, 1 km/s, pi rad; 1,000 km for a station radius)."""

    name: str
    unit: str
    per_station: bool
    description: str
    sigma: float | None = None
    max_sigma: float | None = None


_KINDS = (
    MeasurementKind(
        "range2",
        "km",
        "m",
        1e-3,
        1,
        "2-way range rho",
        "2-way range (TRAKM eqs. 1-2)",
        (("range_bias_km", 0, 1.0),),
        max_sigma=1e7,
    ),
    MeasurementKind(
        "doppler2",
        "km/s",
        "mm/s",
        1e-6,
        1,
        "2-way Doppler as range rate rho_dot",
        "2-way Doppler (TRAKM eqs. 3-7)",
        (("doppler_bias_km_s", 0, 1.0),),
        max_sigma=1e6,
    ),
    MeasurementKind(
        "range3",
        "km",
        "m",
        1e-3,
        2,
        "3-way range rho_1 + rho_2",
        "QVLBI 3-way range (TRAKM eq. 9)",
        (("range_bias_km", 0, 1.0), ("range_bias_km", 1, 1.0), ("qvlbi_timing_km", None, 1.0)),
        max_sigma=1e7,
    ),
    MeasurementKind(
        "doppler3",
        "km/s",
        "mm/s",
        1e-6,
        2,
        "3-way Doppler rho_dot_1 + rho_dot_2",
        "QVLBI 3-way Doppler (TRAKM eq. 10)",
        (("doppler_bias_km_s", 0, 1.0), ("doppler_bias_km_s", 1, 1.0), ("qvlbi_frequency_km_s", None, 1.0)),
        max_sigma=1e6,
    ),
    MeasurementKind(
        "diff_range",
        "km",
        "m",
        1e-3,
        2,
        "differenced range rho_1 - rho_2",
        "differenced range (TRAKM eqs. 11, 13-16)",
        (("range_bias_km", 0, 1.0), ("range_bias_km", 1, -1.0), ("qvlbi_timing_km", None, -1.0)),
        max_sigma=1e7,
    ),
    MeasurementKind(
        "diff_doppler",
        "km/s",
        "mm/s",
        1e-6,
        2,
        "differenced Doppler rho_dot_1 - rho_dot_2",
        "differenced Doppler (TRAKM eqs. 12, 14-16)",
        (("doppler_bias_km_s", 0, 1.0), ("doppler_bias_km_s", 1, -1.0), ("qvlbi_frequency_km_s", None, -1.0)),
        max_sigma=1e6,
    ),
    MeasurementKind(
        "azimuth",
        "rad",
        "deg",
        _DEG,
        1,
        "topocentric azimuth of the spacecraft",
        "azimuth (TRAKM eqs. 21-30, rebuilt topocentric)",
        (("azimuth_bias_rad", 0, 1.0),),
        max_sigma=180.0,
    ),
    MeasurementKind(
        "elevation",
        "rad",
        "deg",
        _DEG,
        1,
        "topocentric elevation of the spacecraft",
        "elevation (TRAKM eqs. 17-20, rebuilt topocentric)",
        (("elevation_bias_rad", 0, 1.0),),
        max_sigma=180.0,
    ),
    MeasurementKind(
        "star_planet_angle",
        "rad",
        "urad",
        1e-6,
        0,
        "angle between a star and a body's centre",
        "star-planet angle (TRAKM eqs. 32-35)",
        (("star_planet_bias_rad", None, 1.0),),
        needs_body=True,
        needs_star=True,
        max_sigma=3.141592653589793e6,
    ),
    MeasurementKind(
        "planet_diameter",
        "rad",
        "urad",
        1e-6,
        0,
        "apparent diameter of a body",
        "apparent planet diameter (TRAKM eqs. 36-39)",
        (("diameter_bias_rad", None, 1.0),),
        needs_body=True,
        max_sigma=3.141592653589793e6,
    ),
    MeasurementKind(
        "doppler_count_1way",
        "km",
        "m",
        1e-3,
        1,
        "one-way integrated Doppler count as range change rho(t_M) - rho(t_M - dt_c)",
        "UNF c = 0.5 one-way Doppler count (exact STM form; CR-134276, digest A.3.4)",
        (("doppler_count_bias_km", 0, 1.0),),
        max_sigma=1e7,
        onboard=True,
    ),
    MeasurementKind(
        "sensor_beta",
        "rad",
        "mrad",
        1e-3,
        0,
        "sensor-frame angle beta = atan2(z, x) of the target",
        "UNF c = 2 unified angle beta (CR-134276, digest A.3.5)",
        (("sensor_beta_bias_rad", None, 1.0),),
        needs_body=True,
        max_sigma=3.141592653589793e3,
        onboard=True,
        geometry_partials=("sensor_misalignment_x_rad", "sensor_misalignment_y_rad", "sensor_misalignment_z_rad"),
    ),
    MeasurementKind(
        "sensor_theta",
        "rad",
        "mrad",
        1e-3,
        0,
        "sensor-frame angle theta = atan2(y, rho_a) of the target",
        "UNF c = 3 unified angle theta (CR-134276, digest A.3.5)",
        (("sensor_theta_bias_rad", None, 1.0),),
        needs_body=True,
        max_sigma=3.141592653589793e3,
        onboard=True,
        geometry_partials=("sensor_misalignment_x_rad", "sensor_misalignment_y_rad", "sensor_misalignment_z_rad"),
    ),
    MeasurementKind(
        "horizon_angle",
        "rad",
        "mrad",
        1e-3,
        0,
        "horizon-sensor angle psi between the oblate limb and the boresight",
        "UNF c = 3 horizon sensor psi with horizon-altitude bias (CR-134276, digest A.3.6, A.7.2)",
        (("horizon_angle_bias_rad", None, 1.0),),
        needs_body=True,
        max_sigma=3.141592653589793e3,
        onboard=True,
        geometry_partials=("horizon_altitude_bias_km",),
    ),
    MeasurementKind(
        "altitude",
        "km",
        "m",
        1e-3,
        0,
        "altitude above the body (spherical or geodetic)",
        "UNF c = 4 altitude (CR-134276, digest A.3.7)",
        (("altitude_bias_km", None, 1.0),),
        needs_body=True,
        max_sigma=1e7,
        onboard=True,
    ),
)
#: name -> :class:`MeasurementKind`, in the order decks and reports list them
MEASUREMENT_KINDS: dict[str, MeasurementKind] = {k.name: k for k in _KINDS}

_PARAMS = (
    MeasurementParam(
        "station_radius_km", "km", True, "station geocentric radius (via STAPRL)", 0.001, max_sigma=1000.0
    ),
    MeasurementParam(
        "station_lat_rad", "rad", True, "station geocentric latitude (via STAPRL)", max_sigma=3.141592653589793
    ),
    MeasurementParam(
        "station_lon_rad", "rad", True, "station east longitude (via STAPRL)", 9.6e-8, max_sigma=3.141592653589793
    ),
    MeasurementParam("range_bias_km", "km", True, "range bias of a station", 0.002, max_sigma=1e4),
    MeasurementParam("doppler_bias_km_s", "km/s", True, "Doppler (range-rate) bias of a station", max_sigma=1.0),
    MeasurementParam("azimuth_bias_rad", "rad", True, "azimuth bias of a station", max_sigma=3.141592653589793),
    MeasurementParam("elevation_bias_rad", "rad", True, "elevation bias of a station", max_sigma=3.141592653589793),
    MeasurementParam("qvlbi_timing_km", "km", False, "QVLBI c dt (+ in range3, - in diff_range)", 0.003, max_sigma=1e4),
    MeasurementParam(
        "qvlbi_frequency_km_s", "km/s", False, "QVLBI c df/f (+ in doppler3, - in diff_doppler)", 3.0e-8, max_sigma=1.0
    ),
    MeasurementParam("star_planet_bias_rad", "rad", False, "star-planet angle bias", max_sigma=3.141592653589793),
    MeasurementParam("diameter_bias_rad", "rad", False, "apparent-diameter bias", max_sigma=3.141592653589793),
    MeasurementParam(
        "doppler_count_bias_km",
        "km",
        True,
        "one-way Doppler count bias of a beacon (range change; c df dt_c / f_D for an oscillator offset df)",
        max_sigma=1e4,
    ),
    MeasurementParam("sensor_beta_bias_rad", "rad", False, "sensor_beta bias (UNF c = 2)", max_sigma=3.141592653589793),
    MeasurementParam(
        "sensor_theta_bias_rad", "rad", False, "sensor_theta bias (UNF c = 3)", max_sigma=3.141592653589793
    ),
    MeasurementParam(
        "sensor_misalignment_x_rad", "rad", False, "sensor-axes rotation about i_xm", max_sigma=3.141592653589793
    ),
    MeasurementParam(
        "sensor_misalignment_y_rad", "rad", False, "sensor-axes rotation about i_ym", max_sigma=3.141592653589793
    ),
    MeasurementParam(
        "sensor_misalignment_z_rad", "rad", False, "sensor-axes rotation about i_zm", max_sigma=3.141592653589793
    ),
    MeasurementParam("horizon_angle_bias_rad", "rad", False, "horizon-sensor angle bias", max_sigma=3.141592653589793),
    MeasurementParam(
        "horizon_altitude_bias_km", "km", False, "horizon altitude gamma_H (UNF horizon bias)", 0.5, max_sigma=1e3
    ),
    MeasurementParam("altitude_bias_km", "km", False, "altimeter bias (UNF c = 4)", max_sigma=1e4),
)
#: label name -> :class:`MeasurementParam`
MEASUREMENT_PARAMETERS: dict[str, MeasurementParam] = {p.name: p for p in _PARAMS}

# --- derived views (the names older modules export) -----------------------------------
KINDS = tuple(MEASUREMENT_KINDS)
#: the Shuttle UNF onboard kinds (fracas.measurements.onboard), in catalogue order
ONBOARD_KINDS = tuple(k.name for k in _KINDS if k.onboard)
N_STATIONS = {k.name: k.n_stations for k in _KINDS}
KIND_UNITS = {k.name: k.unit for k in _KINDS}
#: unit of ``sigma`` in a [[tracking]] entry, per type, and the factor to km, km/s or rad
SIGMA_UNITS = {k.name: (k.sigma_unit, k.sigma_factor) for k in _KINDS}
#: name -> unit, for labels indexed by a station name (name[STATION])
STATION_LABELS = {p.name: p.unit for p in _PARAMS if p.per_station}
#: name -> unit, for unindexed labels
GLOBAL_LABELS = {p.name: p.unit for p in _PARAMS if not p.per_station}

_LABEL = re.compile(r"^([a-z_0-9]+)(?:\[([^\]\[]+)\])?$")


def _valid_forms() -> str:
    forms = [f"{n}[<station>]" for n in STATION_LABELS] + list(GLOBAL_LABELS)
    return ", ".join(forms)


def _split(label: str) -> tuple[str, str | None] | None:
    m = _LABEL.match(label.strip()) if isinstance(label, str) else None
    if m is None:
        return None
    name, idx = m.group(1), m.group(2)
    if name in STATION_LABELS and idx is not None and idx.strip():
        return name, idx.strip()
    if name in GLOBAL_LABELS and idx is None:
        return name, None
    return None


def is_measurement_label(label: str) -> bool:
    """True if ``label`` has the form of a measurement-parameter label (any station name)."""
    return _split(label) is not None


def measurement_label_unit(label: str) -> str:
    """Unit of a measurement-parameter label ('km', 'km/s' or 'rad'); KeyError if unknown."""
    parts = _split(label)
    if parts is None:
        raise KeyError(f"{label!r} is not a measurement-parameter label; valid forms: {_valid_forms()}")
    name = parts[0]
    return STATION_LABELS.get(name) or GLOBAL_LABELS[name]


def check_measurement_label(label: str, station_names: Iterable[str]) -> None:
    """Raise KeyError, naming the valid forms and stations, unless ``label`` is a valid
    measurement-parameter label whose station (if any) is in ``station_names``."""
    names = sorted(station_names)
    parts = _split(label)
    if parts is None:
        raise KeyError(
            f"unknown measurement-parameter label {label!r}: expected one of {_valid_forms()}"
            f" (stations: {', '.join(names) or 'none'})"
        )
    if parts[1] is not None and parts[1] not in names:
        raise KeyError(
            f"measurement-parameter label {label!r}: station {parts[1]!r} is not one of "
            f"{', '.join(names) or 'none (no stations given)'}"
        )
