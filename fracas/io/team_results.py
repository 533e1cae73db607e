"""TEAM results file and punched knowledge covariances (HDF5, atomic; layout in docs/team_results.md)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from fracas.errors import DeckError
from fracas.io.hdf5 import atomic_h5, provenance, read_str, write, write_provenance, write_strings

__all__ = ["write_team_results", "read_team_results", "write_punch", "read_punch", "RESULTS_SCHEMA", "PUNCH_SCHEMA"]

RESULTS_SCHEMA = 1
PUNCH_SCHEMA = 1


def write_team_results(path: str | os.PathLike, res, stm_source: str) -> None:
    """Write the full event history of a TEAM run (``res``: fracas.team.engine.TeamResult)."""
    from fracas.team.eigen import eigen_summary

    st = res.study
    sched = st.schedule
    with atomic_h5(path) as f:
        f.attrs["file_kind"] = "fracas-team-results"
        f.attrs["schema_version"] = RESULTS_SCHEMA
        g = f.create_group("team")
        for k, v in (("title", st.deck.title), ("filter", st.filter_kind), ("propagation", st.propagation),
                     ("square_root", int(st.square_root)), ("generalized_covariance", int(st.gencov)),
                     ("reference", stm_source), ("trajectory_deck", st.traj_deck.source_path or "")):
            g.attrs[k] = v
        g.attrs["epoch_et_s"] = st.problem.epoch_et_s
        write(g, "times_s", res.times_s, "s", description="schedule times from the trajectory epoch")
        write_strings(g, "event_types", ["+".join(e) for e in sched.events], description="events at each time, in order")
        write(g, "states", res.ref.states, "km, km/s, kg", description="reference r, v, m rel. primary (ICRF)")
        write_strings(g, "primary", res.ref.primary)
        lab = g.create_group("labels")
        write_strings(lab, "names", res.labels)
        write_strings(lab, "units", res.units)
        write_strings(lab, "roles", res.roles)
        for which, Pm, Pp, Q in (("assumed", res.Pa_minus, res.Pa_plus, res.Q_assumed),
                                 ("true", res.Pt_minus, res.Pt_plus, res.Q_true)):
            if Pm is None:
                continue
            h = g.create_group(which)
            write(h, "P_minus", Pm, "labels/units x labels/units", description="covariance before the event")
            write(h, "P_plus", Pp, "labels/units x labels/units", description="covariance after the event")
            write(h, "process_noise", Q, "state units^2", description="effective process noise over the interval ending here")
            sig = np.sqrt(np.clip(np.einsum("kii->ki", Pp), 0, None))
            write(h, "sigma", sig, "labels/units", description="1-sigma after each event")
            ev = [k for k, e in enumerate(sched.events) if {"eigenvector", "thrust_on", "thrust_off", "final"} & set(e)]
            eg = h.create_group("eigenvector_events")
            write(eg, "index", np.array(ev, dtype=np.int64), "1")
            es = [eigen_summary(Pp[k]) for k in ev]
            if es:
                write(eg, "position_eigenvalues", np.array([e.pos_eigval for e in es]), "km^2")
                write(eg, "position_eigenvectors", np.array([e.pos_eigvec for e in es]), "1", description="columns")
                write(eg, "velocity_eigenvalues", np.array([e.vel_eigval for e in es]), "km^2/s^2")
                write(eg, "velocity_eigenvectors", np.array([e.vel_eigvec for e in es]), "1", description="columns")
                write(eg, "correlations", np.array([e.corr for e in es]), "1")
        m = g.create_group("measurements")
        recs = res.meas.records
        write(m, "index", np.array([r.k for r in recs], dtype=np.int64), "1", description="schedule index")
        write(m, "tracking", np.array([r.tracking for r in recs], dtype=np.int64), "1", description="[[tracking]] entry")
        write_strings(m, "type", [r.kind for r in recs])
        write_strings(m, "stations", ["+".join(r.stations) for r in recs])
        write(m, "value", np.array([r.value for r in recs]), "km | km/s | rad", description="computed observable")
        write(m, "elevation_deg", np.array([r.elevation_deg for r in recs]), "deg")
        write(m, "used", np.array([r.used for r in recs], dtype=np.int8), "1", description="0: below the horizon")
        write(m, "sigma", np.array([r.sigma for r in recs]), "km | km/s | rad", description="assumed noise")
        innov = np.array([res.innovation_sigma[r.k, r.row] if r.used else np.nan for r in recs])
        write(m, "innovation_sigma", innov, "km | km/s | rad", description="sqrt(H P- H^T + R), assumed")
        if res.predictions:
            pg = g.create_group("predictions")
            i = 0
            for k, lst in sorted(res.predictions.items()):
                for t_to, Pa, Pt in lst:
                    q = pg.create_group(f"{i:03d}")
                    q.attrs["from_index"] = k
                    write(q, "time_from_s", res.times_s[k], "s")
                    write(q, "time_to_s", t_to, "s")
                    write(q, "assumed", Pa, "labels/units x labels/units")
                    if Pt is not None:
                        write(q, "true", Pt, "labels/units x labels/units")
                    i += 1
        if res.psd_problems:
            write_strings(g, "psd_problems", [f"{res.times_s[k]:.3f} s {ev} {w} {e:.3g}" for k, ev, w, e in res.psd_problems])
        write_provenance(f, provenance(st.deck.source_text, st.source))


def read_team_results(path: str | os.PathLike) -> dict[str, Any]:
    """The main arrays of a results file (for reports and tests)."""
    with h5py.File(path, "r") as f:
        g = f["team"]
        out = {"attrs": dict(g.attrs), "times_s": g["times_s"][()], "event_types": read_str(g["event_types"]),
               "labels": read_str(g["labels/names"]), "units": read_str(g["labels/units"]),
               "roles": read_str(g["labels/roles"])}
        for which in ("assumed", "true"):
            if which in g:
                out[which] = {k: g[which][k][()] for k in ("P_minus", "P_plus", "sigma", "process_noise")}
        out["measurements"] = {k: g["measurements"][k][()] for k in g["measurements"]}
    return out


def write_punch(path: str | os.PathLike, res, indices: list[int]) -> None:
    """Punch knowledge covariances at schedule ``indices`` for a later TEAM run (or TSIM)."""
    st = res.study
    with atomic_h5(path) as f:
        f.attrs["file_kind"] = "fracas-punch"
        f.attrs["schema_version"] = PUNCH_SCHEMA
        f.attrs["trajectory_deck"] = st.traj_deck.source_path or ""
        from fracas.io.stm_file import trajectory_hash

        f.attrs["trajectory_hash"] = trajectory_hash(st.traj_deck)
        f.attrs["epoch_et_s"] = st.problem.epoch_et_s
        for i, k in enumerate(indices):
            g = f.create_group(f"punch_{i:03d}")
            write(g, "time_s", res.times_s[k], "s")
            write(g, "state", res.ref.states[k], "km, km/s, kg")
            write_strings(g, "labels", st.labels)
            write_strings(g, "state_labels", st.state_labels)
            write(g, "assumed", res.Pa_plus[k][: st.layout.n, : st.layout.n], "labels/units x labels/units")
            if res.Pt_plus is not None:
                write(g, "true", res.Pt_plus[k][: st.layout.n, : st.layout.n], "labels/units x labels/units")
        write_provenance(f, provenance(st.deck.source_text, st.source))


def read_punch(path: str | os.PathLike, source: str = "<deck>") -> dict[str, Any]:
    """The last punched covariance of a punch file (DeckError if missing or not a punch file)."""
    p = Path(path)
    if not p.exists():
        raise DeckError(f"{source}: a_priori.from_punch = \"{path}\": no such file")
    try:
        with h5py.File(p, "r") as f:
            if f.attrs.get("file_kind") != "fracas-punch":
                raise DeckError(f"{source}: a_priori.from_punch = \"{path}\": not a fracas punch file")
            keys = sorted(k for k in f if k.startswith("punch_"))
            if not keys:
                raise DeckError(f"{source}: a_priori.from_punch = \"{path}\": holds no punched covariance")
            g = f[keys[-1]]
            out = {"time_s": float(g["time_s"][()]), "labels": read_str(g["labels"]), "assumed": g["assumed"][()],
                   "trajectory_hash": f.attrs.get("trajectory_hash", "")}
            if "true" in g:
                out["true"] = g["true"][()]
            return out
    except OSError as exc:
        raise DeckError(f"{source}: a_priori.from_punch = \"{path}\": cannot read ({exc})") from None
