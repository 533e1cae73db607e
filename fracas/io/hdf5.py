"""HDF5 helpers shared by every fracas file: atomic writes, labelled and checksummed
datasets, checked reading, provenance.

Writes are atomic (:mod:`fracas.io.atomic`): the file is built under a temporary name
``.<name>.<pid>-<host>.<random>.tmp`` in the destination directory, flushed and ``fsync``-ed, given
the user's normal permissions, then moved over the destination with ``os.replace``.  A
failure or a kill at any point leaves a previous file at the destination untouched.

Every dataset written by :func:`write` / :func:`write_strings` carries ``data_sha256``, the
SHA-256 of its bytes (:func:`digest_array`, :func:`digest_strings`); :class:`Checked` reads
datasets back verifying dtype, shape, finiteness and that checksum.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import functools
import hashlib
import os
import platform
import sys
from collections.abc import Iterator
from importlib import metadata
from typing import Any

import h5py
import numpy as np

from fracas.io.atomic import atomic_path

STR = h5py.string_dtype(encoding="utf-8")
LIBRARIES = ("numpy", "scipy", "jax", "jaxlib", "h5py", "pydantic", "click", "rich", "matplotlib", "jplephem", "de421")


@contextlib.contextmanager
def atomic_h5(path: str | os.PathLike) -> Iterator[h5py.File]:
    """``with atomic_h5(path) as f:`` -- write an HDF5 file that appears complete or not at all.

    Built on :func:`fracas.io.atomic.atomic_path`: the parent directory is created if
    needed, the file gets the user's normal permissions; on any exception inside the block
    (or while closing/flushing) the temporary file is removed and the exception propagates.
    """
    with atomic_path(path) as tmp, h5py.File(tmp, "w") as f:
        yield f


# --------------------------------------------------------------------------- checksums

CHECKSUM_ATTR = "data_sha256"


def digest_array(arr: Any) -> str:
    """SHA-256 (hex) of a numeric array's bytes: C order, little-endian, its own dtype."""
    a = np.asarray(arr)
    a = np.ascontiguousarray(a, dtype=a.dtype.newbyteorder("<"))
    return hashlib.sha256(a.tobytes()).hexdigest()


def digest_strings(values: Any) -> str:
    """SHA-256 (hex) of a string dataset: its values in UTF-8, each followed by a NUL byte."""
    vals = [values] if isinstance(values, str) else [str(v) for v in values]
    return hashlib.sha256(b"".join(v.encode("utf-8") + b"\0" for v in vals)).hexdigest()


def write_strings(group: h5py.Group, name: str, values, units: str = "none", **attrs: Any) -> h5py.Dataset:
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


# --------------------------------------------------------------------------- checked reading


def dtype_name(dtype: np.dtype) -> str:
    """``float64``, ``int64``, ... or ``strings`` for an HDF5 string dtype."""
    return "strings" if h5py.check_string_dtype(dtype) is not None else str(dtype)


