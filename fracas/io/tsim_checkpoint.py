"""The TSIM checkpoint file (HDF5, atomic): the per-mission arrays of the completed blocks
of a run, so that a killed run can resume.

Layout::

    /                         file_kind = "fracas-tsim-checkpoint", schema_version, plan_key
      block_<index>/<field>   the completed block's arrays (integer or float64)

Re-exported by :mod:`fracas.io.tsim_results`.
"""

from __future__ import annotations

import os
from pathlib import Path

import h5py
import numpy as np

from fracas.errors import ResultsFileError
from fracas.io.hdf5 import atomic_h5, attr_text, one_line, open_h5, write
from fracas.io.tsim_schema import _CKPT_KIND, _FIELDS, CHECKPOINT_SCHEMA, _open_checked


def write_tsim_checkpoint(path: str | os.PathLike, plan_key: str, blocks: dict[int, dict[str, np.ndarray]]) -> Path:
    """Atomically rewrite the checkpoint at ``path``: one group per completed block index
    holding that block's arrays (integer or float64), attribute ``plan_key``."""
    p = Path(path)
    with atomic_h5(p) as f:
        f.attrs["file_kind"] = _CKPT_KIND
        f.attrs["schema_version"] = CHECKPOINT_SCHEMA
        f.attrs["plan_key"] = str(plan_key)
        for index in sorted(blocks):
            g = f.create_group(f"block_{int(index)}")
            for name, arr in blocks[index].items():
                a = np.asarray(arr)
                if a.dtype.kind not in "iu":
                    a = a.astype(np.float64)
                write(g, name, a, _FIELDS.get(name, ("1",))[0])
    return p


def read_tsim_checkpoint(
    path: str | os.PathLike, plan_key: str, *, verify: bool = True
) -> dict[int, dict[str, np.ndarray]]:
    """The completed blocks of a checkpoint ({} when ``path`` does not exist); a one-line
    ResultsFileError for a damaged file or one written by a different run (``plan_key``)."""
    p = Path(path)
    if not p.exists():
        return {}
    try:
        with open_h5(p, ResultsFileError, "TSIM checkpoint file", checksum=verify) as f:
            c = _open_checked(p, f, _CKPT_KIND, CHECKPOINT_SCHEMA, "TSIM checkpoint file", verify)
            key = attr_text(f, "plan_key")
            if key is None:
                raise ResultsFileError(f"{p}: no text attribute 'plan_key', expected the run's plan key")
            if key != str(plan_key):
                raise ResultsFileError(
                    f"{p}: checkpoint belongs to a different run (plan_key {key[:16]}..., expected "
                    f"{str(plan_key)[:16]}...); delete it to start afresh"
                )
            out: dict[int, dict[str, np.ndarray]] = {}
            for gname in f:
                head, _, idx = gname.partition("_")
                if head != "block" or not idx.isdigit() or not isinstance(f[gname], h5py.Group):
                    raise c.fail(gname, "unexpected entry, expected a group 'block_<index>'")
                arrays = {}
                for name in f[gname]:
                    where = f"{gname}/{name}"
                    ds = c.dataset(where)
                    arrays[name] = c.num(where, None, integer=ds.dtype.kind in "iu")
                out[int(idx)] = arrays
            return dict(sorted(out.items()))
    except OSError as exc:
        raise ResultsFileError(f"{p}: cannot read as HDF5 ({one_line(exc)}), expected a TSIM checkpoint file") from None
