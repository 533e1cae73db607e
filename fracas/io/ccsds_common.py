"""What the CCSDS exchange files share (:mod:`fracas.io.ccsds`): the conventions as
constants, the OEM as read back (:class:`OemFile`, :class:`OemSegment`), epochs (TDB
seconds past J2000 <-> astropy Time) and centre names.

Everything public here is re-exported by :mod:`fracas.io.ccsds`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable
from typing import Any

import numpy as np

from fracas import constants
from fracas.errors import ResultsFileError
from fracas.timescales import et_to_calendar

OEM_VERSION = "2.0"  # covariance sections need OEM 2.0
OPM_VERSION = "3.0"
#: REF_FRAME values read as fracas's ICRF axes (written: "ICRF")
OEM_FRAMES = ("ICRF", "EME2000", "J2000")
WRITE_FRAME = "ICRF"
TIME_SYSTEM = "TDB"
#: records closer than this are one epoch (the OEM's microsecond resolution)
EPOCH_TOL_S = 1e-6
STATE6_LABELS = ("x", "y", "z", "vx", "vy", "vz")
CSV_FIXED_COLUMNS = ("event_index", "event", "time_s", "epoch_tdb", "covariance", "row", "row_unit")


# ----------------------------------------------------------------------------- products


@dataclasses.dataclass(frozen=True)
class OemSegment:
    """One OEM segment: states about one centre in one frame.

    ``et_s`` (n,) TDB s past J2000; ``r_km`` (n, 3); ``v_km_s`` (n, 3); ``cov_et_s`` (k,) and
    ``cov`` (k, 6, 6) in km², km²/s, km²/s² (``cov_frames``: the COV_REF_FRAME of each);
    ``centre``: fracas body name (lower case); ``frame``/``time_system``: as written;
    ``interpolation`` ("" when absent) and ``interpolation_degree`` (0 when absent)."""

    centre: str
    frame: str
    time_system: str
    et_s: np.ndarray
    r_km: np.ndarray
    v_km_s: np.ndarray
    cov_et_s: np.ndarray
    cov: np.ndarray
    cov_frames: tuple[str, ...]
    interpolation: str = ""
    interpolation_degree: int = 0
    object_name: str = ""
    object_id: str = ""
    _library_segment: Any = dataclasses.field(default=None, repr=False, compare=False)


@dataclasses.dataclass(frozen=True)
class OemFile:
    """An OEM read back: header fields and the segments in file order."""

    path: str
    version: str
    originator: str
    segments: tuple[OemSegment, ...]

    @property
    def et_s(self) -> np.ndarray:
        return np.concatenate([s.et_s for s in self.segments])


# ----------------------------------------------------------------------------- epochs


def _time(ets: Iterable[float]) -> Any:
    """astropy Time (TDB) of TDB seconds past J2000, through ISO strings rounded to 1 µs."""
    from astropy.time import Time

    return Time([et_to_calendar(float(t), 6) for t in ets], format="isot", scale="tdb", precision=6)


def _et_of(t: Any) -> float:
    """TDB s past J2000 of an astropy Time in TDB (double-double: sub-ns)."""
    return float((t.jd1 - constants.J2000_JD) * constants.DAY_S + t.jd2 * constants.DAY_S)


def _centre_name(body: str) -> str:
    return body.upper()


def _fracas_centre(name: str, where: str) -> str:
    key = name.strip().lower()
    if key not in constants.BODIES:
        raise ResultsFileError(
            f"{where}: CENTER_NAME = {name!r}: not a body fracas knows (expected one of "
            f"{', '.join(b.upper() for b in constants.BODIES)})"
        )
    return key