class Checked:
    """Read datasets of an open file, each checked before use; every refusal is one line,
    ``error(f"{src}: {dataset}: {problem}, expected {what}")``.

    ``verify``: compare each dataset's ``data_sha256`` with its bytes (False skips the
    checksums only; dtype, shape and finiteness are always checked); ``require_checksum``:
    a dataset without ``data_sha256`` is refused (files of a schema that writes them).
    """

    def __init__(
        self, f: h5py.File, src: Any, error: type[Exception], *, verify: bool = True, require_checksum: bool = True
    ):
        self.f, self.src, self.error = f, src, error
        self.verify, self.require_checksum = verify, require_checksum

    def fail(self, name: str, problem: str) -> Exception:
        return self.error(f"{self.src}: {name}: {problem}")

    def dataset(self, name: str) -> h5py.Dataset:
        if name not in self.f:
            raise self.fail(name, "missing, expected a dataset (incomplete file?)")
        try:
            obj = self.f[name]
        except (KeyError, ValueError, OSError) as exc:
            raise self.fail(name, f"missing or unreadable ({exc}), expected a dataset") from None
        if not isinstance(obj, h5py.Dataset):
            raise self.fail(name, f"is a {type(obj).__name__}, expected a dataset")
        return obj

    def _shape(self, name: str, got: tuple[int, ...], want: tuple[int | None, ...] | None) -> None:
        if want is None:
            return
        if len(got) != len(want) or any(w is not None and g != w for g, w in zip(got, want)):
            shown = "(" + ", ".join("*" if w is None else str(w) for w in want) + ("," if len(want) == 1 else "") + ")"
            raise self.fail(name, f"shape {got}, expected {shown}")

    def check_digest(
        self, name: str, obj: h5py.HLObject, got: str, attr: str = CHECKSUM_ATTR, index: int | None = None
    ) -> None:
        """Compare ``got`` with ``obj.attrs[attr]`` (or its element ``index``)."""
        if not self.verify:
            return
        if attr not in obj.attrs:
            if self.require_checksum:
                raise self.fail(name, f"no {attr} attribute, expected the SHA-256 checksum every dataset carries")
            return
        stored = obj.attrs[attr]
        if index is not None:
            vals = np.atleast_1d(stored)
            if index >= vals.shape[0]:
                raise self.fail(name, f"{attr} has {vals.shape[0]} entries, expected one per column ({index + 1}+)")
            stored = vals[index]
        stored = stored.decode() if isinstance(stored, bytes) else stored
        if not isinstance(stored, str):
            raise self.fail(name, f"{attr} attribute is {type(stored).__name__}, expected a hex string")
        if stored != got:
            where = f" (column {index})" if index is not None else ""
            raise self.fail(
                name,
                f"SHA-256 checksum mismatch{where}: data {got[:12]}..., stored {stored[:12]}..., expected equal "
                "(the file was damaged or edited after it was written)",
            )

    def num(
        self,
        name: str,
        shape: tuple[int | None, ...] | None = None,
        *,
        integer: bool = False,
        finite: bool = False,
    ) -> np.ndarray:
        """A float64 (or, ``integer``, any integer) dataset of ``shape`` (None: any length)."""
        ds = self.dataset(name)
        if integer:
            if ds.dtype.kind not in "iu":
                raise self.fail(name, f"dtype {dtype_name(ds.dtype)}, expected an integer dtype")
        elif ds.dtype != np.float64:
            raise self.fail(name, f"dtype {dtype_name(ds.dtype)}, expected float64")
        self._shape(name, tuple(ds.shape), shape)
        try:
            val = ds[()]
        except (OSError, ValueError) as exc:
            raise self.fail(name, f"unreadable ({exc}), expected {ds.dtype} data") from None
        self.check_digest(name, ds, digest_array(val))
        if finite and not np.all(np.isfinite(val)):
            bad = np.argwhere(~np.isfinite(np.atleast_1d(val)))[0]
            raise self.fail(name, f"non-finite value at index {tuple(int(i) for i in bad)}, expected finite numbers")
        return val

    def scalar(self, name: str, *, integer: bool = False, finite: bool = True) -> float | int:
        val = self.num(name, (), integer=integer, finite=finite)
        return int(val) if integer else float(val)

    def strs(self, name: str, n: int | None = None) -> list[str]:
        """A 1-D UTF-8 string dataset (``n`` values when given)."""
        ds = self.dataset(name)
        if h5py.check_string_dtype(ds.dtype) is None:
            raise self.fail(name, f"dtype {ds.dtype}, expected UTF-8 strings")
        self._shape(name, tuple(ds.shape), (n,))
        try:
            vals = [str(x) for x in ds.asstr()[()]]
        except (OSError, ValueError) as exc:
            raise self.fail(name, f"unreadable strings ({exc}), expected UTF-8") from None
        self.check_digest(name, ds, digest_strings(vals))
        return vals

    def text(self, name: str) -> str:
        """A scalar UTF-8 string dataset."""
        ds = self.dataset(name)
        if h5py.check_string_dtype(ds.dtype) is None:
            raise self.fail(name, f"dtype {ds.dtype}, expected a UTF-8 string")
        self._shape(name, tuple(ds.shape), ())
        try:
            val = ds.asstr()[()]
        except (OSError, ValueError) as exc:
            raise self.fail(name, f"unreadable string ({exc}), expected UTF-8") from None
        self.check_digest(name, ds, digest_strings(str(val)))
        return str(val)


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
