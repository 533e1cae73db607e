"""TRAKM's kernels for the onboard (Shuttle UNF) kinds: one-way Doppler count, sensor angles,
horizon angle and altitude, each one jitted, vmapped JAX kernel over packed input rows (the
sensor frame built at the reference), then the label columns of H (unit biases, geometry
partials, station locations, the count's STM chain).

Part of :mod:`fracas.measurements.trakm` (module docstring there).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Mapping, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from fracas import _jax  # noqa: F401  (x64 first)
from fracas.measurements import models, onboard
from fracas.measurements.kinds import MEASUREMENT_KINDS
from fracas.measurements.stations import Station, station_partials, station_state
from fracas.measurements.trakm.bookkeeping import _STATION_PARAM_INDEX, _bucket, _label_table
from fracas.measurements.trakm.records import Geometry, Observation, ObservationBatch, _vec3

# Packed input of an onboard observation:
_J_ET, _J_SC, _J_E, _J_ST, _J_BODY, _J_AX, _J_POLE = 0, 1, 7, 13, 16, 19, 28
_J_A, _J_B, _J_G, _J_RREF, _J_GEOD, _J_OFF, _J_TST, _J_ET0, _J_SC0, _J_E0 = 31, 32, 33, 34, 35, 36, 39, 40, 41, 44
_NJ_IN = 47
# Packed output: value, h_sc (6), h_st (R, phi, lam) (3), h_sc0 (6, at t0), g (4: the kind's
# geometry_partials), rho_H, elevation
_K_H, _K_ST, _K_H0, _K_G, _K_RHO, _K_EL = 1, 7, 10, 16, 20, 21
_NK_OUT = 22


def _onboard_kernel(kind: str) -> Callable[[jax.Array], jax.Array]:
    """Packed kernel for one onboard kind: (47,) -> (22,)."""

    def kernel(x: jax.Array) -> jax.Array:
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
def _onboard_batch_kernel(kind: str) -> Callable[[jax.Array], jax.Array]:
    """Jitted, vmapped onboard kernel for one kind: (b, 47) -> (b, 22) (bucketed as TRAKM's)."""
    return jax.jit(jax.vmap(_onboard_kernel(kind)))


def _np_unit(x: np.ndarray) -> np.ndarray:
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


# C901 on purpose: one branch per onboard measurement kind, kept side by side as in the report
def _onboard_many(  # noqa: C901
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
