"""Reading the STM file of TEAM (FRACAS STMRDR, CR-112256 section 5.3.19): the kind and
schema checks of record 0, then every dataset checked (dtype, shape, finiteness, the
step matrices' determinants, SHA-256 checksums) and only the parameter columns a study
asks for read.  The layout: :mod:`fracas.io.stm_file` (``docs/stm_file.md``).

Every refusal is a one-line :class:`fracas.errors.StmFileError` naming the file.
Re-exported by :mod:`fracas.io.stm_file`.
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Sequence
from pathlib import Path

import h5py
import numpy as np

from fracas.constants import BODIES
from fracas.errors import StmFileError
from fracas.io.hdf5 import (
    Checked,
    attr_int,
    attr_text,
    digest_array,
    dtype_name,
    h5_errors,
    one_line,
    read_provenance,
    verify_file,
)
from fracas.io.inputs import note_input
from fracas.products import SCHEMA_VERSION, TIME_TOL_S, ReferenceTrajectory, _indices

StmData = ReferenceTrajectory  # the STM file holds one reference-trajectory product
#: the STM file's kind tag (its root attribute file_kind), written by fracas.io.stm_file
FILE_KIND = "fracas-stm"


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


def _columns(
    c: Checked, src: Path, labels: Sequence[str] | None
) -> tuple[list[str], list[str], np.ndarray, np.ndarray, list[int]]:
    """(file labels, file units, values, steps, the file columns of ``labels``) of /parameters."""
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
    return file_labels, file_units, values, steps, cols


def _times(c: Checked) -> tuple[float, np.ndarray, list[str], list[str]]:
    """(epoch, times, event types, primaries) of /stm, checked."""
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
    return epoch, t_file, events, prim


def _stm_step(c: Checked, t_file: np.ndarray) -> np.ndarray:
    """/stm/stm_step, checked: finite, non-singular, the identity at t = 0."""
    n = t_file.shape[0]
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
    return stm_step


def _par_step(c: Checked, cols: list[int], file_labels: list[str], t_file: np.ndarray) -> np.ndarray:
    """The columns ``cols`` of /stm/par_step, (len(cols), n, 7), each checked against its checksum."""
    n, n_p = t_file.shape[0], len(file_labels)
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
    return par


def _read_checked(
    src: Path,
    f: h5py.File,
    labels: Sequence[str] | None,
    verify: bool,
) -> StmData:
    c = Checked(f, src, StmFileError, verify=verify)
    file_labels, file_units, values, steps, cols = _columns(c, src, labels)
    epoch, t_file, events, prim = _times(c)
    states = c.num("stm/states", (t_file.shape[0], 7), finite=True)
    stm_step = _stm_step(c, t_file)
    par = _par_step(c, cols, file_labels, t_file)

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
    note_input(path)  # an input of the run: no output may replace it
    with h5_errors(src, StmFileError, "STM file"), f:
        data = _read_checked(src, f, labels, verify)
    if epoch_et_s is not None and not abs(float(epoch_et_s) - data.epoch_et_s) <= TIME_TOL_S:
        raise StmFileError(
            f"{src}: stm/epoch_et_s = {data.epoch_et_s!r} s, expected the study's epoch {float(epoch_et_s)!r} s "
            f"(within {TIME_TOL_S:g} s): regenerate with fracas stm build"
        )
    if times_s is not None:
        _indices(data.times_s, data.event_types, np.atleast_1d(np.asarray(times_s, np.float64)), str(src))
    return data
