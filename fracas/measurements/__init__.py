"""Measurement models and partials (FRACAS TRAKM, STAPRL, MENO): pure functions of arrays.

``stations``: station geocentric ICRF state and STAPRL partials; ``models``: value functions
and analytic partials of each data type; ``trakm``: the observation matrix H, values, R and
elevations for the TEAM engine (numpy at the boundary, jitted kernels inside).
"""

from fracas.measurements.models import KINDS, N_STATIONS
from fracas.measurements.stations import (
    DSN_STATIONS,
    Station,
    earth_rotation_angle,
    station_partials,
    station_state,
)
from fracas.measurements.trakm import (
    Geometry,
    Observation,
    ObservationBatch,
    check_measurement_label,
    is_measurement_label,
    measurement_label_unit,
    observation_matrix,
    observation_matrix_many,
)

__all__ = [
    "KINDS",
    "N_STATIONS",
    "DSN_STATIONS",
    "Station",
    "earth_rotation_angle",
    "station_partials",
    "station_state",
    "Geometry",
    "Observation",
    "ObservationBatch",
    "check_measurement_label",
    "is_measurement_label",
    "measurement_label_unit",
    "observation_matrix",
    "observation_matrix_many",
]
