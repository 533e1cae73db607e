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

Every refusal is a one-line :class:`fracas.errors.StmFileError` naming the file.
"""

from __future__ import annotations

import hashlib
import os
from collections import Counter
from collections.abc import Sequence
from pathlib import Path

import h5py
import numpy as np

from fracas.constants import BODIES, DAY_S
from fracas.errors import StmFileError
from fracas.io.hdf5 import (
    Checked,
    atomic_h5,
    attr_int,
    attr_text,
    digest_array,
    dtype_name,
    one_line,
    provenance,
    read_provenance,
    set_attr,
    verify_file,
    write,
    write_provenance,
    write_strings,
)
from fracas.params import STATE_LABELS, STATE_UNITS  # noqa: F401  (re-exported)
from fracas.products import (
    SCHEMA_VERSION,
    TIME_TOL_S,
    ReferenceTrajectory,
    _indices,
    chain,
    time_indices,
)

StmData = ReferenceTrajectory  # the STM file holds one reference-trajectory product
FILE_KIND = "fracas-stm"
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


# --------------------------------------------------------------------------- data


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

            g = f.create_group("stm")
            set_attr(g, "state_labels", list(STATE_LABELS))
            set_attr(g, "state_units", list(STATE_UNITS))
            write(
                g,
                "epoch_et_s",
                np.float64(data.epoch_et_s),
                "s",
                meaning="epoch of t = 0, TDB seconds past J2000 (2000-01-01T12:00:00 TDB)",
            )
            write(
                g,
                "times_s",
                np.asarray(data.times_s, np.float64),
                "s",
                meaning="times on the file, s from the epoch, non-decreasing",
            )
            write_strings(g, "event_types", data.event_types, meaning="event type(s) at each time ('+' joins several)")
            write(
                g,
                "states",
                np.asarray(data.states, np.float64),
                "col_units[j]",
                col_labels=list(STATE_LABELS),
                col_units=list(STATE_UNITS),
                meaning="r km, v km/s, m kg relative to primary[i], ICRF",
            )
            write_strings(g, "primary", data.primary, meaning="centre body of states[i]")
            write(
                g,
                "stm_step",
                np.asarray(data.stm_step, np.float64),
                "row_units[i]/col_units[j]",
                col_labels=list(STATE_LABELS),
                col_units=list(STATE_UNITS),
                **mat_attrs,
                meaning="Phi(t_i, t_{i-1}) = dx(t_i)/dx(t_{i-1}); i = 0: from t = 0 to times_s[0]",
                dims="(time, row, col)",
            )
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
            write_provenance(f, data.provenance or provenance(data.deck_text, data.deck_path))
    except OSError as exc:
        raise StmFileError(f"{dest}: cannot write the STM file: {exc.strerror or exc}") from None


# --------------------------------------------------------------------------- read


def _attr_str(obj: h5py.HLObject, key: str, default: str = "") -> str:
    val = attr_text(obj, key)
    return default if val is None else val


def _open(path: str | os.PathLike, verify: bool = True) -> tuple[Path, h5py.File]:
    """Open and check kind and schema (STMRDR's record-0 checks)."""
    src = Path(path)
    if not src.exists():
        raise StmFileError(f"{src}: no such STM file")
    verify_file(src, StmFileError, "fracas STM file", checksum=verify)  # integrity header, or a bounded probe
    try:
        f = h5py.File(src, "r")
    except OSError as exc:
        raise StmFileError(f"{src}: unreadable HDF5 file (truncated or damaged?): {one_line(exc)}") from None
    try:
        if "file_kind" in f.attrs and attr_text(f, "file_kind") is None:
            raise StmFileError(
                f"{src}: attribute file_kind is {type(f.attrs['file_kind']).__name__}, "
                f"expected the string {FILE_KIND!r}"
            )
        kind = _attr_str(f, "file_kind")
        if kind != FILE_KIND:
            other = _attr_str(f, "format")
            what = f"file_kind = {kind!r}" if kind else (f"a {other!r} file" if other else "no file_kind attribute")
            raise StmFileError(f"{src}: not a fracas STM file ({what}, expected file_kind = {FILE_KIND!r})")
        raw = f.attrs.get("schema_version")
        version = attr_int(
            f,
            "schema_version",
            StmFileError(
                f"{src}: attribute schema_version is {type(raw).__name__} ({raw!r}), expected an integer "
                f"({SCHEMA_VERSION}): regenerate with fracas stm build"
            ),
        )
        if version is None:
            raise StmFileError(f"{src}: no schema_version attribute, expected {SCHEMA_VERSION}")
        if version != SCHEMA_VERSION:
            raise StmFileError(
                f"{src}: STM file schema_version = {version}, this fracas reads {SCHEMA_VERSION}: "
                "regenerate with fracas stm build"
            )
    except BaseException:
        f.close()
        raise
    return src, f


def _read_checked(
    src: Path,
    f: h5py.File,
    labels: Sequence[str] | None,
    verify: bool,
) -> StmData:
    c = Checked(f, src, StmFileError, verify=verify)
    file_labels = c.strs("parameters/labels")
    n_p = len(file_labels)
    if len(set(file_labels)) != n_p:
        raise c.fail("parameters/labels", f"repeated labels {file_labels}, expected each parameter once")
    file_units = c.strs("parameters/units", n_p)
    values = c.num("parameters/values", (n_p,), finite=True)
    steps = c.num("parameters/steps", (n_p,))  # NaN: matrices by AD
    if labels is None:
        cols = list(range(n_p))
    else:
        labels = [str(x) for x in labels]
        missing = [x for x in labels if x not in file_labels]
        if missing:
            raise StmFileError(
                f"{src}: parameter{'s' if len(missing) > 1 else ''} {', '.join(missing)} not on the STM file; "
                f"it has {', '.join(file_labels) if file_labels else 'no parameters'}: regenerate it "
                "with every parameter the study solves for, considers or ignores"
            )
        cols = [file_labels.index(x) for x in labels]

    epoch = c.scalar("stm/epoch_et_s")
    t_file = c.num("stm/times_s", (None,), finite=True)
    n = t_file.shape[0]
    if n == 0:
        raise c.fail("stm/times_s", "no times, expected at least one")
    dec = np.flatnonzero(np.diff(t_file) < 0)
    if dec.size:
        k = int(dec[0]) + 1
        raise c.fail(
            "stm/times_s", f"decreases at index {k} ({t_file[k - 1]!r} -> {t_file[k]!r} s), expected non-decreasing"
        )
    events = c.strs("stm/event_types", n)
    prim = c.strs("stm/primary", n)
    unknown = sorted(set(prim) - set(BODIES))
    if unknown:
        raise c.fail(
            "stm/primary",
            f"unknown bod{'ies' if len(unknown) > 1 else 'y'} {unknown}, expected names in fracas.constants.BODIES",
        )
    states = c.num("stm/states", (n, 7), finite=True)
    stm_step = c.num("stm/stm_step", (n, 7, 7), finite=True)
    det = np.linalg.det(stm_step)
    bad = np.flatnonzero(~np.isfinite(det) | (det == 0.0))
    if bad.size:
        raise c.fail(
            "stm/stm_step",
            f"singular step matrix at index {int(bad[0])} (det = {det[bad[0]]!r}), "
            "expected a finite non-zero determinant",
        )
    if t_file[0] == 0.0 and np.max(np.abs(stm_step[0] - np.eye(7))) > 1e-12:
        raise c.fail("stm/stm_step", "stm_step[0] is not the identity although times_s[0] = 0, expected Phi(0, 0) = I")

    name = "stm/par_step"
    ds = c.dataset(name)
    if ds.dtype != np.float64:
        raise c.fail(name, f"dtype {dtype_name(ds.dtype)}, expected float64")
    c._shape(name, tuple(ds.shape), (n_p, n, 7))
    par = np.empty((len(cols), n, 7))
    if c.verify and n_p and "column_sha256" not in ds.attrs:
        raise c.fail(name, "no column_sha256 attribute, expected one SHA-256 checksum per parameter column")
    for j, col in enumerate(cols):  # one chunk per parameter: only the requested columns are read
        try:
            par[j] = ds[col]
        except (OSError, ValueError) as exc:
            raise c.fail(name, f"column {col} unreadable ({exc}), expected float64 data") from None
        c.check_digest(name, ds, digest_array(par[j]), attr="column_sha256", index=col)
    if not np.all(np.isfinite(par)):
        j = int(np.argwhere(~np.isfinite(par))[0][0])
        raise c.fail(name, f"non-finite value in column {cols[j]} ({file_labels[cols[j]]}), expected finite numbers")
    if t_file[0] == 0.0 and par.size and np.max(np.abs(par[:, 0])) > 1e-12:
        raise c.fail(name, "par_step[:, 0] is not zero although times_s[0] = 0, expected Theta(0, 0) = 0")

    deck = c.dataset("trajectory_deck")
    deck_text = c.text("trajectory_deck")
    if verify:
        sha = _attr_str(deck, "text_sha256")
        if sha and sha != hashlib.sha256(deck_text.encode("utf-8")).hexdigest():
            raise c.fail("trajectory_deck", "text_sha256 does not match the deck text, expected equal")
    return StmData(
        times_s=t_file,
        epoch_et_s=epoch,
        event_types=events,
        states=states,
        primary=prim,
        stm_step=stm_step,
        par_step=np.ascontiguousarray(np.transpose(par, (1, 2, 0))),
        param_labels=[file_labels[col] for col in cols],
        param_units=[file_units[col] for col in cols],
        param_values=values[cols] if cols else np.zeros(0),
        param_steps=steps[cols] if cols else np.zeros(0),
        deck_text=deck_text,
        deck_hash=_attr_str(deck, "trajectory_hash"),
        deck_path=_attr_str(deck, "path") or None,
        title=_attr_str(f, "title"),
        centre=_attr_str(f, "centre"),
        frame=_attr_str(f, "frame"),
        fracas_version=_attr_str(f, "fracas_version"),
        schema_version=int(f.attrs["schema_version"]),
        sensitivity_method=_attr_str(f, "sensitivity_method"),
        provenance=read_provenance(f),
        source_path=str(src),
    )


def read_stm_file(
    path: str | os.PathLike,
    labels: Sequence[str] | None = None,
    times_s: Sequence[float] | None = None,
    *,
    epoch_et_s: float | None = None,
    verify: bool = True,
) -> StmData:
    """Read an STM file (FRACAS STMRDR), loading only the parameter columns ``labels``.

    ``labels``: parameter labels in the order the study wants its columns (None: all);
    ``times_s``: times (s from the epoch) the study will ask :func:`chain` for; each must be
    on the file within 1e-6 s (all file times are still returned: chaining needs them);
    ``epoch_et_s``: the study's epoch (TDB s past J2000), refused unless within 1e-6 s of the
    file's; ``verify``: check each dataset's SHA-256 checksum (False skips only that).
    Refuses with a one-line StmFileError naming the file and the dataset: missing file, not
    HDF5, a file changed after fracas wrote it (its integrity header, checked before h5py
    opens it: :func:`fracas.io.hdf5.verify_file`; ``verify=False`` decodes such a file in a
    time-bounded child process first instead), not a fracas STM file, another
    schema_version, a dataset of the wrong dtype or shape, non-finite or decreasing times,
    non-finite states or matrices, a singular step matrix, an unknown primary, a checksum
    mismatch, an unknown label (lists the file's), a time not on the file (names the
    nearest), another epoch.
    """
    src, f = _open(path, verify)
    try:
        with f:
            data = _read_checked(src, f, labels, verify)
    except StmFileError:
        raise
    except KeyError as exc:
        raise StmFileError(f"{src}: incomplete STM file: {one_line(exc)} is missing") from None
    except (OSError, ValueError, IndexError, TypeError, RuntimeError, AttributeError) as exc:
        raise StmFileError(f"{src}: unreadable or incomplete STM file: {type(exc).__name__}: {one_line(exc)}") from None
    if epoch_et_s is not None and not abs(float(epoch_et_s) - data.epoch_et_s) <= TIME_TOL_S:
        raise StmFileError(
            f"{src}: stm/epoch_et_s = {data.epoch_et_s!r} s, expected the study's epoch {float(epoch_et_s)!r} s "
            f"(within {TIME_TOL_S:g} s): regenerate with fracas stm build"
        )
    if times_s is not None:
        _indices(data.times_s, data.event_types, np.atleast_1d(np.asarray(times_s, np.float64)), str(src))
    return data


def check_trajectory(data: StmData, deck_hash: str, path, study_deck: str | None = None) -> None:
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
