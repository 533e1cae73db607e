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
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import jax
import jax.numpy as jnp
import numpy as np

from fracas import _jax  # noqa: F401  (x64 first)
from fracas.measurements import models, onboard
from fracas.measurements.kinds import (
    GLOBAL_LABELS,
    KIND_UNITS,
    MEASUREMENT_KINDS,
    STATION_LABELS,
    _split,
    check_measurement_label,
    is_measurement_label,
    measurement_label_unit,
)
from fracas.measurements.stations import Station, station_partials, station_state

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

# Label tables and label checks live in the jax-free catalogue (re-exported here).
_KIND_UNITS = KIND_UNITS
_STATION_PARAM_INDEX = {"station_radius_km": 0, "station_lat_rad": 1, "station_lon_rad": 2}


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

    def __post_init__(self):
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


# --- kernels ------------------------------------------------------------------------
# Packed input (one float64 vector, one host->device transfer per observation):
_I_ET, _I_SC, _I_E, _I_ST1, _I_ST2, _I_BODY, _I_RP, _I_STAR = 0, 1, 7, 13, 16, 19, 22, 23
_N_IN = 26
# Packed output: value, h_sc (6), h_st1 (R, phi, lam), h_st2 (3), h_body_r (3), elev1, elev2
_O_H, _O_ST1, _O_ST2, _O_BODY, _O_EL = 1, 7, 10, 13, 16
_N_OUT = 18


def _station(x, i0, et):
    R, lat, lon = x[i0], x[i0 + 1], x[i0 + 2]
    r, v = station_state(R, lat, lon, et)
    return r, v, station_partials(R, lat, lon, et)


def _kernel(kind: str):
    """Packed kernel for one kind: (26,) -> (18,) (traced inside :func:`_batch_kernel`)."""
    value_fn = models.VALUE_FUNCTIONS[kind]
    partial_fn = models.PARTIAL_FUNCTIONS[kind]
    n_st = models.N_STATIONS[kind]

    def kernel(x):
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
def _batch_kernel(kind: str):
    """Jitted kernel for one kind, vmapped over observations: (b, 26) -> (b, 18).

    Built once per kind; the batch is padded to a power of two (at least
    :data:`_MIN_BUCKET`), so it compiles once per kind and size bucket (and not at all in a
    later process with the persistent compilation cache).  One dispatch per kind present
    in a call.  (A single all-kinds kernel with ``lax.switch`` was tried: vmapped, it
    evaluates every branch and cost ~0.5 ms a call against ~0.05 ms per kind here.)
    """
    return jax.jit(jax.vmap(_kernel(kind)))


_MIN_BUCKET = 4


def _bucket(m: int) -> int:
    return max(_MIN_BUCKET, 1 << max(m - 1, 0).bit_length())


# --- label bookkeeping --------------------------------------------------------------
# Unit bias partials per kind: (label name, station slot or None, coefficient).
_BIAS_TERMS = {k.name: k.bias_terms for k in MEASUREMENT_KINDS.values()}


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


_ONE = _N_OUT  # index of a constant 1.0 appended to each kernel output row


@functools.lru_cache(maxsize=4096)
def _columns(labels: tuple, station_names: tuple, kind: str, obs_stations: tuple):
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


def _vec3(name, x):
    a = np.asarray(x, dtype=np.float64)
    if a.shape != (3,):
        raise ValueError(f"Geometry.{name}: expected shape (3,), got {a.shape}")
    return a


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


# --- onboard (Shuttle UNF) kinds ----------------------------------------------------------
# Packed input of an onboard observation:
_J_ET, _J_SC, _J_E, _J_ST, _J_BODY, _J_AX, _J_POLE = 0, 1, 7, 13, 16, 19, 28
_J_A, _J_B, _J_G, _J_RREF, _J_GEOD, _J_OFF, _J_TST, _J_ET0, _J_SC0, _J_E0 = 31, 32, 33, 34, 35, 36, 39, 40, 41, 44
_NJ_IN = 47
# Packed output: value, h_sc (6), h_st (R, phi, lam) (3), h_sc0 (6, at t0), g (4: the kind's
# geometry_partials), rho_H, elevation
_K_H, _K_ST, _K_H0, _K_G, _K_RHO, _K_EL = 1, 7, 10, 16, 20, 21
_NK_OUT = 22


