"""Ground-beacon visibility cones and passes (Shuttle UNF beacon prediction; digest
``unf-apollo.md`` A.7.4), a schedule helper: numpy only, no JAX.

A beacon (or station) at r_B (geocentric, km) sees the vehicle at r_P when the vehicle lies in
the cone about the beacon's local vertical and within the sensor's range::

    unit(r_B) . (r_P - r_B) >= sin(delta) |r_P - r_B|      and      |r_P - r_B| <= max range

(delta: the elevation mask, UNF s_deltaR = sin delta_beta; the UNF sensor's maximum range is
1500 n.mi. = 2778 km).  ``unit(r_B)`` is the geocentric vertical (spherical Earth), as in the
UNF.  TEAM applies it per [[tracking]] entry (``visibility = {min_elevation_deg,
max_range_km}``, :mod:`fracas.team.measure`): an observation outside the cone is skipped
and counted, like one below ``min_elevation_deg``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    import numpy.typing as npt

__all__ = ["UNF_MAX_RANGE_KM", "beacon_visible", "visibility_passes", "beacon_passes"]

#: the UNF beacon sensor's maximum range, 1500 n.mi. (km)
UNF_MAX_RANGE_KM = 1500.0 * 1.852


def beacon_visible(
    r_p: npt.ArrayLike, r_b: npt.ArrayLike, min_elevation_rad: float, max_range_km: float = np.inf
) -> np.ndarray:
    """Whether the vehicle(s) ``r_p`` (..., 3) km are in the visibility cone of the beacon(s)
    ``r_b`` (..., 3) km (both geocentric, broadcast): elevation above ``min_elevation_rad``
    and range at most ``max_range_km``.  Returns a bool array of the broadcast shape."""
    r_p = np.asarray(r_p, dtype=np.float64)
    r_b = np.asarray(r_b, dtype=np.float64)
    d = r_p - r_b
    rng = np.linalg.norm(d, axis=-1)
    up = r_b / np.linalg.norm(r_b, axis=-1, keepdims=True)
    return (np.sum(up * d, axis=-1) >= np.sin(min_elevation_rad) * rng) & (rng <= max_range_km)


def visibility_passes(times_s: npt.ArrayLike, visible: npt.ArrayLike) -> list[tuple[float, float]]:
    """The passes of a visibility mask sampled at ``times_s``: [(first, last visible time)]
    for each run of consecutive True samples (s)."""
    t = np.asarray(times_s, dtype=np.float64)
    v = np.asarray(visible, dtype=bool)
    if v.size == 0:
        return []
    edges = np.diff(np.concatenate([[0], v.astype(np.int8), [0]]))
    starts = np.flatnonzero(edges == 1)
    stops = np.flatnonzero(edges == -1) - 1
    return [(float(t[a]), float(t[b])) for a, b in zip(starts, stops)]


def beacon_passes(
    times_s: npt.ArrayLike,
    r_p: npt.ArrayLike,
    r_b: npt.ArrayLike,
    min_elevation_rad: float,
    max_range_km: float = UNF_MAX_RANGE_KM,
) -> list[tuple[float, float]]:
    """The passes [(first, last visible time)] of a beacon over a sampled reference: vehicle
    ``r_p`` (K, 3) and beacon ``r_b`` (K, 3) or (3,) geocentric km at ``times_s`` (K,) (the
    UNF's beacon prediction steps the conic in 1-min steps; here the caller's samples)."""
    return visibility_passes(times_s, beacon_visible(r_p, r_b, min_elevation_rad, max_range_km))
