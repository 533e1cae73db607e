"""TRAKM's kernels for the ground-station and optical kinds (FRACAS TRAKM, section 5.3.22):
one jitted, vmapped JAX kernel per kind over packed input rows, then the label columns of H.

Part of :mod:`fracas.measurements.trakm` (module docstring there).
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Mapping, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from fracas import _jax  # noqa: F401  (x64 first)
from fracas.measurements import models
from fracas.measurements.stations import Station, station_partials, station_state
from fracas.measurements.trakm.bookkeeping import _BIAS_TERMS, _STATION_PARAM_INDEX, _bucket, _label_table
from fracas.measurements.trakm.records import Geometry, Observation, ObservationBatch, _vec3

# Packed input (one float64 vector, one host->device transfer per observation):
_I_ET, _I_SC, _I_E, _I_ST1, _I_ST2, _I_BODY, _I_RP, _I_STAR = 0, 1, 7, 13, 16, 19, 22, 23
_N_IN = 26
# Packed output: value, h_sc (6), h_st1 (R, phi, lam), h_st2 (3), h_body_r (3), elev1, elev2
_O_H, _O_ST1, _O_ST2, _O_BODY, _O_EL = 1, 7, 10, 13, 16
_N_OUT = 18


def _station(x: jax.Array, i0: int, et: jax.Array) -> tuple[jax.Array, jax.Array, jax.Array]:
    R, lat, lon = x[i0], x[i0 + 1], x[i0 + 2]
    r, v = station_state(R, lat, lon, et)
    return r, v, station_partials(R, lat, lon, et)


def _kernel(kind: str) -> Callable[[jax.Array], jax.Array]:
    """Packed kernel for one kind: (26,) -> (18,) (traced inside :func:`_batch_kernel`)."""
    value_fn = models.VALUE_FUNCTIONS[kind]
    partial_fn = models.PARTIAL_FUNCTIONS[kind]
    n_st = models.N_STATIONS[kind]

    def kernel(x: jax.Array) -> jax.Array:
        et = x[_I_ET]
        sc_r, sc_v = x[_I_SC : _I_SC + 3], x[_I_SC + 3 : _I_SC + 6]
        e_r, e_v = x[_I_E : _I_E + 3], x[_I_E + 3 : _I_E + 6]
        z3 = jnp.zeros(3, dtype=jnp.float64)
        nan2 = jnp.full(2, jnp.nan, dtype=jnp.float64)
        if n_st == 0:
            body_r, star = x[_I_BODY : _I_BODY + 3], x[_I_STAR : _I_STAR + 3]
            third = star if kind == "star_planet_angle" else x[_I_RP]
            val = value_fn(sc_r, body_r, third)
            h_sc, h_body = partial_fn(sc_r, body_r, third)[:2]
            return jnp.concatenate([val[None], h_sc, z3, z3, h_body, nan2])
        s1_r, s1_v, s1_p = _station(x, _I_ST1, et)
        el1 = models.elevation(sc_r, sc_v, e_r, e_v, s1_r, s1_v)
        if n_st == 1:
            args = (sc_r, sc_v, e_r, e_v, s1_r, s1_v)
            h_sc, h_s1 = partial_fn(*args)
            h_p1, h_p2, el2 = h_s1 @ s1_p, z3, jnp.full((), jnp.nan, dtype=jnp.float64)
        else:
            s2_r, s2_v, s2_p = _station(x, _I_ST2, et)
            el2 = models.elevation(sc_r, sc_v, e_r, e_v, s2_r, s2_v)
            args = (sc_r, sc_v, e_r, e_v, s1_r, s1_v, s2_r, s2_v)
            h_sc, h_s1, h_s2 = partial_fn(*args)
            h_p1, h_p2 = h_s1 @ s1_p, h_s2 @ s2_p
        val = value_fn(*args)
        return jnp.concatenate([val[None], h_sc, h_p1, h_p2, z3, jnp.stack([el1, el2])])

    return kernel


@functools.cache
def _batch_kernel(kind: str) -> Callable[[jax.Array], jax.Array]:
    """Jitted kernel for one kind, vmapped over observations: (b, 26) -> (b, 18).

    Built once per kind; the batch is padded to a power of two (at least
    :data:`_MIN_BUCKET`), so it compiles once per kind and size bucket (and not at all in a
    later process with the persistent compilation cache).  One dispatch per kind present
    in a call.  (A single all-kinds kernel with ``lax.switch`` was tried: vmapped, it
    evaluates every branch and cost ~0.5 ms a call against ~0.05 ms per kind here.)
    """
    return jax.jit(jax.vmap(_kernel(kind)))


_ONE = _N_OUT  # index of a constant 1.0 appended to each kernel output row


@functools.lru_cache(maxsize=4096)
def _columns(
    labels: tuple, station_names: tuple, kind: str, obs_stations: tuple
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Label-column scatter of one observation signature: arrays (src, col, coef) with
    H[nx + col] += coef * out_ext[src] (out_ext = kernel row with 1.0 appended)."""
    table = _label_table(labels, station_names)
    src, col, coef = [], [], []
    for slot, name in enumerate(obs_stations):  # station locations (STAPRL chain)
        o = _O_ST1 if slot == 0 else _O_ST2
        for lname, k in _STATION_PARAM_INDEX.items():
            for j in table.get((lname, name), ()):
                src.append(o + k), col.append(j), coef.append(1.0)
    for lname, slot, c in _BIAS_TERMS[kind]:  # unit bias partials (TRAKM eq. 8)
        for j in table.get((lname, None if slot is None else obs_stations[slot]), ()):
            src.append(_ONE), col.append(j), coef.append(c)
    return np.array(src, dtype=np.intp), np.array(col, dtype=np.intp), np.array(coef)


