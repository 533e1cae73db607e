"""The STM file of TEAM (FRACAS STMGEN / STMRDR, CR-112256 sections 3.2, 5.3.18-19).

One reference trajectory, sampled at every time an error analysis may ever need (the
union of all event schedules), with the state transition matrix Phi and the parameter
transition matrix Theta between consecutive times.  Many studies reuse one file: a study
reads only the parameter columns it uses (STMRDR "entries for unused parameters are passed
over") and multiplies the step matrices over the file times it skips (section 3.2):

    Phi(t_b, t_a)   = Phi_b Phi_{b-1} ... Phi_{a+1}
    Theta(t_b, t_a) = Phi_b Theta(t_{b-1}, t_a) + Theta_b

where Phi_i = Phi(t_i, t_{i-1}) = dx(t_i)/dx(t_{i-1}) and Theta_i = dx(t_i)/dp with
x(t_{i-1}) held fixed (FRACAS PTRAN; here by forward-mode AD).  State order
x y z vx vy vz m in km, km/s, kg, relative to the primary at each time, ICRF axes.

FRACAS STMGEN's record 0 (the parameter list "used by DATA for error checking") becomes
``/parameters``; records 1..N (time, event type, state, Phi, Theta) become ``/stm``; the
ERTRAJ namelist written at the head of the tape becomes ``/trajectory_deck`` with its
canonical hash (:func:`trajectory_hash`), which a study checks (:func:`check_trajectory`).

Layout (``docs/stm_file.md`` is the reference; every dataset has ``units``)::

    /                  attrs: file_kind = "fracas-stm", schema_version, fracas_version,
                              title, centre, frame = "ICRF", sensitivity_method
    /stm/              epoch_et_s, times_s, event_types, states, primary,
                       stm_step (n,7,7), par_step (np,n,7) -- one chunk per parameter
    /parameters/       labels, units, values, steps
    /trajectory_deck   deck TOML text; attrs trajectory_hash, text_sha256, path
    /provenance/       attrs + deck_text + libraries/

Every refusal is a one-line :class:`fracas.errors.StmFileError` naming the file.  This
module writes the file (STMGEN); reading it (STMRDR, :func:`read_stm_file`) is in
:mod:`fracas.io.stm_read`, re-exported here.
"""

from __future__ import annotations

import hashlib
import os
from collections import Counter
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from fracas.constants import DAY_S
from fracas.errors import StmFileError
from fracas.io.hdf5 import (
    atomic_h5,
    digest_array,
    provenance,
    set_attr,
    write,
    write_epoch,
    write_provenance,
    write_strings,
)
from fracas.io.stm_read import FILE_KIND, StmData, read_stm_file
from fracas.params import STATE_LABELS, STATE_UNITS  # noqa: F401  (re-exported)
from fracas.products import (
    SCHEMA_VERSION,
    ReferenceTrajectory,
    chain,
    time_indices,
)

EVENT_TYPES = (
    "initial",
    "measurement",
    "propagation",
    "eigenvector",
    "prediction",
    "thrust_on",
    "thrust_off",
    "guidance",
    "final",
    "grid",
)
SENSITIVITY_METHODS = {
    "ad": "forward-mode automatic differentiation through the integrator (propagate_with_sensitivities)",
    "finite_difference": "central finite differences (FRACAS PTRAN), steps in /parameters/steps",
}

__all__ = [
    "FILE_KIND",
    "SCHEMA_VERSION",
    "STATE_LABELS",
    "STATE_UNITS",
    "StmData",
    "ReferenceTrajectory",
    "chain",
    "check_trajectory",
    "describe",
    "read_stm_file",
    "time_indices",
    "write_stm_file",
]


# --------------------------------------------------------------------------- write


def _validate(data: StmData, dest: Path) -> tuple[int, int]:
    def bad(what: str) -> StmFileError:
        return StmFileError(f"{dest}: cannot write the STM file: {what}")

    t = np.asarray(data.times_s, np.float64)
    if t.ndim != 1 or t.shape[0] == 0:
        raise bad(f"times_s has shape {t.shape}, expected (n,) with n >= 1")
    n = t.shape[0]
    n_p = len(data.param_labels)
    shapes = {
        "states": (np.shape(data.states), (n, 7)),
        "stm_step": (np.shape(data.stm_step), (n, 7, 7)),
        "par_step": (np.shape(data.par_step), (n, 7, n_p)),
        "param_units": ((len(data.param_units),), (n_p,)),
        "param_values": (np.shape(data.param_values), (n_p,)),
        "param_steps": (np.shape(data.param_steps), (n_p,)),
        "event_types": ((len(data.event_types),), (n,)),
        "primary": ((len(data.primary),), (n,)),
    }
    for name, (got, want) in shapes.items():
        if tuple(got) != want:
            raise bad(f"{name} has shape {tuple(got)}, expected {want}")
    if not np.all(np.isfinite(t)) or np.any(np.diff(t) < 0):
        raise bad("times_s must be finite and non-decreasing")
    if len(set(data.param_labels)) != n_p:
        raise bad(f"repeated parameter labels {list(data.param_labels)}")
    if data.sensitivity_method not in SENSITIVITY_METHODS:
        raise bad(f"sensitivity_method = {data.sensitivity_method!r}, expected one of {sorted(SENSITIVITY_METHODS)}")
    return n, n_p


