"""The trajectory file (HDF5): one propagation, its optional sensitivities and provenance.

Layout (``docs/trajectory_file.md`` is the reference; every dataset has ``units``)::

    /                       attrs: format = "fracas-trajectory", schema_version, title,
                                   centre, frame = "ICRF", bodies
    /trajectory/            epoch_et_s, t_s, r_km, v_km_s, mass_kg, primary,
                            primary_index, status, t_final_s, r_final_km, v_final_km_s,
                            mass_final_kg, primary_final, n_steps, n_rect
    /sensitivities/         (optional) t_s, stm, stm_step, par, par_step
    /provenance/            attrs + deck_text + libraries/

Reading and writing go through :class:`TrajectoryData`; failures are
:class:`fracas.errors.StmFileError` naming the file.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from fracas.errors import StmFileError
from fracas.io.hdf5 import (
    atomic_h5,
    attr_strs,
    read_provenance,
    read_str,
    set_attr,
    write,
    write_provenance,
)
from fracas.params import STATE_LABELS, STATE_UNITS  # noqa: F401  (re-exported)
from fracas.products import SensitivityData, TrajectoryData  # the products this file stores
from fracas.status import PROPAGATION_STATUSES, STATUS_TEXT, status_text  # noqa: F401  (STATUS_TEXT re-exported)

FORMAT = "fracas-trajectory"
SCHEMA_VERSION = 1


__all__ = [
    "FORMAT",
    "SCHEMA_VERSION",
    "STATE_LABELS",
    "STATE_UNITS",
    "STATUS_TEXT",
    "SensitivityData",
    "TrajectoryData",
    "write_trajectory_file",
    "read_trajectory_file",
]


def _labels_units(state: bool, labels: tuple[str, ...], units: tuple[str, ...]):
    return (STATE_LABELS, STATE_UNITS) if state else (tuple(labels), tuple(units))


def _write_matrix(g: h5py.Group, name: str, data: np.ndarray, col_labels, col_units, meaning: str) -> None:
    write(
        g,
        name,
        np.asarray(data, dtype=np.float64),
        "row_units[i]/col_units[j]",
        row_labels=list(STATE_LABELS),
        row_units=list(STATE_UNITS),
        col_labels=list(col_labels),
        col_units=list(col_units),
        meaning=meaning,
    )


def write_trajectory_file(path: str | os.PathLike, data: TrajectoryData) -> Path:
    """Write ``data`` atomically to ``path`` (parent directories created). Returns the path."""
    dest = Path(path)
    try:
        with atomic_h5(dest) as f:
            f.attrs["format"] = FORMAT
            f.attrs["schema_version"] = SCHEMA_VERSION
            f.attrs["title"] = data.title
            f.attrs["centre"] = data.centre
            f.attrs["frame"] = "ICRF"
            set_attr(f, "bodies", list(data.bodies))

            g = f.create_group("trajectory")
            g.attrs["epoch_tdb"] = data.epoch_tdb
            write(
                g,
                "epoch_et_s",
                np.float64(data.epoch_et_s),
                "s",
                meaning="epoch of t = 0, TDB seconds past J2000 (2000-01-01T12:00:00 TDB)",
            )
            write(
                g,
                "t_s",
                np.asarray(data.t_s, np.float64),
                "s",
                meaning="output times from the epoch (NaN after an early stop)",
            )
            write(g, "r_km", np.asarray(data.r_km, np.float64), "km", meaning="position relative to primary, ICRF")
            write(
                g, "v_km_s", np.asarray(data.v_km_s, np.float64), "km/s", meaning="velocity relative to primary, ICRF"
            )
            write(g, "mass_kg", np.asarray(data.mass_kg, np.float64), "kg", meaning="spacecraft mass")
            write(g, "primary", list(data.primary) or [""], "none", meaning="name of the centre of r_km, v_km_s")
            idx = [data.bodies.index(p) if p in data.bodies else -1 for p in data.primary]
            write(g, "primary_index", np.asarray(idx, np.int32), "1", meaning="index into /@bodies (-1 undefined)")
            write(
                g,
                "status",
                np.int32(data.status),
                "1",
                meaning="; ".join(f"{int(k)} {k.text}" for k in PROPAGATION_STATUSES),
            )
            write(g, "t_final_s", np.float64(data.t_final_s), "s", meaning="time where the propagation ended")
            write(g, "r_final_km", np.asarray(data.r_final_km, np.float64), "km")
            write(g, "v_final_km_s", np.asarray(data.v_final_km_s, np.float64), "km/s")
            write(g, "mass_final_kg", np.float64(data.mass_final_kg), "kg")
            write(g, "primary_final", data.primary_final, "none")
            write(g, "n_steps", np.int64(data.n_steps), "1", meaning="integration steps taken")
            write(g, "n_rect", np.int64(data.n_rect), "1", meaning="Encke rectifications")

            s = data.sensitivities
            if s is not None:
                h = f.create_group("sensitivities")
                set_attr(h, "state_labels", list(STATE_LABELS))
                write(
                    h,
                    "t_s",
                    np.asarray(data.t_s, np.float64),
                    "s",
                    meaning="times of the matrices (as /trajectory/t_s)",
                )
                _write_matrix(h, "stm", s.stm, STATE_LABELS, STATE_UNITS, "Phi(t_k, t_0) = dx(t_k)/dx(t_0)")
                _write_matrix(
                    h, "stm_step", s.stm_step, STATE_LABELS, STATE_UNITS, "Phi(t_k, t_{k-1}) (identity at k = 0)"
                )
                pl, pu = tuple(s.param_labels), tuple(s.param_units)
                _write_matrix(h, "par", s.par, pl, pu, "dx(t_k)/dp from t_0")
                _write_matrix(h, "par_step", s.par_step, pl, pu, "dx(t_k)/dp holding x(t_{k-1}) fixed")

            write_provenance(f, data.provenance)
    except OSError as exc:
        raise StmFileError(f"{dest}: cannot write the trajectory file: {exc.strerror or exc}") from None
    return dest


def _scalar(ds: h5py.Dataset) -> Any:
    return ds[()].item() if hasattr(ds[()], "item") else ds[()]


def read_trajectory_file(path: str | os.PathLike) -> TrajectoryData:
    """Read a file written by :func:`write_trajectory_file`."""
    src = Path(path)
    if not src.exists():
        raise StmFileError(f"{src}: no such file")
    try:
        with h5py.File(src, "r") as f:
            fmt = f.attrs.get("format", "")
            if isinstance(fmt, bytes):
                fmt = fmt.decode()
            if fmt != FORMAT or "trajectory" not in f:
                raise StmFileError(
                    f"{src}: not a fracas trajectory file (format attribute = {fmt!r}, expected {FORMAT!r})"
                )
            version = int(f.attrs.get("schema_version", -1))
            if version > SCHEMA_VERSION:
                raise StmFileError(f"{src}: schema_version = {version}: this fracas reads up to {SCHEMA_VERSION}")
            g = f["trajectory"]
            bodies = tuple(attr_strs(f, "bodies"))
            prim = read_str(g["primary"])
            prim = tuple([prim] if isinstance(prim, str) else prim)
            n = g["t_s"].shape[0]
            sens = None
            if "sensitivities" in f:
                h = f["sensitivities"]
                sens = SensitivityData(
                    stm=h["stm"][()],
                    stm_step=h["stm_step"][()],
                    par=h["par"][()],
                    par_step=h["par_step"][()],
                    param_labels=tuple(attr_strs(h["par"], "col_labels")) if h["par"].shape[-1] else (),
                    param_units=tuple(attr_strs(h["par"], "col_units")) if h["par"].shape[-1] else (),
                )
            epoch_tdb = g.attrs.get("epoch_tdb", "")
            return TrajectoryData(
                epoch_et_s=float(_scalar(g["epoch_et_s"])),
                t_s=g["t_s"][()],
                r_km=g["r_km"][()],
                v_km_s=g["v_km_s"][()],
                mass_kg=g["mass_kg"][()],
                primary=prim[:n],
                bodies=bodies,
                t_final_s=float(_scalar(g["t_final_s"])),
                r_final_km=g["r_final_km"][()],
                v_final_km_s=g["v_final_km_s"][()],
                mass_final_kg=float(_scalar(g["mass_final_kg"])),
                primary_final=read_str(g["primary_final"]),
                status=int(_scalar(g["status"])),
                n_steps=int(_scalar(g["n_steps"])),
                n_rect=int(_scalar(g["n_rect"])),
                centre=str(f.attrs.get("centre", "")),
                title=str(f.attrs.get("title", "")),
                epoch_tdb=epoch_tdb.decode() if isinstance(epoch_tdb, bytes) else str(epoch_tdb),
                sensitivities=sens,
                provenance=read_provenance(f),
            )
    except StmFileError:
        raise
    except (OSError, KeyError, ValueError) as exc:
        raise StmFileError(f"{src}: unreadable or incomplete trajectory file: {exc}") from None
