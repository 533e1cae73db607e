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
    """TRAKM + MENO over the schedule: the observation matrices of every measurement event."""
    sched = study.schedule
    K, n, nx = sched.n, study.layout.n, study.nx
    ks = [k for k in range(K) if sched.tracking[k]]
    per_k: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray, list[MeasurementRecord]]] = {}
    skipped: dict[int, int] = {}
    if ks:
        body_names = sorted({t.body for t in study.deck.tracking if t.body})
        bodies = sorted(set(ref.primary[k] for k in ks) | {"earth"} | set(body_names))
        pos, vel = _ephemeris_states(study, ref, ks, bodies)
        bi = {b: i for i, b in enumerate(bodies)}
        for j_k, k in enumerate(ks):
            p = bi[ref.primary[k]]
            o_r, o_v = pos[j_k, p], vel[j_k, p]
            x = ref.states[k]
            obs, sig_t, meta = [], [], []
            for j in sched.tracking[k]:
                t = study.deck.tracking[j]
                body_r = body_v = None
                radius = star = None
                if t.body:
                    body_r, body_v = pos[j_k, bi[t.body]] - o_r, vel[j_k, bi[t.body]] - o_v
                    radius = BODIES[t.body].radius_km
                if t.type == "star_planet_angle":
                    ra, de = math.radians(t.star_ra_deg), math.radians(t.star_dec_deg)
                    star = np.array([math.cos(de) * math.cos(ra), math.cos(de) * math.sin(ra), math.sin(de)])
                geo = trakm.Geometry(
                    et_s=float(study.problem.epoch_et_s + ref.times_s[k]), sc_r=x[:3], sc_v=x[3:6],
                    earth_r=pos[j_k, bi["earth"]] - o_r, earth_v=vel[j_k, bi["earth"]] - o_v,
                    body_r=body_r, body_v=body_v, body_radius_km=radius, star_unit=star)
                b = trakm.observation_matrix([study.observations[j]], geo, study.stations, study.labels, nx)
                elev = float(b.elevation_deg[0])
                used = not (np.isfinite(elev) and elev < study.min_elevation_deg)
                rec = MeasurementRecord(k, j, t.type, tuple(t.stations), float(b.values[0]), elev, used,
                                        study.observations[j].sigma)
                if not used:
                    skipped[j] = skipped.get(j, 0) + 1
                else:
                    obs.append(np.asarray(b.H[0]))
                    sig_t.append(study.true_sigma[j])
                meta.append(rec)
            per_k[k] = (np.array(obs).reshape(-1, n), np.array([r.sigma for r in meta if r.used]),
                        np.array(sig_t), meta)
    m = max([v[0].shape[0] for v in per_k.values()] + [1])
    m = int(math.ceil(m / m_pad) * m_pad)
    H = np.zeros((K, m, n))
    Ra = np.broadcast_to(np.eye(m), (K, m, m)).copy()
    Rt = Ra.copy()
    records: list[MeasurementRecord] = []
    for k, (h, sa, st, meta) in per_k.items():
        r = h.shape[0]
        H[k, :r] = h
        Ra[k, np.arange(r), np.arange(r)] = sa ** 2
        Rt[k, np.arange(r), np.arange(r)] = st ** 2
        row = 0
        for rec in meta:
            if rec.used:
                rec.row = row
                row += 1
            records.append(rec)
    return MeasurementSet(H, Ra, Rt, records, skipped)