def _onboard_kernel(kind: str):
    """Packed kernel for one onboard kind: (47,) -> (22,)."""

    def kernel(x):
        et = x[_J_ET]
        sc_r = x[_J_SC : _J_SC + 3]
        e_r, e_v = x[_J_E : _J_E + 3], x[_J_E + 3 : _J_E + 6]
        body_r = x[_J_BODY : _J_BODY + 3]
        axes = x[_J_AX : _J_AX + 9].reshape(3, 3)
        pole = x[_J_POLE : _J_POLE + 3]
        a_f, b_f, gam = x[_J_A], x[_J_B], x[_J_G]
        z3, z6 = jnp.zeros(3, dtype=jnp.float64), jnp.zeros(6, dtype=jnp.float64)
        z4 = jnp.zeros(4, dtype=jnp.float64)
        nan1 = jnp.full(1, jnp.nan, dtype=jnp.float64)
        R, lat, lon = x[_J_ST], x[_J_ST + 1], x[_J_ST + 2]
        if kind == "doppler_count_1way":
            et0 = x[_J_ET0]
            s1_r, s1_v = station_state(R, lat, lon, et)
            s0_r, _ = station_state(R, lat, lon, et0)
            sc0, e0 = x[_J_SC0 : _J_SC0 + 3], x[_J_E0 : _J_E0 + 3]
            val = onboard.doppler_count_1way(sc_r, e_r, s1_r, sc0, e0, s0_r)
            h1, hs1, h0, hs0 = onboard.doppler_count_1way_partials(sc_r, e_r, s1_r, sc0, e0, s0_r)
            h_st = jnp.concatenate([hs1, z3]) @ station_partials(R, lat, lon, et) + jnp.concatenate(
                [hs0, z3]
            ) @ station_partials(R, lat, lon, et0)
            sc_v = x[_J_SC + 3 : _J_SC + 6]
            el1 = models.elevation(sc_r, sc_v, e_r, e_v, s1_r, s1_v)
            el0 = models.elevation(sc0, sc_v, e0, e_v, s0_r, s1_v)
            el = jnp.minimum(el0, el1)
            return jnp.concatenate([val[None], h1, h_st, h0, z4, nan1, el[None]])
        if kind in ("sensor_beta", "sensor_theta"):
            st_r, _ = station_state(R, lat, lon, et)
            is_st = x[_J_TST] > 0.5
            target = jnp.where(is_st, e_r + st_r, body_r + x[_J_OFF : _J_OFF + 3])
            fns = {"sensor_beta": onboard.sensor_beta, "sensor_theta": onboard.sensor_theta}
            pfs = {"sensor_beta": onboard.sensor_beta_partials, "sensor_theta": onboard.sensor_theta_partials}
            val = fns[kind](sc_r, target, axes)
            h_sc, h_t, h_phi = pfs[kind](sc_r, target, axes)
            h_st = jnp.where(is_st, jnp.concatenate([h_t, z3]) @ station_partials(R, lat, lon, et), z3)
            g = jnp.concatenate([h_phi, jnp.zeros(1, dtype=jnp.float64)])
            return jnp.concatenate([val[None], h_sc, h_st, z6, g, nan1, nan1])
        if kind == "horizon_angle":
            val = onboard.horizon_angle(sc_r, body_r, axes, pole, a_f, b_f, gam)
            h_sc, dgam, rho_h = onboard.horizon_angle_partials(sc_r, body_r, axes, pole, a_f, b_f, gam)
            g = jnp.concatenate([dgam[None], z3])
            return jnp.concatenate([val[None], h_sc, z3, z6, g, rho_h[None], nan1])
        args = (sc_r, body_r, pole, a_f, b_f, x[_J_RREF], x[_J_GEOD])
        val = onboard.altitude(*args)
        h_sc = onboard.altitude_partials(*args)
        return jnp.concatenate([val[None], h_sc, z3, z6, z4, nan1, nan1])

    return kernel


