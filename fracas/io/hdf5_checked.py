"""Checksums of datasets and checked reading of an open HDF5 file.

Every dataset written by :func:`fracas.io.hdf5.write` / :func:`fracas.io.hdf5.write_strings`
carries ``data_sha256``, the SHA-256 of its bytes (:func:`digest_array`,
:func:`digest_strings`); :class:`Checked` reads datasets back verifying dtype, shape,
finiteness and that checksum (this names the damaged dataset in files without the
integrity header, :mod:`fracas.io.hdf5_integrity`).

Everything here is re-exported by :mod:`fracas.io.hdf5`.
"""

from __future__ import annotations

import hashlib
from typing import Any

import h5py
import numpy as np

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
    ) -> None:
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