def _write_par_step(g: h5py.Group, data: StmData, n: int, n_p: int, mat_attrs: dict[str, list[str]]) -> h5py.Dataset:
    """/stm/par_step, parameter-major (np, n, 7) with one chunk and one checksum per parameter
    (returned open: see :func:`write_stm_file`)."""
    par = np.ascontiguousarray(np.transpose(np.asarray(data.par_step, np.float64), (2, 0, 1)))
    chunks = (1, n, 7) if n_p else None
    ds = g.create_dataset("par_step", data=par, chunks=chunks)
    ds.attrs["units"] = "row_units[i]/col_units[p]"
    for key, val in {
        "col_labels": list(data.param_labels),
        "col_units": list(data.param_units),
        **mat_attrs,
    }.items():
        set_attr(ds, key, val)
    ds.attrs["meaning"] = (
        "Theta(t_i, t_{i-1}) = dx(t_i)/dp holding x(t_{i-1}) fixed, stored as "
        "par_step[p, i, row]; i = 0: from t = 0 to times_s[0]"
    )
    ds.attrs["dims"] = "(parameter, time, row)"
    set_attr(ds, "column_sha256", [digest_array(par[p]) for p in range(n_p)])
    return ds


def _write_state_columns(g: h5py.Group, name: str, values: np.ndarray, units: str, **attrs: Any) -> h5py.Dataset:
    """A float64 dataset whose columns are the state (col_labels, col_units: x y z vx vy vz m),
    then ``attrs`` in their order."""
    return write(
        g,
        name,
        np.asarray(values, np.float64),
        units,
        col_labels=list(STATE_LABELS),
        col_units=list(STATE_UNITS),
        **attrs,
    )


def _write_stm_group(f: h5py.File, data: StmData, n: int, n_p: int, mat_attrs: dict[str, list[str]]) -> h5py.Dataset:
    """/stm: epoch, times, events, states, primaries and the step matrices; returns par_step, open."""
    g = f.create_group("stm")
    set_attr(g, "state_labels", list(STATE_LABELS))
    set_attr(g, "state_units", list(STATE_UNITS))
    write_epoch(g, data.epoch_et_s)
    write(
        g,
        "times_s",
        np.asarray(data.times_s, np.float64),
        "s",
        meaning="times on the file, s from the epoch, non-decreasing",
    )
    write_strings(g, "event_types", data.event_types, meaning="event type(s) at each time ('+' joins several)")
    _write_state_columns(
        g, "states", data.states, "col_units[j]", meaning="r km, v km/s, m kg relative to primary[i], ICRF"
    )
    write_strings(g, "primary", data.primary, meaning="centre body of states[i]")
    _write_state_columns(
        g,
        "stm_step",
        data.stm_step,
        "row_units[i]/col_units[j]",
        **mat_attrs,
        meaning="Phi(t_i, t_{i-1}) = dx(t_i)/dx(t_{i-1}); i = 0: from t = 0 to times_s[0]",
        dims="(time, row, col)",
    )
    return _write_par_step(g, data, n, n_p, mat_attrs)


def _write_parameters(f: h5py.File, data: StmData, n_p: int) -> None:
    """/parameters: labels, units, nominal values, finite-difference steps."""
    h = f.create_group("parameters")
    write_strings(h, "labels", data.param_labels, meaning="fracas.params labels: columns of par_step")
    write_strings(h, "units", data.param_units, meaning="unit of each parameter")
    write(
        h,
        "values",
        np.asarray(data.param_values, np.float64).reshape(n_p),
        "units[p]",
        meaning="nominal values the trajectory was built with",
    )
    write(
        h,
        "steps",
        np.asarray(data.param_steps, np.float64).reshape(n_p),
        "units[p]",
        meaning="finite-difference perturbations (NaN: matrices by AD)",
    )


