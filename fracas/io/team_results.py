"""TEAM results file and punched knowledge covariances (HDF5, atomic; layout in docs/team_results.md).

Serialises a :class:`fracas.products.TeamProduct` and reads results files back for reports;
no numerics here."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from fracas.errors import DeckError, ResultsFileError
from fracas.io.hdf5 import atomic_h5, read_str, write, write_provenance, write_strings
from fracas.products import CovarianceHistory, TeamProduct
from fracas.status import status_text

__all__ = ["write_team_results", "read_team_results", "write_punch", "read_punch", "RESULTS_SCHEMA", "PUNCH_SCHEMA"]

RESULTS_SCHEMA = 1
PUNCH_SCHEMA = 1


def _write_history(h: h5py.Group, c: CovarianceHistory) -> None:
    write(h, "P_minus", c.P_minus, "labels/units x labels/units", description="covariance before the event")
    write(h, "P_plus", c.P_plus, "labels/units x labels/units", description="covariance after the event")
    write(
        h,
        "process_noise",
        c.process_noise,
        "state units^2",
        description="effective process noise over the interval ending here",
    )
    write(h, "sigma", c.sigma, "labels/units", description="1-sigma after each event")
    write(h, "a_priori_sigma", c.a_priori_sigma, "labels/units", description="1-sigma of the a-priori covariance")
    if c.event_status is not None:
        write(
            h,
            "event_status",
            np.asarray(c.event_status, dtype=np.int64),
            "1",
            description="fracas.status.RunStatus of P_plus at each event (0 OK, 6 not positive-definite, 7 non-finite)",
        )
    e = c.eigen
    eg = h.create_group("eigenvector_events")
    write(eg, "index", np.asarray(e.index, dtype=np.int64), "1")
    if len(e.index):
        write(eg, "position_eigenvalues", e.position_eigenvalues, "km^2")
        write(eg, "position_eigenvectors", e.position_eigenvectors, "1", description="columns")
        write(eg, "velocity_eigenvalues", e.velocity_eigenvalues, "km^2/s^2")
        write(eg, "velocity_eigenvectors", e.velocity_eigenvectors, "1", description="columns")
        write(eg, "correlations", e.correlations, "1")


def write_team_results(path: str | os.PathLike, res: TeamProduct) -> None:
    """Write the full event history of a TEAM run (a :class:`fracas.products.TeamProduct`)."""
    st = res.settings
    with atomic_h5(path) as f:
        f.attrs["file_kind"] = "fracas-team-results"
        f.attrs["schema_version"] = RESULTS_SCHEMA
        g = f.create_group("team")
        for k, v in (
            ("title", res.title),
            ("filter", st["filter"]),
            ("propagation", st["propagation"]),
            ("square_root", int(st["square_root"])),
            ("generalized_covariance", int(st["generalized_covariance"])),
            ("reference", st["reference"]),
            ("trajectory_deck", st.get("trajectory_deck", "")),
        ):
            g.attrs[k] = v
        g.attrs["epoch_et_s"] = res.epoch_et_s
        g.attrs["source"] = res.source
        g.attrs["status"] = int(res.status)
        g.attrs["status_text"] = status_text(res.status)
        g.attrs["n_state"] = int(res.n_state)
        g.attrs["min_elevation_deg"] = float(st.get("min_elevation_deg", 0.0))
        g.attrs["trajectory_hash"] = st.get("trajectory_hash", "")
        pr = g.create_group("print")
        for k, v in st.get("print", {}).items():
            pr.attrs[k] = v
        tg = g.create_group("timing")
        for k, v in res.timing.items():
            tg.attrs[k] = float(v)
        write(g, "times_s", res.times_s, "s", description="schedule times from the trajectory epoch")
        write_strings(g, "event_types", res.event_types, description="events at each time, in order")
        write(g, "states", res.states, "km, km/s, kg", description="reference r, v, m rel. primary (ICRF)")
        write_strings(g, "primary", res.primary)
        lab = g.create_group("labels")
        write_strings(lab, "names", res.labels)
        write_strings(lab, "units", res.units)
        write_strings(lab, "roles", res.roles)
        tr = g.create_group("tracking")
        write_strings(tr, "type", [t for t, _ in res.tracking], description="[[tracking]] entries in deck order")
        write_strings(tr, "stations", [s for _, s in res.tracking])
        for which, c in (("assumed", res.assumed), ("true", res.true)):
            if c is not None:
                _write_history(g.create_group(which), c)
        m = g.create_group("measurements")
        ml = res.measurements
        write(m, "index", ml.index, "1", description="schedule index")
        write(m, "tracking", ml.tracking, "1", description="[[tracking]] entry")
        write_strings(m, "type", ml.kind)
        write_strings(m, "stations", ml.stations)
        write(m, "value", ml.value, "km | km/s | rad", description="computed observable")
        write(m, "elevation_deg", ml.elevation_deg, "deg")
        write(m, "used", ml.used.astype(np.int8), "1", description="0: below the horizon")
        write(m, "sigma", ml.sigma, "km | km/s | rad", description="assumed noise")
        write(m, "innovation_sigma", ml.innovation_sigma, "km | km/s | rad", description="sqrt(H P- H^T + R), assumed")
        if res.predictions:
            pg = g.create_group("predictions")
            for i, p in enumerate(res.predictions):
                q = pg.create_group(f"{i:03d}")
                q.attrs["from_index"] = p.from_index
                q.attrs["status"] = int(p.status)
                write(q, "time_from_s", p.time_from_s, "s")
                write(q, "time_to_s", p.time_to_s, "s")
                write(q, "assumed", p.assumed, "labels/units x labels/units")
                if p.true is not None:
                    write(q, "true", p.true, "labels/units x labels/units")
        if res.psd_problems:
            write_strings(
                g, "psd_problems", [f"{res.times_s[k]:.3f} s {ev} {w} {e:.3g}" for k, ev, w, e in res.psd_problems]
            )
            pp = g.create_group("psd_events")
            write(pp, "index", np.array([k for k, _, _, _ in res.psd_problems], dtype=np.int64), "1")
            write_strings(pp, "event", [e for _, e, _, _ in res.psd_problems])
            write_strings(pp, "which", [w for _, _, w, _ in res.psd_problems])
            write(pp, "min_eigenvalue", np.array([e for _, _, _, e in res.psd_problems]), "mixed")
        write_provenance(f, res.provenance)


def _history(h: h5py.Group) -> dict[str, Any]:
    out = {
        k: h[k][()] for k in ("P_minus", "P_plus", "sigma", "process_noise", "a_priori_sigma", "event_status") if k in h
    }
    eg = h["eigenvector_events"]
    out["eigenvector_events"] = {k: eg[k][()] for k in eg}
    return out


def read_team_results(path: str | os.PathLike) -> dict[str, Any]:
    """Everything a report needs from a results file (``docs/team_results.md``), as a dict.

    A missing file, another kind of file or a damaged one: one-line ResultsFileError."""
    p = Path(path)
    if not p.exists():
        raise ResultsFileError(f"{p}: no such results file")
    try:
        with h5py.File(p, "r") as f:
            if f.attrs.get("file_kind") != "fracas-team-results":
                raise ResultsFileError(
                    f"{p}: not a fracas TEAM results file (file_kind = {f.attrs.get('file_kind')!r})"
                )
            g = f["team"]
            out = {
                "path": str(p),
                "attrs": dict(g.attrs),
                "times_s": g["times_s"][()],
                "event_types": read_str(g["event_types"]),
                "labels": read_str(g["labels/names"]),
                "units": read_str(g["labels/units"]),
                "roles": read_str(g["labels/roles"]),
                "states": g["states"][()],
                "primary": read_str(g["primary"]),
                "print": dict(g["print"].attrs) if "print" in g else {},
                "timing": dict(g["timing"].attrs) if "timing" in g else {},
            }
            out["tracking"] = (
                list(zip(read_str(g["tracking/type"]), read_str(g["tracking/stations"]))) if "tracking" in g else []
            )
            for which in ("assumed", "true"):
                if which in g:
                    out[which] = _history(g[which])
            out["measurements"] = {k: g["measurements"][k][()] for k in g["measurements"]}
            for k in ("type", "stations"):
                out["measurements"][k] = read_str(g["measurements"][k])
            preds = []
            if "predictions" in g:
                for name in sorted(g["predictions"]):
                    q = g["predictions"][name]
                    preds.append(
                        {
                            "from_index": int(q.attrs["from_index"]),
                            "status": int(q.attrs.get("status", 0)),
                            "time_from_s": float(q["time_from_s"][()]),
                            "time_to_s": float(q["time_to_s"][()]),
                            "assumed": q["assumed"][()],
                            "true": q["true"][()] if "true" in q else None,
                        }
                    )
            out["predictions"] = preds
            psd = []
            if "psd_events" in g:
                pp = g["psd_events"]
                psd = list(
                    zip(
                        pp["index"][()].tolist(),
                        read_str(pp["event"]),
                        read_str(pp["which"]),
                        pp["min_eigenvalue"][()].tolist(),
                    )
                )
            out["psd_problems"] = psd
        return out
    except ResultsFileError:
        raise
    except (OSError, KeyError, ValueError, TypeError) as exc:
        raise ResultsFileError(f"{p}: unreadable or incomplete TEAM results file: {exc}") from None


def write_punch(path: str | os.PathLike, res: TeamProduct, indices: list[int] | None = None) -> None:
    """Punch knowledge covariances at schedule ``indices`` (default: the punch events) for a
    later TEAM run (or TSIM)."""
    idx = res.punch_indices if indices is None else indices
    n = sum(r != "noise_state" for r in res.roles)  # PDOT's noise states are not punched
    nx = res.n_state
    with atomic_h5(path) as f:
        f.attrs["file_kind"] = "fracas-punch"
        f.attrs["schema_version"] = PUNCH_SCHEMA
        f.attrs["trajectory_deck"] = res.settings.get("trajectory_deck", "")
        f.attrs["trajectory_hash"] = res.settings.get("trajectory_hash", "")
        f.attrs["epoch_et_s"] = res.epoch_et_s
        for i, k in enumerate(idx):
            g = f.create_group(f"punch_{i:03d}")
            write(g, "time_s", res.times_s[k], "s")
            write(g, "state", res.states[k], "km, km/s, kg")
            write_strings(g, "labels", res.labels[nx:n])
            write_strings(g, "state_labels", res.labels[:nx])
            write(g, "assumed", res.assumed.P_plus[k][:n, :n], "labels/units x labels/units")
            if res.true is not None:
                write(g, "true", res.true.P_plus[k][:n, :n], "labels/units x labels/units")
        write_provenance(f, res.provenance)


def read_punch(path: str | os.PathLike, source: str = "<deck>") -> dict[str, Any]:
    """The last punched covariance of a punch file (DeckError if missing or not a punch file)."""
    p = Path(path)
    if not p.exists():
        raise DeckError(f'{source}: a_priori.from_punch = "{path}": no such file')
    try:
        with h5py.File(p, "r") as f:
            if f.attrs.get("file_kind") != "fracas-punch":
                raise DeckError(f'{source}: a_priori.from_punch = "{path}": not a fracas punch file')
            keys = sorted(k for k in f if k.startswith("punch_"))
            if not keys:
                raise DeckError(f'{source}: a_priori.from_punch = "{path}": holds no punched covariance')
            g = f[keys[-1]]
            out = {
                "time_s": float(g["time_s"][()]),
                "labels": read_str(g["labels"]),
                "assumed": g["assumed"][()],
                "trajectory_hash": f.attrs.get("trajectory_hash", ""),
            }
            if "true" in g:
                out["true"] = g["true"][()]
            return out
    except OSError as exc:
        raise DeckError(f'{source}: a_priori.from_punch = "{path}": cannot read ({exc})') from None
