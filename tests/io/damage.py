"""Helpers of the damaged-file tests: change a fracas file in place and seal it again.

A file changed with h5py after fracas wrote it no longer matches its integrity header
(:mod:`fracas.io.hdf5`) and is refused as damaged before any dataset is looked at.  To test
what the readers check *inside* a file (dtypes, shapes, per-dataset checksums, missing
datasets, schema versions), as a writer's bug or an older fracas would have left it, the
change is made through :func:`edited`, which re-seals the file afterwards.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator

import h5py

from fracas.io.hdf5 import USERBLOCK_SIZE, kind_attr, seal


@contextlib.contextmanager
def edited(path: str | os.PathLike, mode: str = "r+") -> Iterator[h5py.File]:
    """``with edited(path) as f:`` change a sealed file with h5py, then seal it again."""
    with h5py.File(path, mode) as f:
        yield f
        kind = kind_attr(f)
    seal(path, kind)


def unsealed(path: str | os.PathLike, dest: str | os.PathLike) -> None:
    """Copy a sealed file to ``dest`` without its user block: a file as fracas wrote it
    before the integrity header (HDF5 addresses are relative to the superblock)."""
    with open(path, "rb") as fh:
        data = fh.read()
    with open(dest, "wb") as fh:
        fh.write(data[USERBLOCK_SIZE:])
