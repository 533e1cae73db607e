"""Files (h5py): atomic writes, checked and checksummed HDF5 files, provenance.

The names below load lazily, so ``import fracas.io.atomic`` (check_output_path,
atomic_path, savefig_atomic) loads no h5py.
"""

from __future__ import annotations

import importlib
from typing import Any

_WHERE = {
    "atomic_h5": "fracas.io.hdf5",
    "provenance": "fracas.io.hdf5",
    "atomic_path": "fracas.io.atomic",
    "check_output_path": "fracas.io.atomic",
    "savefig_atomic": "fracas.io.atomic",
    "SensitivityData": "fracas.io.trajectory_file",
    "TrajectoryData": "fracas.io.trajectory_file",
    "read_trajectory_file": "fracas.io.trajectory_file",
    "write_trajectory_file": "fracas.io.trajectory_file",
}

__all__ = list(_WHERE)


def __getattr__(name: str) -> Any:
    if name in _WHERE:
        return getattr(importlib.import_module(_WHERE[name]), name)
    raise AttributeError(f"module 'fracas.io' has no attribute {name!r}")
