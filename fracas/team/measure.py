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
    ks = sorted({k for k, _ in pairs})
    body_names = sorted({t.body for t in study.tracking if t.body})
    bodies = sorted({ref.primary[k] for k in ks} | {"earth"} | set(body_names))
    pos, vel = _ephemeris_states(study, ref, ks, bodies)
    bi = {b: i for i, b in enumerate(bodies)}
    stars = {j: t.star_unit for j, t in enumerate(study.tracking) if t.star_unit is not None}
    geos: dict[tuple[int, str | None], trakm.Geometry] = {}
    items = []
    for k, j in pairs:
        t = study.tracking[j]
        key = (k, t.body)
        geo = geos.get(key)
        if geo is None:
            a, p = ks.index(k), bi[ref.primary[k]]
            o_r, o_v = pos[a, p], vel[a, p]
            x = ref.states[k]
            geo = geos[key] = trakm.Geometry(
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
        items.append((study.observations[j], geo))
    batch = trakm.observation_matrix_many(items, study.stations, study.labels, nx)

    skipped: dict[int, int] = {}
    records: list[MeasurementRecord] = []
    per_k: dict[int, int] = {}
    for i, (k, j) in enumerate(pairs):
        e = float(batch.elevation_deg[i])
        used = not (np.isfinite(e) and e < study.min_elevation_deg)
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
    m = int(math.ceil(max(list(per_k.values()) + [1]) / m_pad) * m_pad)
    H = np.zeros((K, m, n))
    Ra = np.broadcast_to(np.eye(m), (K, m, m)).copy()
    Rt = Ra.copy()
    ii = np.array([i for i, r in enumerate(records) if r.used], dtype=np.intp)
    kk = np.array([records[i].k for i in ii], dtype=np.intp)
    rr = np.array([records[i].row for i in ii], dtype=np.intp)
    jj = np.array([records[i].tracking for i in ii], dtype=np.intp)
    H[kk, rr] = batch.H[ii]
    Ra[kk, rr, rr] = batch.sigma[ii] ** 2
    Rt[kk, rr, rr] = study.true_sigma[jj] ** 2
    return MeasurementSet(H, Ra, Rt, records, skipped)
