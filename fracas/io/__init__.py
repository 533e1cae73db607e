"""Files (h5py): atomic HDF5 writing, the trajectory file, provenance."""

from fracas.io.hdf5 import atomic_h5, provenance
from fracas.io.trajectory_file import (
    SensitivityData,
    TrajectoryData,
    read_trajectory_file,
    write_trajectory_file,
)

__all__ = [
    "atomic_h5",
    "provenance",
    "SensitivityData",
    "TrajectoryData",
    "read_trajectory_file",
    "write_trajectory_file",
]
