"""Measurement events of a study: geometry, observation matrices and noise (FRACAS MEAS, TRAKM, MENO).

For every measurement time of the schedule: the Earth's (and an observed body's) state
relative to the trajectory primary from DE421, the observations of the tracking entries
due then, their H rows over the augmented state and their noise.  An observation whose
station sees the spacecraft below ``min_elevation_deg`` is skipped and counted (reported,
never fatal).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from fracas.constants import BODIES, DAY_S
from fracas.measurements import trakm
from fracas.team.reference import Reference
from fracas.team.study import Study

__all__ = ["MeasurementRecord", "MeasurementSet", "assemble_measurements"]


@dataclass
class MeasurementRecord:
    """One observation at one schedule time (what the printout and results file show)."""

    k: int
    tracking: int
    kind: str
    stations: tuple[str, ...]
    value: float
    elevation_deg: float
    used: bool
    sigma: float
    row: int = -1  # row in H[k] when used


@dataclass
class MeasurementSet:
    """H (K, m, n), assumed and true noise R (K, m, m) over the schedule, padded rows zero."""

    H: np.ndarray
    R_assumed: np.ndarray
    R_true: np.ndarray
    records: list[MeasurementRecord] = field(default_factory=list)
    skipped: dict[int, int] = field(default_factory=dict)

    @property
    def m(self) -> int:
        return self.H.shape[1]


def _ephemeris_states(study: Study, ref: Reference, ks: list[int], bodies: list[str]):
    """Heliocentric ICRF states (len(ks), nb, 3) of ``bodies`` at schedule indices ``ks``."""
    from fracas.dynamics.ephemeris import body_states, build_ephemeris

    et = study.problem.epoch_et_s + ref.times_s[ks]
    table = build_ephemeris(bodies, float(et.min()), float(et.max()), margin_s=2 * DAY_S)
    pos, vel = body_states(table, et)
    return np.asarray(pos), np.asarray(vel)


def assemble_measurements(study: Study, ref: Reference, m_pad: int = 4) -> MeasurementSet:
    """TRAKM + MENO over the schedule: the observation matrices of every measurement event.

    One :class:`trakm.Geometry` per measurement time, all observations of the study in one
    :func:`trakm.observation_matrix_many` call (one vmapped kernel dispatch per type), then
    the rows are scattered into H[k] by schedule index.  Skipped observations (below
    ``min_elevation_deg``) are counted per tracking entry.
    """
    sched = study.schedule
    K, n, nx = sched.n, study.layout.n, study.nx
    pairs = [(k, j) for k in range(K) for j in sched.tracking[k]]
    eye = np.broadcast_to(np.eye(m_pad), (K, m_pad, m_pad))
    if not pairs:
        return MeasurementSet(np.zeros((K, m_pad, n)), eye.copy(), eye.copy(), [], {})
    starts, no_start = _count_starts(study, ref, pairs)
    items = _observation_items(study, ref, pairs, starts)
    batch = trakm.observation_matrix_many(items, study.stations, study.labels, nx)
    visible = _visible(study, ref, pairs, items)
    records, skipped, per_k = _records(study, pairs, batch, visible, no_start)
    m = int(math.ceil(max(list(per_k.values()) + [1]) / m_pad) * m_pad)
    H, Ra, Rt = _scatter(study, K, m, n, records, batch, len(pairs))
    return MeasurementSet(H, Ra, Rt, records, skipped)


def _observation_items(study: Study, ref: Reference, pairs: list[tuple[int, int]], starts: dict) -> list[tuple]:
    """(observation, geometry) of every (k, j) pair, one :class:`trakm.Geometry` per
    schedule index, observed body and count interval (built once, shared)."""
    ks = sorted({k for k, _ in pairs} | {k0 for k0, _, _ in starts.values()})
    body_names = sorted({t.body for t in study.tracking if t.body})
    bodies = sorted({ref.primary[k] for k in ks} | {"earth"} | set(body_names))
    pos, vel = _ephemeris_states(study, ref, ks, bodies)
    bi = {b: i for i, b in enumerate(bodies)}
    stars = {j: t.star_unit for j, t in enumerate(study.tracking) if t.star_unit is not None}
    geos: dict[tuple[int, str | None, float], trakm.Geometry] = {}
    items = []
    for k, j in pairs:
        t = study.tracking[j]
        ob = study.observations[j]
        dt_c = ob.sensor.count_interval_s if ob.kind == "doppler_count_1way" else 0.0
        key = (k, t.body, dt_c)
        geo = geos.get(key)
        if geo is None:
            geo = geos[key] = _geometry(study, ref, k, j, dt_c, starts, ks, bi, pos, vel, stars)
        items.append((study.observations[j], geo))
    return items


def _geometry(
    study: Study,
    ref: Reference,
    k: int,
    j: int,
    dt_c: float,
    starts: dict,
    ks: list[int],
    bi: dict[str, int],
    pos: np.ndarray,
    vel: np.ndarray,
    stars: dict,
) -> trakm.Geometry:
    """The geometry of observation ``j`` at schedule index ``k``: a one-way Doppler count's
    (with its start, or zeros when the count started before the study), else the usual one."""
    t = study.tracking[j]
    if dt_c > 0.0 and (k, j) in starts:
        k0, phi_0m, dx0 = starts[(k, j)]
        a, a0, p = ks.index(k), ks.index(k0), bi[ref.primary[k]]
        x, x0 = ref.states[k], ref.states[k0]
        return trakm.Geometry(
            et_s=float(study.problem.epoch_et_s + ref.times_s[k]),
            sc_r=x[:3],
            sc_v=x[3:6],
            earth_r=pos[a, bi["earth"]] - pos[a, p],
            earth_v=vel[a, bi["earth"]] - vel[a, p],
            et0_s=float(study.problem.epoch_et_s + ref.times_s[k0]),
            sc_r0=x0[:3],
            earth_r0=pos[a0, bi["earth"]] - pos[a0, p],
            phi_0m=phi_0m,
            dx0_dp=dx0,
        )
    if dt_c > 0.0:  # the count started before the study (or on another primary)
        return trakm.Geometry(
            et_s=float(study.problem.epoch_et_s + ref.times_s[k]),
            sc_r=ref.states[k][:3],
            sc_v=ref.states[k][3:6],
            earth_r=np.zeros(3),
            earth_v=np.zeros(3),
            et0_s=float(study.problem.epoch_et_s + ref.times_s[k]),
            sc_r0=ref.states[k][:3],
            earth_r0=np.zeros(3),
            phi_0m=np.eye(7),
        )
    a, p = ks.index(k), bi[ref.primary[k]]
    o_r, o_v = pos[a, p], vel[a, p]
    x = ref.states[k]
    return trakm.Geometry(
        et_s=float(study.problem.epoch_et_s + ref.times_s[k]),
        sc_r=x[:3],
        sc_v=x[3:6],
        earth_r=pos[a, bi["earth"]] - o_r,
        earth_v=vel[a, bi["earth"]] - o_v,
        body_r=None if t.body is None else pos[a, bi[t.body]] - o_r,
        body_v=None if t.body is None else vel[a, bi[t.body]] - o_v,
        body_radius_km=None if t.body is None else BODIES[t.body].radius_km,
        star_unit=stars.get(j),
    )


def _records(
    study: Study, pairs: list[tuple[int, int]], batch: trakm.ObservationBatch, visible: np.ndarray, no_start: set
) -> tuple[list[MeasurementRecord], dict[int, int], dict[int, int]]:
    """The record of every observation (used, or skipped below the elevation mask, outside a
    beacon's cone or without its count start), the skipped count per tracking entry and the
    used rows per schedule index."""
    skipped: dict[int, int] = {}
    records: list[MeasurementRecord] = []
    per_k: dict[int, int] = {}
    for i, (k, j) in enumerate(pairs):
        e = float(batch.elevation_deg[i])
        used = not (np.isfinite(e) and e < study.min_elevation_deg) and visible[i] and (k, j) not in no_start
        rec = MeasurementRecord(
            k,
            j,
            study.tracking[j].kind,
            study.observations[j].stations,
            float(batch.values[i]),
            e,
            used,
            float(batch.sigma[i]),
        )
        if used:
            rec.row = per_k.get(k, 0)
            per_k[k] = rec.row + 1
        else:
            skipped[j] = skipped.get(j, 0) + 1
        records.append(rec)
    return records, skipped, per_k


def _scatter(
    study: Study, K: int, m: int, n: int, records: list[MeasurementRecord], batch: trakm.ObservationBatch, n_pairs: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """H (K, m, n), R_assumed, R_true (K, m, m): the used rows scattered by schedule index
    (MENO: the true variance adds the observation's extra variance)."""
    H = np.zeros((K, m, n))
    Ra = np.broadcast_to(np.eye(m), (K, m, m)).copy()
    Rt = Ra.copy()
    ii = np.array([i for i, r in enumerate(records) if r.used], dtype=np.intp)
    kk = np.array([records[i].k for i in ii], dtype=np.intp)
    rr = np.array([records[i].row for i in ii], dtype=np.intp)
    jj = np.array([records[i].tracking for i in ii], dtype=np.intp)
    H[kk, rr] = batch.H[ii]
    Ra[kk, rr, rr] = batch.sigma[ii] ** 2
    extra = np.zeros(n_pairs) if batch.extra_variance is None else batch.extra_variance
    Rt[kk, rr, rr] = study.true_sigma[jj] ** 2 + extra[ii]
    return H, Ra, Rt


def _count_starts(study: Study, ref: Reference, pairs):
    """One-way Doppler counts: (k, j) -> (k0, Phi(t0, t_M) (7, 7), {label: d x(t0)/d p (7,)})
    with t0 = t_M - dt_c a schedule time (the deck builder adds it, fracas.build.onboard), and
    the set of counts whose start is not in the schedule or not on the same primary (skipped).

    Phi(t_M, t0) and Theta(t_M, t0) are chained from the reference's step matrices
    (x_k = Phi_k x_{k-1} + Theta_k p); at fixed x(t_M), d x(t0)/d p = -Phi(t0, t_M) Theta(t_M, t0).
    """
    times = ref.times_s
    out: dict = {}
    missing: set = set()
    for k, j in pairs:
        ob = study.observations[j]
        if ob.kind != "doppler_count_1way":
            continue
        t0 = times[k] - ob.sensor.count_interval_s
        k0 = int(np.argmin(np.abs(times - t0)))
        if abs(times[k0] - t0) > 1.5e-3 or k0 >= k or ref.primary[k0] != ref.primary[k]:
            missing.add((k, j))
            continue
        phi = np.eye(7)
        theta = np.zeros((7, ref.theta.shape[2]))
        for i in range(k0 + 1, k + 1):
            phi = ref.phi[i] @ phi
            theta = ref.phi[i] @ theta + ref.theta[i]
        phi_0m = np.linalg.inv(phi)
        dx0 = {lab: -(phi_0m @ theta[:, c]) for c, lab in enumerate(ref.labels)}
        out[(k, j)] = (k0, phi_0m, dx0)
    return out, missing


def _visible(study: Study, ref: Reference, pairs, items) -> np.ndarray:
    """Beacon visibility cones (fracas.measurements.visibility) of the entries that set one:
    every participating station must see the spacecraft (elevation mask, maximum range)."""
    from fracas.measurements.stations import station_state
    from fracas.measurements.visibility import beacon_visible

    out = np.ones(len(pairs), dtype=bool)
    for i, (_, j) in enumerate(pairs):
        ob = study.observations[j]
        if ob.visibility is None:
            continue
        geo = items[i][1]
        for name in ob.stations:
            st = study.stations[name]
            r_b, _ = station_state(st.radius_km, st.latitude_rad, st.longitude_rad, geo.et_s)
            r_p = np.asarray(geo.sc_r) - np.asarray(geo.earth_r)
            out[i] &= bool(beacon_visible(r_p, np.asarray(r_b), ob.visibility[0], ob.visibility[1]))
    return out