def _write_deck(f: h5py.File, data: StmData) -> None:
    """/trajectory_deck: the deck text the file was built from, its hash and path."""
    write(
        f,
        "trajectory_deck",
        str(data.deck_text or ""),
        "none",
        trajectory_hash=data.deck_hash,
        path=data.deck_path or "",
        text_sha256=hashlib.sha256(str(data.deck_text or "").encode("utf-8")).hexdigest(),
        meaning="the trajectory deck (TOML) the file was built from; trajectory_hash "
        "is fracas.io.stm_file.trajectory_hash of the validated deck",
    )


def write_stm_file(path: str | os.PathLike, data: StmData) -> None:
    """Write ``data`` atomically to ``path`` (FRACAS STMGEN's tape; parent directories created).

    ``par_step`` is stored parameter-major, (np, n, 7) with one HDF5 chunk per parameter,
    so :func:`read_stm_file` reads only the columns a study asks for.
    """
    dest = Path(path)
    n, n_p = _validate(data, dest)
    mat_attrs = {"row_labels": list(STATE_LABELS), "row_units": list(STATE_UNITS)}
    try:
        with atomic_h5(dest) as f:
            f.attrs["file_kind"] = FILE_KIND
            f.attrs["schema_version"] = SCHEMA_VERSION
            f.attrs["fracas_version"] = data.fracas_version
            f.attrs["title"] = data.title
            f.attrs["centre"] = data.centre
            f.attrs["frame"] = data.frame
            f.attrs["sensitivity_method"] = data.sensitivity_method
            f.attrs["sensitivity_method_text"] = SENSITIVITY_METHODS[data.sensitivity_method]

            # par_step stays open until the file closes: its chunks are written then, after
            # everything else, as they always were (the file's bytes depend on it)
            par_step = _write_stm_group(f, data, n, n_p, mat_attrs)
            _write_parameters(f, data, n_p)
            _write_deck(f, data)
            write_provenance(f, data.provenance or provenance(data.deck_text, data.deck_path))
            del par_step
    except OSError as exc:
        raise StmFileError(f"{dest}: cannot write the STM file: {exc.strerror or exc}") from None


def check_trajectory(data: StmData, deck_hash: str, path: str | os.PathLike, study_deck: str | None = None) -> None:
    """StmFileError unless the file was built from the study's trajectory deck.

    ``deck_hash``: :func:`trajectory_hash` of the study's trajectory deck; ``path``: the STM
    file (for the message); ``study_deck``: where the study's deck came from (optional).
    """
    if data.deck_hash == deck_hash:
        return
    study = f" ({study_deck})" if study_deck else ""
    raise StmFileError(
        f"{path}: built from another trajectory: file's deck {data.deck_path or '<unknown>'} has hash "
        f"{data.deck_hash[:12]}, the study's trajectory deck{study} has {str(deck_hash)[:12]}: "
        "regenerate the STM file from the study's deck or point the study at the file's deck"
    )


# --------------------------------------------------------------------------- chain


def describe(path: str | os.PathLike) -> str:
    """Readable multi-line summary of an STM file (``fracas stm info FILE``); the file is
    checked as by :func:`read_stm_file` first."""
    from fracas.timescales import et_to_calendar

    d = read_stm_file(path)
    src = Path(path)
    t, prov = d.times_s, d.provenance or {}
    lines = [
        f"STM file     {src}",
        f"title        {d.title or '-'}",
        f"trajectory   {d.deck_path or '<unknown deck>'} (hash {d.deck_hash[:16]})",
        f"epoch        {et_to_calendar(d.epoch_et_s)} TDB ({d.epoch_et_s:.3f} s past J2000)",
        (
            f"span         {t[0] / DAY_S:.6f} to {t[-1] / DAY_S:.6f} d ({(t[-1] - t[0]) / DAY_S:.6f} d), "
            f"centre {d.centre or '-'}, frame {d.frame}"
        ),
        f"primaries    {', '.join(dict.fromkeys(d.primary))}",
        f"times        {t.shape[0]}: " + ", ".join(f"{c} {e}" for e, c in sorted(Counter(d.event_types).items())),
        f"parameters   {len(d.param_labels)} (matrices by {d.sensitivity_method})",
    ]
    lines += [f"  {lab:<28s} {val: .10g} {u}" for lab, u, val in zip(d.param_labels, d.param_units, d.param_values)]
    lines += [
        f"file size    {src.stat().st_size / 1024:.1f} KiB (SHA-256 checksums verified)",
        (
            f"written by   fracas {d.fracas_version} at {prov.get('created_utc', '?')}, "
            f"schema_version {d.schema_version}"
        ),
    ]
    return "\n".join(lines)
