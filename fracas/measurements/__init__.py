"""Measurement models and partials (FRACAS TRAKM, STAPRL, MENO): pure functions of arrays.

``kinds``: the jax-free catalogue of data types and measurement-parameter labels;
``stations``: station geocentric ICRF state and STAPRL partials; ``models``: value functions
and analytic partials of each data type; ``trakm``: the observation matrix H, values, R and
elevations for the TEAM engine (numpy at the boundary, jitted kernels inside).

Importing this package (or :mod:`fracas.measurements.kinds`) does not import JAX: the
catalogue names below are loaded eagerly, the JAX ones on first access.
"""

import importlib
from typing import Any

from fracas.measurements.kinds import (
    KINDS,
    N_STATIONS,
    check_measurement_label,
    is_measurement_label,
    measurement_label_unit,
)

# name -> submodule that defines it (imported on first access; they import JAX)
_LAZY = {
    "DSN_STATIONS": "stations",
    "Station": "stations",
    "earth_rotation_angle": "stations",
    "station_partials": "stations",
    "station_state": "stations",
    "Geometry": "trakm",
    "Observation": "trakm",
    "ObservationBatch": "trakm",
    "observation_matrix": "trakm",
    "observation_matrix_many": "trakm",
}
_SUBMODULES = ("kinds", "models", "stations", "trakm")

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


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        value = getattr(importlib.import_module(f"{__name__}.{_LAZY[name]}"), name)
        globals()[name] = value
        return value
    if name in _SUBMODULES:
        return importlib.import_module(f"{__name__}.{name}")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__) | set(_SUBMODULES))
