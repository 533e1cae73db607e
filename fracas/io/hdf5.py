"""HDF5 helpers shared by every fracas file: atomic writes sealed by an integrity header,
labelled and checksummed datasets, checked reading, provenance.

Writes are atomic (:mod:`fracas.io.atomic`): the file is built under a temporary name
``.<name>.<pid>-<host>.<random>.tmp`` in the destination directory, flushed and ``fsync``-ed, given
the user's normal permissions, then moved over the destination with ``os.replace``.  A
failure or a kill at any point leaves a previous file at the destination untouched.

**Integrity header.**  Every file :func:`atomic_h5` writes starts with a 512-byte HDF5 user
block that :func:`seal` fills with the file's kind, length and SHA-256; every reader checks
it (:func:`verify_file`, :func:`open_h5`) before h5py opens the file, and decodes a file
without it only in a time-bounded child process.  Those checks live in
:mod:`fracas.io.hdf5_integrity` (``docs/hdf5_integrity.md``) and are re-exported here.

Every dataset written by :func:`write` / :func:`write_strings` also carries ``data_sha256``, the
SHA-256 of its bytes (:func:`digest_array`, :func:`digest_strings`); :class:`Checked` reads
datasets back verifying dtype, shape, finiteness and that checksum (this names the damaged
dataset in files without the integrity header); both live in :mod:`fracas.io.hdf5_checked`
and are re-exported here.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import functools
import hashlib
import os
import platform
import sys
from collections.abc import Iterable, Iterator
from importlib import metadata
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from fracas.errors import ResultsFileError
from fracas.io.atomic import atomic_path
from fracas.io.hdf5_checked import CHECKSUM_ATTR, Checked, digest_array, digest_strings, dtype_name
from fracas.io.hdf5_integrity import (
    HDF5_SIGNATURE,
    MAGIC,
    PROBE_DEFAULT_S,
    PROBE_ENV,
    USERBLOCK_SIZE,
    ErrorType,
    _opened,
    file_problem,
    h5_errors,
    one_line,
    open_h5,
    probe_timeout_s,
    seal,
    verify_file,
)
from fracas.io.inputs import path_text

__all__ = [
    "CHECKSUM_ATTR",
    "Checked",
    "EPOCH_MEANING",
    "ErrorType",
    "HDF5_SIGNATURE",
    "LIBRARIES",
    "MAGIC",
    "PROBE_DEFAULT_S",
    "PROBE_ENV",
    "STR",
    "USERBLOCK_SIZE",
    "atomic_h5",
    "attr_int",
    "attr_strs",
    "attr_text",
    "digest_array",
    "digest_strings",
    "dtype_name",
    "file_problem",
    "h5_errors",
    "kind_attr",
    "library_versions",
    "one_line",
    "open_h5",
    "probe_timeout_s",
    "provenance",
    "read_kind",
    "read_provenance",
    "read_str",
    "schema_version",
    "schema_version_attr",
    "seal",
    "set_attr",
    "verify_file",
    "write",
    "write_epoch",
    "write_provenance",
    "write_strings",
]

STR = h5py.string_dtype(encoding="utf-8")
LIBRARIES = ("numpy", "scipy", "jax", "jaxlib", "h5py", "pydantic", "click", "rich", "matplotlib", "jplephem", "de421")
_KIND_ATTRS = ("file_kind", "format", "kind")


@contextlib.contextmanager
def atomic_h5(path: str | os.PathLike) -> Iterator[h5py.File]:
    """``with atomic_h5(path) as f:`` -- write an HDF5 file that appears complete or not at all,
    sealed by the integrity header (:func:`seal`).

    Built on :func:`fracas.io.atomic.atomic_path`: the parent directory is created if
    needed, the file gets the user's normal permissions; on any exception inside the block
    (or while closing/flushing/sealing) the temporary file is removed and the exception
    propagates.  The header's kind tag is the root attribute ``file_kind`` (or ``format``,
    ``kind``) as the block left it.
    """
    with atomic_path(path) as tmp:
        # built in memory (the core driver, no backing store), then written with plain Python
        # I/O: a full disk is an OSError here, never an HDF5 write failing inside h5py (which
        # printed pages of "Exception ignored" and could crash the process on close); the
        # bytes are those the file driver would have written
        f = h5py.File(tmp, "w", driver="core", backing_store=False, userblock_size=USERBLOCK_SIZE)
        try:
            yield f
            kind = kind_attr(f)
            f.flush()
            image = f.id.get_file_image()
        finally:
            f.close()
        _write_image(tmp, image)
        del image
        seal(tmp, kind)


def _write_image(tmp: Path, image: bytes) -> None:
    """The user block (zeros, :func:`seal` fills it) and the HDF5 image into ``tmp``."""
    view = memoryview(image)
    with open(tmp, "wb") as fh:
        fh.write(bytes(USERBLOCK_SIZE))
        for start in range(0, len(view), 1 << 24):
            fh.write(view[start : start + (1 << 24)])


def kind_attr(f: h5py.File) -> str:
    """The kind tag of an open file: its ``file_kind``, ``format`` or ``kind`` root attribute ("" if none)."""
    for key in _KIND_ATTRS:
        val = attr_text(f, key)
        if val:
            return val
    return ""


def read_kind(path: str | os.PathLike, error: ErrorType = ResultsFileError, what: str = "results file") -> str:
    """The kind of a fracas file (its ``file_kind``, ``format`` or ``kind`` root attribute),
    read after :func:`verify_file`'s checks; "" when it names none.  A sealed file's integrity
    header names its kind too; one that names another (a header rewritten after fracas wrote
    the file: forged) is refused, so that no file is called what only its header claims."""
    tag = verify_file(path, error, what)
    with _opened(Path(path), error, what) as f:
        kind = kind_attr(f)
    if tag and tag != "".join(c if " " <= c <= "~" else "?" for c in kind)[:100]:
        raise error(
            f"{path}: its integrity header says kind {tag!r} but the file itself says {kind or 'none'!r} "
            f"(the header was rewritten after fracas wrote the file); not a {what} fracas can read"
        )
    return kind


EPOCH_MEANING = "epoch of t = 0, TDB seconds past J2000 (2000-01-01T12:00:00 TDB)"


def write_epoch(group: h5py.Group, epoch_et_s: float) -> h5py.Dataset:
    """Dataset ``epoch_et_s`` (float64, s): the epoch of t = 0, TDB seconds past J2000."""
    return write(group, "epoch_et_s", np.float64(epoch_et_s), "s", meaning=EPOCH_MEANING)


def write_strings(
    group: h5py.Group, name: str, values: Iterable[Any], units: str = "none", **attrs: Any
) -> h5py.Dataset:
    """A 1-D UTF-8 string dataset (empty lists included) with a ``units`` attribute."""
    vals = [str(v) for v in values]
    if vals:
        ds = group.create_dataset(name, data=np.array(vals, dtype=object), dtype=STR)
    else:
        ds = group.create_dataset(name, shape=(0,), dtype=STR)
    ds.attrs["units"] = units
    ds.attrs[CHECKSUM_ATTR] = digest_strings(vals)
    for key, val in attrs.items():
        set_attr(ds, key, val)
    return ds


def write(group: h5py.Group, name: str, data: Any, units: str, **attrs: Any) -> h5py.Dataset:
    """Create dataset ``name`` with a ``units`` attribute (``"1"``: dimensionless,
    ``"none"``: text or labels) and any further attributes."""
    if isinstance(data, str):
        ds = group.create_dataset(name, data=data, dtype=STR)
        ds.attrs[CHECKSUM_ATTR] = digest_strings(data)
    elif isinstance(data, (list, tuple)) and data and all(isinstance(x, str) for x in data):
        return write_strings(group, name, data, units, **attrs)
    else:
        arr = np.asarray(data)
        ds = group.create_dataset(name, data=arr)
        ds.attrs[CHECKSUM_ATTR] = digest_array(arr)
    ds.attrs["units"] = units
    for key, val in attrs.items():
        set_attr(ds, key, val)
    return ds


def set_attr(obj: h5py.HLObject, key: str, val: Any) -> None:
    """Attribute with lists of strings stored as UTF-8 string arrays."""
    if isinstance(val, (list, tuple)) and all(isinstance(x, str) for x in val):
        obj.attrs.create(key, np.array(val, dtype=object), dtype=STR)
    else:
        obj.attrs[key] = val


def read_str(ds: h5py.Dataset) -> str | list[str]:
    """A string dataset as ``str`` (scalar) or ``list[str]``."""
    val = ds.asstr()[()]
    return val if isinstance(val, str) else [str(x) for x in np.asarray(val).ravel()]


def attr_strs(obj: h5py.HLObject, key: str) -> list[str]:
    val = obj.attrs[key]
    return [v.decode() if isinstance(v, bytes) else str(v) for v in np.atleast_1d(val)]


def library_versions() -> dict[str, str]:
    """Versions of Python and the libraries the files depend on (a fresh copy; looked up once
    per process: the package metadata scan costs 20-40 ms, paid by every sweep study)."""
    return dict(_library_versions())


@functools.cache
def _library_versions() -> dict[str, str]:
    out = {"python": platform.python_version()}
    for name in LIBRARIES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            continue
    return out


def provenance(deck_text: str | None, deck_path: str | None = None) -> dict[str, Any]:
    """What made a file: fracas version, UTC time, command line, deck text and its SHA-256,
    library versions, host platform."""
    from fracas import __version__

    text = deck_text or ""
    return {
        "fracas_version": __version__,
        "created_utc": _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "command": " ".join(path_text(a) for a in sys.argv),  # a file name need not be UTF-8
        "platform": platform.platform(),
        "deck_path": path_text(deck_path) if deck_path else "",
        "deck_sha256": hashlib.sha256(text.encode("utf-8")).hexdigest(),
        "deck_text": text,
        "libraries": library_versions(),
    }


def write_provenance(f: h5py.File, prov: dict[str, Any]) -> None:
    """``/provenance``: attributes for the short items, ``deck_text`` dataset, ``libraries`` subgroup attrs."""
    g = f.create_group("provenance")
    for key, val in prov.items():
        if key == "deck_text":
            write(g, "deck_text", val, "none", sha256=prov.get("deck_sha256", ""))
        elif key == "libraries":
            lib = g.create_group("libraries")
            for name, ver in val.items():
                lib.attrs[name] = ver
        else:
            g.attrs[key] = val


def read_provenance(f: h5py.File) -> dict[str, Any]:
    if "provenance" not in f:
        return {}
    g = f["provenance"]
    out: dict[str, Any] = {k: (v.decode() if isinstance(v, bytes) else v) for k, v in g.attrs.items()}
    if "deck_text" in g:
        out["deck_text"] = read_str(g["deck_text"])
    if "libraries" in g:
        out["libraries"] = {k: str(v) for k, v in g["libraries"].attrs.items()}
    return out


def attr_int(obj: h5py.HLObject, key: str, error: Exception | None = None) -> int | None:
    """An integer attribute (numpy or Python int, not bool); None if absent, ``error`` if not an integer."""
    if key not in obj.attrs:
        return None
    val = obj.attrs[key]
    if isinstance(val, np.ndarray) and val.shape == ():
        val = val[()]
    if isinstance(val, (bool, np.bool_)) or not isinstance(val, (int, np.integer)):
        if error is not None:
            raise error
        return None
    return int(val)


def schema_version_attr(f: h5py.File, src: Any, error: ErrorType) -> int | None:
    """The root attribute ``schema_version`` as an integer (None if absent); ``error`` (one line
    naming ``src``) if it is not an integer."""
    raw = f.attrs.get("schema_version")
    return attr_int(
        f,
        "schema_version",
        error(f"{src}: attribute schema_version is {type(raw).__name__} ({raw!r}), expected an integer"),
    )


def schema_version(f: h5py.File, src: Any, latest: int, error: ErrorType, what: str) -> int:
    """The root attribute ``schema_version`` of a ``what`` file, an integer from 1 to ``latest``;
    else ``error`` (one line naming ``src``)."""
    version = schema_version_attr(f, src, error)
    if version is None or not 1 <= version <= latest:
        raise error(f"{src}: {what} schema_version = {version}, this fracas reads 1 to {latest}")
    return version


def attr_text(obj: h5py.HLObject, key: str) -> str | None:
    """A string attribute as ``str``; None if absent or not a string."""
    if key not in obj.attrs:
        return None
    val = obj.attrs[key]
    if isinstance(val, bytes):
        try:
            return val.decode()
        except UnicodeDecodeError:
            return None
    return val if isinstance(val, str) else None