@functools.cache
def _onboard_batch_kernel(kind: str):
    """Jitted, vmapped onboard kernel for one kind: (b, 47) -> (b, 22) (bucketed as TRAKM's)."""
    return jax.jit(jax.vmap(_onboard_kernel(kind)))


def _np_unit(x):
    return x / np.linalg.norm(x)


def _onboard_row(ob: Observation, geometry: Geometry, stations: Mapping[str, Station], i: int) -> np.ndarray:
    """Packed onboard input row of one observation (the sensor frame built at the reference)."""
    sen = ob.sensor
    x = np.zeros(_NJ_IN)
    x[_J_ET] = float(geometry.et_s)
    x[_J_SC : _J_SC + 3] = _vec3("sc_r", geometry.sc_r)
    x[_J_SC + 3 : _J_SC + 6] = _vec3("sc_v", geometry.sc_v)
    x[_J_E : _J_E + 3] = _vec3("earth_r", geometry.earth_r)
    x[_J_E + 3 : _J_E + 6] = _vec3("earth_v", geometry.earth_v)
    st_name = ob.stations[0] if ob.stations else (sen.target_station if sen.target == "station" else "")
    if st_name:
        st = stations.get(st_name)
        if st is None:
            raise KeyError(
                f"observation {i} ({ob.kind}): station {st_name!r} unknown; known: {', '.join(sorted(stations))}"
            )
        x[_J_ST : _J_ST + 3] = (st.radius_km, st.latitude_rad, st.longitude_rad)
    if ob.kind == "doppler_count_1way":
        if geometry.et0_s is None or geometry.sc_r0 is None or geometry.earth_r0 is None:
            raise ValueError(
                f"observation {i} (doppler_count_1way) needs Geometry.et0_s, sc_r0, earth_r0 (count start)"
            )
        x[_J_ET0] = float(geometry.et0_s)
        x[_J_SC0 : _J_SC0 + 3] = _vec3("sc_r0", geometry.sc_r0)
        x[_J_E0 : _J_E0 + 3] = _vec3("earth_r0", geometry.earth_r0)
        return x
    if geometry.body_r is None:
        raise ValueError(f"observation {i} ({ob.kind}) needs Geometry.body_r")
    body_r = _vec3("body_r", geometry.body_r)
    body_v = np.zeros(3) if geometry.body_v is None else _vec3("body_v", geometry.body_v)
    x[_J_BODY : _J_BODY + 3] = body_r
    a_f = sen.equatorial_radius_km or (geometry.body_radius_km or 0.0)
    b_f = sen.polar_radius_km or a_f
    x[_J_A], x[_J_B], x[_J_G] = a_f, b_f, sen.horizon_altitude_km
    x[_J_POLE : _J_POLE + 3] = _np_unit(np.asarray(sen.pole, dtype=np.float64))
    x[_J_RREF] = sen.reference_radius_km or a_f
    x[_J_GEOD] = 1.0 if sen.altitude_model == "geodetic" else 0.0
    r_rel = x[_J_SC : _J_SC + 3] - body_r
    v_rel = x[_J_SC + 3 : _J_SC + 6] - body_v
    if ob.kind == "horizon_angle":
        dep = sen.boresight_depression_rad
        if dep is None:
            dep = math.acos(min(1.0, a_f / np.linalg.norm(r_rel)))
        axes = np.asarray(onboard.horizon_sensor_axes(r_rel, v_rel, sen.horizon_azimuth_rad, dep))
    else:
        axes = np.asarray(sen.sensor_axes, dtype=np.float64)
        if sen.sensor_frame == "lvlh":
            axes = axes @ np.asarray(onboard.lvlh_axes(r_rel, v_rel))
    x[_J_AX : _J_AX + 9] = axes.reshape(9)
    x[_J_OFF : _J_OFF + 3] = np.asarray(sen.target_point_km, dtype=np.float64)
    x[_J_TST] = 1.0 if sen.target == "station" else 0.0
    return x


