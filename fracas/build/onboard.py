"""The onboard (Shuttle UNF) parts of a [[tracking]] entry in canonical units (application layer).

:func:`onboard_config` turns an entry's deck fields (deg, m, the body's defaults) into the
:class:`~fracas.measurements.trakm.OnboardSensor` and visibility cone of its observation;
:func:`count_start_times` lists the starts t_M - dt_c of the one-way Doppler counts, which the
schedule carries as event-free reference times (their state and transition enter the count's
H row, the exact STM form; docs/onboard_measurements.md).
"""

from __future__ import annotations

import math

import numpy as np

from fracas.constants import BODIES, pole_unit_vector
from fracas.measurements.trakm import OnboardSensor

__all__ = ["EARTH_FLATTENING", "onboard_config", "count_start_times"]

#: WGS-84 flattening of the Earth (the polar radius default of the onboard kinds)
EARTH_FLATTENING = 1.0 / 298.257223563
_ONBOARD = ("doppler_count_1way", "sensor_beta", "sensor_theta", "horizon_angle", "altitude")


# C901 on purpose: one default per onboard field, each a separate branch on what the deck gave
def onboard_config(t) -> tuple[OnboardSensor | None, tuple[float, float] | None]:  # noqa: C901
    """(sensor, visibility) of a validated [[tracking]] entry (None, None for a plain one).

    Defaults: radii from the body (equatorial = its radius; polar: WGS-84 flattening for the
    Earth, a sphere elsewhere), pole from its IAU pole (ICRF), identity sensor
    axes in the "inertial" frame, target = the body centre, altitude model spherical with
    the equatorial radius as reference."""
    vis = None
    if t.visibility is not None:
        vis = (math.radians(t.visibility.min_elevation_deg), float(t.visibility.max_range_km))
    if t.type not in _ONBOARD:
        return None, vis
    kw: dict = {}
    if t.count_interval_s is not None:
        kw["count_interval_s"] = float(t.count_interval_s)
    if t.body is not None and t.body in BODIES:
        a = t.equatorial_radius_km or BODIES[t.body].radius_km
        flat = EARTH_FLATTENING if t.body == "earth" else 0.0
        b = t.polar_radius_km or a * (1.0 - flat)
        kw.update(equatorial_radius_km=float(a), polar_radius_km=float(min(a, b)), pole=pole_unit_vector(t.body))
    if t.sensor_frame is not None:
        kw["sensor_frame"] = t.sensor_frame
    if t.sensor_axes is not None:
        kw["sensor_axes"] = tuple(tuple(float(x) for x in row) for row in t.sensor_axes)
    if t.target is not None:
        kw["target"] = t.target
    if t.target_point_km is not None:
        kw["target_point_km"] = tuple(float(x) for x in t.target_point_km)
    if t.target_station is not None:
        kw["target_station"] = t.target_station
    if t.horizon_azimuth_deg is not None:
        kw["horizon_azimuth_rad"] = math.radians(t.horizon_azimuth_deg)
    if t.boresight_depression_deg is not None:
        kw["boresight_depression_rad"] = math.radians(t.boresight_depression_deg)
    if t.horizon_altitude_km is not None:
        kw["horizon_altitude_km"] = float(t.horizon_altitude_km)
    if t.horizon_sigma_m is not None:
        kw["horizon_sigma_km"] = float(t.horizon_sigma_m) * 1e-3
    if t.altitude_model is not None:
        kw["altitude_model"] = t.altitude_model
    if t.reference_radius_km is not None:
        kw["reference_radius_km"] = float(t.reference_radius_km)
    return OnboardSensor(**kw), vis


def count_start_times(deck, track_times: list[np.ndarray]) -> np.ndarray:
    """The count starts t_M - dt_c (s) of every doppler_count_1way entry (track_times[j]: its
    observation times, s)."""
    out = [np.zeros(0)]
    for t, ts in zip(deck.tracking, track_times):
        if t.type == "doppler_count_1way":
            out.append(np.asarray(ts, dtype=np.float64) - float(t.count_interval_s))
    return np.concatenate(out)
