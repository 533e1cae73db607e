"""The trajectory file (HDF5): one propagation, its optional sensitivities and provenance.

Layout (``docs/trajectory_file.md`` is the reference; every dataset has ``units``)::

    /                       attrs: format = "fracas-trajectory", schema_version, title,
                                   centre, frame = "ICRF", bodies
    /trajectory/            epoch_et_s, t_s, r_km, v_km_s, mass_kg, primary,
                            primary_index, status, t_final_s, r_final_km, v_final_km_s,
                            mass_final_kg, primary_final, n_steps, n_rect, n_reject
                            (attrs: integrator, epoch_tdb)
    /sensitivities/         (optional) t_s, stm, stm_step, par, par_step
    /provenance/            attrs + deck_text + libraries/

Reading and writing go through :class:`TrajectoryData`; failures are
:class:`fracas.errors.StmFileError` naming the file.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import h5py
import numpy as np

from fracas.errors import StmFileError
from fracas.io.hdf5 import (
    Checked,
    atomic_h5,
    attr_strs,
    attr_text,
    one_line,
    open_h5,
    read_provenance,
    schema_version_attr,
    set_attr,
    write,
    write_epoch,
    write_provenance,
)
from fracas.params import STATE_LABELS, STATE_UNITS  # noqa: F401  (re-exported)
from fracas.products import SensitivityData, TrajectoryData  # the products this file stores
from fracas.status import PROPAGATION_STATUSES, STATUS_TEXT, status_text  # noqa: F401  (STATUS_TEXT re-exported)

FORMAT = "fracas-trajectory"
SCHEMA_VERSION = 2  # 2: every dataset carries data_sha256; 1 (no checksums) is still read


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


def _labels_units(
    state: bool, labels: tuple[str, ...], units: tuple[str, ...]
) -> tuple[tuple[str, ...], tuple[str, ...]]:
    return (STATE_LABELS, STATE_UNITS) if state else (tuple(labels), tuple(units))


def _write_matrix(
    g: h5py.Group, name: str, data: np.ndarray, col_labels: Sequence[str], col_units: Sequence[str], meaning: str
) -> None:
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
            write_epoch(g, data.epoch_et_s)
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
            write(g, "n_reject", np.int64(data.n_reject), "1", meaning="steps rejected by the error control")
            set_attr(g, "integrator", data.integrator)

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


def _read_sensitivities(c: Checked, f: h5py.File, n: int) -> SensitivityData:
    """/sensitivities of a file with ``n`` output times, checked."""
    h = f["sensitivities"]
    par = c.num("sensitivities/par", (n, 7, None))
    n_p = par.shape[-1]
    if "sensitivities/t_s" in f:
        c.num("sensitivities/t_s", (n,))
    sens = SensitivityData(
        stm=c.num("sensitivities/stm", (n, 7, 7)),
        stm_step=c.num("sensitivities/stm_step", (n, 7, 7)),
        par=par,
        par_step=c.num("sensitivities/par_step", (n, 7, n_p)),
        param_labels=tuple(attr_strs(h["par"], "col_labels")) if n_p else (),
        param_units=tuple(attr_strs(h["par"], "col_units")) if n_p else (),
    )
    if len(sens.param_labels) != n_p:
        raise c.fail("sensitivities/par", f"{len(sens.param_labels)} col_labels, expected {n_p}")
    return sens


def read_trajectory_file(path: str | os.PathLike, *, verify: bool = True) -> TrajectoryData:
    """Read a file written by :func:`write_trajectory_file`.

    Every dataset is checked (dtype, shapes consistent with ``t_s``, an integer status)
    and, with ``verify`` and a schema-2 file, its SHA-256 checksum.
    One-line StmFileError naming the file and the dataset."""
    src = Path(path)
    if not src.exists():
        raise StmFileError(f"{src}: no such file")
    try:
        with open_h5(src, StmFileError, "fracas trajectory file", checksum=verify) as f:
            fmt = attr_text(f, "format") or ""
            if fmt != FORMAT or "trajectory" not in f:
                raise StmFileError(
                    f"{src}: not a fracas trajectory file (format attribute = {fmt!r}, expected {FORMAT!r})"
                )
            version = schema_version_attr(f, src, StmFileError)
            if version is None or not 1 <= version <= SCHEMA_VERSION:
                raise StmFileError(f"{src}: schema_version = {version}: this fracas reads 1 to {SCHEMA_VERSION}")
            c = Checked(f, src, StmFileError, verify=verify, require_checksum=version >= 2)
            g = f["trajectory"]
            bodies = tuple(attr_strs(f, "bodies"))
            t = c.num("trajectory/t_s", (None,))  # NaN after an early stop
            n = t.shape[0]
            prim = c.strs("trajectory/primary")
            if len(prim) < n:
                raise c.fail("trajectory/primary", f"shape ({len(prim)},), expected ({n},)")
            c.num("trajectory/primary_index", (None,), integer=True)
            status = c.scalar("trajectory/status", integer=True)
            # an unknown code is kept: status_text() names it "unknown status N"
            sens = _read_sensitivities(c, f, n) if "sensitivities" in f else None
            epoch_tdb = attr_text(g, "epoch_tdb") or ""
            return TrajectoryData(
                epoch_et_s=c.scalar("trajectory/epoch_et_s"),
                t_s=t,
                r_km=c.num("trajectory/r_km", (n, 3)),
                v_km_s=c.num("trajectory/v_km_s", (n, 3)),
                mass_kg=c.num("trajectory/mass_kg", (n,)),
                primary=tuple(prim[:n]),
                bodies=bodies,
                t_final_s=c.scalar("trajectory/t_final_s", finite=False),
                r_final_km=c.num("trajectory/r_final_km", (3,)),
                v_final_km_s=c.num("trajectory/v_final_km_s", (3,)),
                mass_final_kg=c.scalar("trajectory/mass_final_kg", finite=False),
                primary_final=c.text("trajectory/primary_final"),
                status=status,
                n_steps=c.scalar("trajectory/n_steps", integer=True),
                n_rect=c.scalar("trajectory/n_rect", integer=True),
                n_reject=c.scalar("trajectory/n_reject", integer=True) if "n_reject" in g else 0,
                integrator=attr_text(g, "integrator") or "",
                centre=attr_text(f, "centre") or "",
                title=attr_text(f, "title") or "",
                epoch_tdb=epoch_tdb,
                sensitivities=sens,
                provenance=read_provenance(f),
            )
    except StmFileError:
        raise
    except (OSError, KeyError, ValueError, TypeError) as exc:
        raise StmFileError(f"{src}: unreadable or incomplete trajectory file: {one_line(exc)}") from None
