"""HDF5 helpers shared by every fracas file: atomic writes, labelled datasets, provenance.

Writes are atomic: the file is built under a temporary name in the destination directory,
flushed and ``fsync``-ed, then moved over the destination with ``os.replace`` (atomic on
POSIX within one filesystem).  A failure at any point removes the temporary file and
leaves a previous file at the destination untouched, so readers never see a partial file.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import hashlib
import os
import platform
import sys
import tempfile
from collections.abc import Iterator
from importlib import metadata
from pathlib import Path
from typing import Any

import h5py
import numpy as np

STR = h5py.string_dtype(encoding="utf-8")
LIBRARIES = ("numpy", "scipy", "jax", "jaxlib", "h5py", "pydantic", "click", "rich", "matplotlib", "jplephem", "de421")


@contextlib.contextmanager
def atomic_h5(path: str | os.PathLike) -> Iterator[h5py.File]:
    """``with atomic_h5(path) as f:`` -- write an HDF5 file that appears complete or not at all.

    The parent directory is created if needed.  On any exception inside the block (or
    while closing/flushing) the temporary file is removed and the exception propagates.
    """
    dest = Path(path)
    dest.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{dest.name}.", suffix=".tmp", dir=dest.parent)
    os.close(fd)
    try:
        with h5py.File(tmp, "w") as f:
            yield f
        with open(tmp, "rb+") as fh:
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, dest)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    # Make the rename durable (best effort: not every filesystem allows opening a directory).
    with contextlib.suppress(OSError):
        dfd = os.open(dest.parent, os.O_RDONLY)
        try:
            os.fsync(dfd)
        finally:
            os.close(dfd)


def write_strings(group: h5py.Group, name: str, values, units: str = "none", **attrs: Any) -> h5py.Dataset:
    """A 1-D UTF-8 string dataset (empty lists included) with a ``units`` attribute."""
    vals = [str(v) for v in values]
    if vals:
        ds = group.create_dataset(name, data=np.array(vals, dtype=object), dtype=STR)
    else:
        ds = group.create_dataset(name, shape=(0,), dtype=STR)
    ds.attrs["units"] = units
    for key, val in attrs.items():
        set_attr(ds, key, val)
    return ds


def write(group: h5py.Group, name: str, data: Any, units: str, **attrs: Any) -> h5py.Dataset:
    """Create dataset ``name`` with a ``units`` attribute (``"1"``: dimensionless,
    ``"none"``: text or labels) and any further attributes."""
    if isinstance(data, str):
        ds = group.create_dataset(name, data=data, dtype=STR)
    elif isinstance(data, (list, tuple)) and data and all(isinstance(x, str) for x in data):
        return write_strings(group, name, data, units, **attrs)
    else:
        ds = group.create_dataset(name, data=np.asarray(data))
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
        "command": " ".join(sys.argv),
        "platform": platform.platform(),
        "deck_path": deck_path or "",
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
