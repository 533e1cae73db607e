"""Observation matrices for the TEAM engine (FRACAS TRAKM, section 5.3.22, and MENO, 5.3.9).

Boundary module: numpy in, numpy out; the arithmetic runs in one jitted JAX kernel per
measurement kind (compiled once per process, then reused), built from
:mod:`fracas.measurements.models` and :mod:`fracas.measurements.stations`.

TRAKM linearises y = h(x, s, u, v, w) about the nominal: dy = H_x dx + H_p dp.  Here H has
``nx`` spacecraft-state columns (r km, v km/s, then mass etc. with zero partials) followed by
one column per parameter label (TRAKM's single H_p "rearranged column by column" is the
caller's business).  The measurement-parameter labels (station locations, per-station
biases, QVLBI timing and frequency, star-planet and diameter biases) and their units are
listed in the catalogue, :mod:`fracas.measurements.kinds`.

Biases enter with unit partials (TRAKM eq. 8 and its closing remark): 2-way kinds use their
station's bias, 3-way kinds both stations' (+1 each), differenced kinds station 1 minus
station 2.  Any other label (a dynamic parameter) gets a zero column, except labels in
``Geometry.body_r_partials``: for the spacecraft-based kinds their column is
d h / d body_r . d body_r / d param (TRAKM eqs. 35, 39).  Predicted ``values`` are the
bias-free model values (nominal biases are zero).

R = diag(sigma^2) (MENO: the white-noise variance of each measurement's data type).

Modules (their public names re-exported here): :mod:`.records` (observations, sensors,
geometry, the output batch), :mod:`.classic` (the ground-station and optical kinds' kernels),
:mod:`.onboard_kinds` (the onboard kinds' kernels), :mod:`.bookkeeping` (label columns, batch
buckets); the entry points :func:`observation_matrix` and :func:`observation_matrix_many` are
here.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from fracas import _jax  # noqa: F401  (x64 first)
from fracas.measurements import models
from fracas.measurements.kinds import (
    GLOBAL_LABELS,
    STATION_LABELS,
    check_measurement_label,
    is_measurement_label,
    measurement_label_unit,
)
from fracas.measurements.stations import Station
from fracas.measurements.trakm.bookkeeping import _BIAS_TERMS, _STATION_PARAM_INDEX
from fracas.measurements.trakm.classic import _classic_many
from fracas.measurements.trakm.onboard_kinds import _onboard_many
from fracas.measurements.trakm.records import (
    _KIND_UNITS,
    Geometry,
    Observation,
    ObservationBatch,
    OnboardSensor,
)

__all__ = [
    "STATION_LABELS",
    "GLOBAL_LABELS",
    "Observation",
    "OnboardSensor",
    "Geometry",
    "ObservationBatch",
    "is_measurement_label",
    "measurement_label_unit",
    "check_measurement_label",
    "observation_matrix",
    "observation_matrix_many",
]

# private tables other modules and the catalogue tests read through this package
_TABLES = (_KIND_UNITS, _BIAS_TERMS, _STATION_PARAM_INDEX)


def observation_matrix(
    observations: Sequence[Observation],
    geometry: Geometry,
    stations: Mapping[str, Station],
    labels: Sequence[str],
    nx: int,
) -> ObservationBatch:
    """Values, observation matrix H, noise covariance R (MENO) and station elevations for
    the observations at one epoch (FRACAS TRAKM + MENO).

    H[:, :nx]: d h / d spacecraft state (r km, v km/s; columns 6..nx-1, e.g. mass, zero).
    H[:, nx + j]: d h / d labels[j] (module docstring).  Station-location columns chain the
    station (r, v) partials with STAPRL (:func:`stations.station_partials`; TRAKM eqs. 2, 6,
    31).  Raises ValueError / KeyError for malformed input (unknown station, bad label,
    missing body data); a station below the horizon is not an error (see elevation_deg).
    Cost: one jitted dispatch per kind present, plus O(m) bookkeeping.
    """
    return observation_matrix_many([(ob, geometry) for ob in observations], stations, labels, nx)


def observation_matrix_many(
    items: Sequence[tuple[Observation, Geometry]],
    stations: Mapping[str, Station],
    labels: Sequence[str],
    nx: int,
) -> ObservationBatch:
    """:func:`observation_matrix` for observations at many epochs at once: ``items`` pairs
    each observation with its own :class:`Geometry` (share one Geometry object between the
    observations of an epoch).  Rows come back in the order of ``items``; R is diag(sigma^2)
    over all of them.  One jitted dispatch per kind for the whole set, so a study's schedule
    can be evaluated in a handful of calls.  Onboard kinds go through their own kernels
    (:func:`_onboard_many`) and are merged back in order.
    """
    if nx < 6:
        raise ValueError(f"nx must be >= 6 (spacecraft r, v first), got {nx}")
    is_ob = [ob.kind in models.ONBOARD_KINDS for ob, _ in items]
    if not any(is_ob):
        return _classic_many(items, stations, labels, nx)
    i_on = [i for i, f in enumerate(is_ob) if f]
    i_cl = [i for i, f in enumerate(is_ob) if not f]
    parts = [(i_on, _onboard_many([items[i] for i in i_on], stations, labels, nx))]
    if i_cl:
        parts.append((i_cl, _classic_many([items[i] for i in i_cl], stations, labels, nx)))
    m = len(items)
    values, H = np.empty(m), np.empty((m, nx + len(labels)))
    sigma, elev, extra = np.empty(m), np.empty(m), np.zeros(m)
    for rows, b in parts:
        values[rows], H[rows], sigma[rows], elev[rows] = b.values, b.H, b.sigma, b.elevation_deg
        if b.extra_variance is not None:
            extra[rows] = b.extra_variance
    return ObservationBatch(values=values, H=H, sigma=sigma, elevation_deg=elev, extra_variance=extra)