def _onboard_many(
    items: Sequence[tuple[Observation, Geometry]],
    stations: Mapping[str, Station],
    labels: Sequence[str],
    nx: int,
) -> ObservationBatch:
    """TRAKM + MENO for the onboard kinds: kernels per kind, then the label columns (unit
    biases from the catalogue, geometry partials, station locations, the count's STM chain)."""
    labels = tuple(labels)
    names = tuple(sorted(stations))
    table = _label_table(labels, names)
    m, n = len(items), nx + len(labels)
    x = np.stack([_onboard_row(ob, g, stations, i) for i, (ob, g) in enumerate(items)])
    groups: dict[str, list[int]] = {}
    for i, (ob, _) in enumerate(items):
        groups.setdefault(ob.kind, []).append(i)
    out = np.empty((m, _NK_OUT))
    for kind, rows in groups.items():
        b = _bucket(len(rows))
        xk = np.empty((b, _NJ_IN))
        xk[: len(rows)] = x[rows]
        xk[len(rows) :] = x[rows[0]]
        out[rows] = np.asarray(_onboard_batch_kernel(kind)(xk))[: len(rows)]
    H = np.zeros((m, n))
    H[:, :6] = out[:, _K_H : _K_H + 6]
    extra = np.zeros(m)
    for i, (ob, geometry) in enumerate(items):
        kind = MEASUREMENT_KINDS[ob.kind]
        st_name = ob.stations[0] if ob.stations else (ob.sensor.target_station if ob.sensor.target == "station" else "")
        if st_name:
            for lname, k in _STATION_PARAM_INDEX.items():
                for j in table.get((lname, st_name), ()):
                    H[i, nx + j] += out[i, _K_ST + k]
        for lname, slot, c in kind.bias_terms:
            for j in table.get((lname, None if slot is None else ob.stations[slot]), ()):
                H[i, nx + j] += c
        for s_i, lname in enumerate(kind.geometry_partials):
            for j in table.get((lname, None), ()):
                H[i, nx + j] += out[i, _K_G + s_i]
        if ob.kind == "doppler_count_1way":
            phi = geometry.phi_0m
            if phi is None:
                raise ValueError(f"observation {i} (doppler_count_1way) needs Geometry.phi_0m, Phi(t0, t_M)")
            phi = np.asarray(phi, dtype=np.float64)
            h0 = np.zeros(phi.shape[0])
            h0[:6] = out[i, _K_H0 : _K_H0 + 6]
            H[i, : min(nx, phi.shape[1])] += (h0 @ phi)[: min(nx, phi.shape[1])]
            for j, lab in enumerate(labels):
                if lab in geometry.dx0_dp:
                    H[i, nx + j] += h0 @ np.asarray(geometry.dx0_dp[lab], dtype=np.float64)
        if ob.kind == "horizon_angle" and ob.sensor.horizon_sigma_km > 0.0:
            extra[i] = (ob.sensor.horizon_sigma_km * out[i, _K_G]) ** 2
    sigma = np.sqrt(np.array([ob.sigma for ob, _ in items], dtype=np.float64) ** 2 + extra)
    with np.errstate(invalid="ignore"):
        elev = np.degrees(out[:, _K_EL])
    return ObservationBatch(values=out[:, 0].copy(), H=H, sigma=sigma, elevation_deg=elev, extra_variance=extra)


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


def _classic_many(
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
