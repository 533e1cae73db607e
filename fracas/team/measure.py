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

from fracas.constants import BODIES
from fracas.measurements import trakm
from fracas.team.reference import Reference
from fracas.team.setup import Study

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
    table = build_ephemeris(bodies, float(et.min()), float(et.max()), margin_s=2 * 86400.0)
    pos, vel = body_states(table, et)
    return np.asarray(pos), np.asarray(vel)


def assemble_measurements(study: Study, ref: Reference, m_pad: int = 4) -> MeasurementSet:
    """TRAKM + MENO over the schedule: the observation matrices of every measurement event.

    All observations of the study are evaluated together: one jitted, vmapped kernel call
    per measurement type (trakm's packed kernels), then scattered into H[k] by schedule
    index.  Skipped observations (below ``min_elevation_deg``) are counted per entry.
    """
    sched = study.schedule
    K, n, nx = sched.n, study.layout.n, study.nx
    pairs = [(k, j) for k in range(K) for j in sched.tracking[k]]
    skipped: dict[int, int] = {}
    records: list[MeasurementRecord] = []
    if not pairs:
        return MeasurementSet(np.zeros((K, m_pad, n)), np.broadcast_to(np.eye(m_pad), (K, m_pad, m_pad)).copy(),
                              np.broadcast_to(np.eye(m_pad), (K, m_pad, m_pad)).copy(), [], {})
    ks = sorted({k for k, _ in pairs})
    kpos = {k: i for i, k in enumerate(ks)}
    body_names = sorted({t.body for t in study.deck.tracking if t.body})
    bodies = sorted(set(ref.primary[k] for k in ks) | {"earth"} | set(body_names))
    pos, vel = _ephemeris_states(study, ref, ks, bodies)
    bi = {b: i for i, b in enumerate(bodies)}
    T = trakm
    x = np.zeros((len(pairs), T._N_IN))
    pk = np.array([k for k, _ in pairs])
    pj = np.array([j for _, j in pairs])
    pa = np.array([kpos[k] for k in pk])
    prim = np.array([bi[ref.primary[k]] for k in pk])
    o_r, o_v = pos[pa, prim], vel[pa, prim]
    x[:, T._I_ET] = study.problem.epoch_et_s + ref.times_s[pk]
    x[:, T._I_SC:T._I_SC + 6] = ref.states[pk, :6]
    x[:, T._I_E:T._I_E + 3] = pos[pa, bi["earth"]] - o_r
    x[:, T._I_E + 3:T._I_E + 6] = vel[pa, bi["earth"]] - o_v
    for j, t in enumerate(study.deck.tracking):
        rows = pj == j
        if not rows.any():
            continue
        for slot, name in enumerate(t.stations):
            st = study.stations[name]
            i0 = T._I_ST1 if slot == 0 else T._I_ST2
            x[rows, i0:i0 + 3] = (st.radius_km, st.latitude_rad, st.longitude_rad)
        if t.body:
            x[rows, T._I_BODY:T._I_BODY + 3] = pos[pa[rows], bi[t.body]] - o_r[rows]
            x[rows, T._I_RP] = BODIES[t.body].radius_km
        if t.type == "star_planet_angle":
            ra, de = math.radians(t.star_ra_deg), math.radians(t.star_dec_deg)
            x[rows, T._I_STAR:T._I_STAR + 3] = (math.cos(de) * math.cos(ra), math.cos(de) * math.sin(ra), math.sin(de))
    out = np.ones((len(pairs), T._N_OUT + 1))
    groups: dict[str, list[int]] = {}
    for i, (_, j) in enumerate(pairs):
        groups.setdefault(study.deck.tracking[j].type, []).append(i)
    for kind, rows in groups.items():
        b = T._bucket(len(rows))
        xk = np.empty((b, T._N_IN))
        xk[: len(rows)] = x[rows]
        xk[len(rows):] = x[rows[0]]
        out[rows, : T._N_OUT] = np.asarray(T._batch_kernel(kind)(xk))[: len(rows)]
    labels = tuple(study.labels)
    names = tuple(sorted(study.stations))
    T._label_table(labels, names)
    with np.errstate(invalid="ignore"):
        elev = np.degrees(np.fmin(out[:, T._O_EL], out[:, T._O_EL + 1]))
    per_k: dict[int, list[int]] = {}
    for i, (k, j) in enumerate(pairs):
        t = study.deck.tracking[j]
        e = float(elev[i]) if study.observations[j].stations else float("nan")
        used = not (np.isfinite(e) and e < study.min_elevation_deg)
        rec = MeasurementRecord(k, j, t.type, tuple(t.stations), float(out[i, 0]), e, used, study.observations[j].sigma)
        records.append(rec)
        if used:
            rec.row = len(per_k.setdefault(k, []))
            per_k[k].append(i)
        else:
            skipped[j] = skipped.get(j, 0) + 1
    m = max([len(v) for v in per_k.values()] + [1])
    m = int(math.ceil(m / m_pad) * m_pad)
    H = np.zeros((K, m, n))
    Ra = np.broadcast_to(np.eye(m), (K, m, m)).copy()
    Rt = Ra.copy()
    used_i = np.array([i for i, r in enumerate(records) if r.used], dtype=np.intp)
    rows_of = np.array([r.row for r in records])
    for j, t in enumerate(study.deck.tracking):  # scatter per tracking entry (one column map each)
        ii = used_i[pj[used_i] == j]
        if ii.size == 0:
            continue
        kk, rr = pk[ii], rows_of[ii]
        H[kk, rr, :6] = out[ii, T._O_H:T._O_H + 6]
        src, col, coef = T._columns(labels, names, t.type, tuple(t.stations))
        if col.size:
            H[kk[:, None], rr[:, None], nx + col[None, :]] += coef[None, :] * out[ii[:, None], src[None, :]]
        Ra[kk, rr, rr] = study.observations[j].sigma ** 2
        Rt[kk, rr, rr] = study.true_sigma[j] ** 2
    return MeasurementSet(H, Ra, Rt, records, skipped)