def _pack(geometry: Geometry) -> np.ndarray:
    """Packed kernel input row of one geometry (stations filled in per observation)."""
    base = np.zeros(_N_IN, dtype=np.float64)
    base[_I_ET] = float(geometry.et_s)
    base[_I_SC : _I_SC + 3] = _vec3("sc_r", geometry.sc_r)
    base[_I_SC + 3 : _I_SC + 6] = _vec3("sc_v", geometry.sc_v)
    base[_I_E : _I_E + 3] = _vec3("earth_r", geometry.earth_r)
    base[_I_E + 3 : _I_E + 6] = _vec3("earth_v", geometry.earth_v)
    if geometry.body_r is not None:
        base[_I_BODY : _I_BODY + 3] = _vec3("body_r", geometry.body_r)
    if geometry.body_radius_km is not None:
        base[_I_RP] = float(geometry.body_radius_km)
    if geometry.star_unit is not None:
        base[_I_STAR : _I_STAR + 3] = _vec3("star_unit", geometry.star_unit)
    return base


# C901 on purpose: one branch per FRACAS TRAKM measurement kind, kept side by side as in the report
def _classic_many(  # noqa: C901
    items: Sequence[tuple[Observation, Geometry]],
    stations: Mapping[str, Station],
    labels: Sequence[str],
    nx: int,
) -> ObservationBatch:
    """:func:`observation_matrix_many` for the TRAKM (non-onboard) kinds."""
    if nx < 6:
        raise ValueError(f"nx must be >= 6 (spacecraft r, v first), got {nx}")
    labels = tuple(labels)
    names = tuple(sorted(stations))
    _label_table(labels, names)  # validates the measurement labels once per label set
    m = len(items)
    n = nx + len(labels)

    packed: dict[int, np.ndarray] = {}
    x = np.empty((m, _N_IN))
    sig_rows: dict[tuple[str, tuple[str, ...]], list[int]] = {}  # rows by observation signature
    for i, (ob, geometry) in enumerate(items):
        base = packed.get(id(geometry))
        if base is None:
            base = packed[id(geometry)] = _pack(geometry)
        x[i] = base
        sig_rows.setdefault((ob.kind, ob.stations), []).append(i)
    groups: dict[str, list[int]] = {}
    body_rows: list[int] = []
    for (kind, obs_st), rows in sig_rows.items():
        groups.setdefault(kind, []).extend(rows)
        for slot, name in enumerate(obs_st):
            st = stations.get(name)
            if st is None:
                raise KeyError(f"observation {rows[0]} ({kind}): station {name!r} unknown; known: {', '.join(names)}")
            i0 = _I_ST1 if slot == 0 else _I_ST2
            x[rows, i0 : i0 + 3] = (st.radius_km, st.latitude_rad, st.longitude_rad)
        if not obs_st:
            body_rows.extend(rows)
            for i in rows:
                geometry = items[i][1]
                if geometry.body_r is None:
                    raise ValueError(f"observation {i} ({kind}) needs Geometry.body_r")
                if kind == "planet_diameter" and geometry.body_radius_km is None:
                    raise ValueError(f"observation {i} (planet_diameter) needs Geometry.body_radius_km")
                if kind == "star_planet_angle" and geometry.star_unit is None:
                    raise ValueError(f"observation {i} (star_planet_angle) needs Geometry.star_unit")

    out = np.ones((m, _N_OUT + 1))  # last column: the constant 1.0 of the bias partials
    for kind, rows in groups.items():
        b = _bucket(len(rows))
        xk = np.empty((b, _N_IN))
        xk[: len(rows)] = x[rows]
        xk[len(rows) :] = x[rows[0]]  # padding: a copy of a valid row, discarded
        out[rows, :_N_OUT] = np.asarray(_batch_kernel(kind)(xk))[: len(rows)]

    H = np.zeros((m, n))
    H[:, :6] = out[:, _O_H : _O_H + 6]
    for (kind, obs_st), rows in sig_rows.items():  # one column map per signature
        src, col, coef = _columns(labels, names, kind, obs_st)
        if col.size:  # columns are distinct within one observation (distinct stations)
            r = np.asarray(rows)
            H[r[:, None], nx + col[None, :]] += coef[None, :] * out[r[:, None], src[None, :]]
    for i in body_rows:  # ephemeris parameters through the target body's position (eqs. 35, 39)
        partials = items[i][1].body_r_partials
        if partials:
            h_body = out[i, _O_BODY : _O_BODY + 3]
            for j, lab in enumerate(labels):
                if lab in partials:
                    H[i, nx + j] += h_body @ _vec3(f"body_r_partials[{lab!r}]", partials[lab])
    with np.errstate(invalid="ignore"):
        elev = np.degrees(np.fmin(out[:, _O_EL], out[:, _O_EL + 1]))  # nan-aware minimum
    elev[body_rows] = np.nan
    sigma = np.array([ob.sigma for ob, _ in items], dtype=np.float64)
    return ObservationBatch(values=out[:, 0].copy(), H=H, sigma=sigma, elevation_deg=elev)
