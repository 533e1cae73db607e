"""Label bookkeeping shared by the TRAKM kernels (:mod:`fracas.measurements.trakm`): which
H column each measurement-parameter label fills, the unit bias partials per kind, and the
power-of-two batch buckets the jitted kernels are compiled for.
"""

from __future__ import annotations

import functools

from fracas.measurements.kinds import (
    GLOBAL_LABELS,
    MEASUREMENT_KINDS,
    STATION_LABELS,
    _split,
    check_measurement_label,
)

_STATION_PARAM_INDEX = {"station_radius_km": 0, "station_lat_rad": 1, "station_lon_rad": 2}
# Unit bias partials per kind: (label name, station slot or None, coefficient).
_BIAS_TERMS = {k.name: k.bias_terms for k in MEASUREMENT_KINDS.values()}

_MIN_BUCKET = 4


def _bucket(m: int) -> int:
    return max(_MIN_BUCKET, 1 << max(m - 1, 0).bit_length())


@functools.lru_cache(maxsize=64)
def _label_table(labels: tuple, station_names: tuple) -> dict:
    """(label name, station or None) -> column offsets; validates measurement labels."""
    table: dict = {}
    for j, label in enumerate(labels):
        parts = _split(label)
        if parts is None:
            base = label.split("[", 1)[0].strip() if isinstance(label, str) else ""
            if base in STATION_LABELS or base in GLOBAL_LABELS:  # e.g. 'range_bias_km' alone
                check_measurement_label(label, station_names)  # raises, naming the forms
            continue  # not a measurement parameter (dynamic, ephemeris, ...)
        check_measurement_label(label, station_names)
        table.setdefault(parts, []).append(j)
    return table
