"""CCSDS exchange files: trajectories as OEM (out and in), covariances as OPM or CSV.

Reference: ``docs/exchange.md``.  Conventions (fracas's, carried into the files):

* epochs are TDB (``TIME_SYSTEM = TDB``); in memory TDB seconds past J2000
  (2000-01-01T12:00:00 TDB, :mod:`fracas.timescales`); written as ISO calendar strings
  rounded to the microsecond (the ``oem`` library's resolution);
* axes are ICRF (``REF_FRAME = ICRF``, what fracas's files say); ``EME2000``/``J2000``
  are read as the same axes (fracas treats the 20 mas frame bias as zero, as its decks do);
* states are relative to the primary body of the record (``CENTER_NAME``); a trajectory
  whose primary changes is written as one OEM segment per primary;
* units: km, km/s; covariances km², km²/s, km²/s² (the CCSDS units).

Writing and reading go through the ``oem`` library (python-oem) for OEMs and ``ccsds_ndm``
for OPMs; COMMENT lines are added to the KVN text by hand (python-oem cannot write them).
Every failure is a one-line :class:`fracas.errors.ResultsFileError` naming the file.

This module holds the OPM, the covariance CSV and :func:`compare_oem`; the OEM is in
:mod:`fracas.io.ccsds_oem`, the sources (trajectory and TEAM results files, the schedule
entries chosen) in :mod:`fracas.io.ccsds_sources`, the conventions' constants and the OEM
read back in :mod:`fracas.io.ccsds_common`; their public names are re-exported here.
"""

from __future__ import annotations

import csv
import datetime as _dt
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from fracas.errors import ResultsFileError
from fracas.io.atomic import atomic_path
from fracas.io.ccsds_common import (
    CSV_FIXED_COLUMNS,
    EPOCH_TOL_S,
    OEM_FRAMES,  # noqa: F401  (re-exported)
    OEM_VERSION,  # noqa: F401  (re-exported)
    OPM_VERSION,  # noqa: F401  (re-exported)
    STATE6_LABELS,
    TIME_SYSTEM,
    WRITE_FRAME,
    OemFile,
    OemSegment,
    _centre_name,
)
from fracas.io.ccsds_oem import DENSE_FRACTION, read_oem, sample_oem, write_oem  # noqa: F401  (re-exported)
from fracas.io.ccsds_sources import (
    _from_trajectory,
    covariance_at,
    default_covariance,  # noqa: F401  (re-exported)
    file_kind,
    select_events,
)
from fracas.timescales import calendar_to_et, et_to_calendar

__all__ = [
    "OemFile",
    "OemSegment",
    "OEM_FRAMES",
    "write_oem",
    "read_oem",
    "sample_oem",
    "select_events",
    "covariance_at",
    "write_opm",
    "read_opm",
    "write_covariance_csv",
    "CSV_FIXED_COLUMNS",
    "compare_oem",
    "file_kind",
]


# ----------------------------------------------------------------------------- OPM


def _opm_model(c: dict, object_name: str, object_id: str, originator: str, comments: list[str]) -> Any:
    from ccsds_ndm.models.ndmxml4 import ndmxml_4_0_0_common_4_0 as cm
    from ccsds_ndm.models.ndmxml4 import ndmxml_4_0_0_opm_3_0 as om
    from ccsds_ndm.models.ndmxml4.ndmxml_4_0_0_master_4_0 import Opm

    idx = [c["labels"].index(k) for k in STATE6_LABELS]
    P = c["P"][np.ix_(idx, idx)]
    s = c["state"]
    epoch = et_to_calendar(c["et_s"], 6)
    pos = [cm.PositionTypeUo(value=float(x), units=cm.PositionUnits.KM) for x in s[:3]]
    vel = [cm.VelocityTypeUo(value=float(x), units=cm.VelocityUnits.KM_S) for x in s[3:6]]
    sv = cm.StateVectorType(epoch=epoch, x=pos[0], y=pos[1], z=pos[2], x_dot=vel[0], y_dot=vel[1], z_dot=vel[2])
    names = ("X", "Y", "Z", "X_DOT", "Y_DOT", "Z_DOT")
    entries: dict[str, Any] = {}
    for i in range(6):
        for j in range(i + 1):
            key = f"c{names[i]}_{names[j]}".lower()
            value = float(P[i, j])
            if i < 3:
                entries[key] = cm.PositionCovarianceType(value=value, units=cm.PositionCovarianceUnits.KM_2)
            elif j < 3:
                entries[key] = cm.PositionVelocityCovarianceType(
                    value=value, units=cm.PositionVelocityCovarianceUnits.KM_2_S
                )
            else:
                entries[key] = cm.VelocityCovarianceType(value=value, units=cm.VelocityCovarianceUnits.KM_2_S_2)
    cov = cm.OpmCovarianceMatrixType(cov_ref_frame=WRITE_FRAME, **entries)
    sc = None
    if len(s) > 6 and math.isfinite(float(s[6])):
        sc = cm.SpacecraftParametersType(mass=cm.MassType(value=float(s[6]), units=cm.MassUnits.KG))
    data = om.OpmData(comment=list(comments), state_vector=sv, covariance_matrix=cov, spacecraft_parameters=sc)
    meta = om.OpmMetadata(
        object_name=object_name,
        object_id=object_id,
        center_name=_centre_name(c["primary"]),
        ref_frame=WRITE_FRAME,
        time_system=TIME_SYSTEM,
    )
    header = cm.OdmHeader(
        creation_date=_dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%S"), originator=originator
    )
    return Opm(
        header=header,
        body=om.OpmBody(segment=om.OpmSegment(metadata=meta, data=data)),
    )


def write_opm(
    path: str | os.PathLike,
    c: dict,
    *,
    xml: bool = False,
    object_name: str = "SPACECRAFT",
    object_id: str = "UNKNOWN",
    originator: str = "FRACAS",
    source: str = "",
) -> Path:
    """One CCSDS OPM (KVN, or XML with ``xml``) of a :func:`covariance_at` entry: the TEAM
    reference state (km, km/s; mass kg), its 6x6 position/velocity covariance (km², km²/s,
    km²/s²) in ICRF, TDB.  Written with ccsds_ndm, atomically."""
    from ccsds_ndm.mapping import NDMFileFormats
    from ccsds_ndm.ndm_io import NdmIo

    dest = Path(path)
    when = "before" if c["before"] else "after"
    comments = [
        f"fracas TEAM {source}: event #{c['index']} {c['event']} at t = {c['time_s']:.6f} s from the epoch".replace(
            "  ", " "
        ),
        f"covariance: {c['which']} knowledge covariance {when} the update, position/velocity block",
    ]
    try:
        model = _opm_model(c, object_name, object_id, originator, comments)
        text = NdmIo().to_string(model, NDMFileFormats.XML if xml else NDMFileFormats.KVN)
    except (ValueError, TypeError, KeyError, AttributeError) as exc:
        raise ResultsFileError(f"{dest}: cannot form the OPM: {exc}") from None
    try:
        with atomic_path(dest) as tmp:
            tmp.write_text(text if text.endswith("\n") else text + "\n", encoding="utf-8")
    except OSError as exc:
        raise ResultsFileError(f"{dest}: cannot write the OPM: {exc.strerror or exc}") from None
    return dest


def read_opm(path: str | os.PathLike) -> dict:
    """An OPM read with ccsds_ndm: ``et_s`` (TDB s past J2000), ``r_km``, ``v_km_s``, ``cov``
    (6, 6) or None, ``centre``, ``frame``, ``time_system``.  ResultsFileError naming the file."""
    from ccsds_ndm.ndm_io import NdmIo

    p = Path(path)
    if not p.exists():
        raise ResultsFileError(f"{p}: no such OPM file")
    try:
        o = NdmIo().from_path(p)
        seg = o.body.segment
        md, d = seg.metadata, seg.data
        sv = d.state_vector
    except Exception as exc:  # noqa: BLE001 - the parser raises many types on a corrupt file
        raise ResultsFileError(f"{p}: not a readable CCSDS OPM: {type(exc).__name__}: {exc}") from None
    if str(md.time_system).upper() != TIME_SYSTEM:
        raise ResultsFileError(f"{p}: TIME_SYSTEM = {md.time_system!r}: fracas reads TDB only")
    cov = None
    if d.covariance_matrix is not None:
        names = ("X", "Y", "Z", "X_DOT", "Y_DOT", "Z_DOT")
        cov = np.zeros((6, 6))
        for i in range(6):
            for j in range(i + 1):
                cov[i, j] = cov[j, i] = float(getattr(d.covariance_matrix, f"c{names[i]}_{names[j]}".lower()).value)
    return {
        "et_s": calendar_to_et(str(sv.epoch)),
        "r_km": np.array([sv.x.value, sv.y.value, sv.z.value], dtype=np.float64),
        "v_km_s": np.array([sv.x_dot.value, sv.y_dot.value, sv.z_dot.value], dtype=np.float64),
        "cov": cov,
        "centre": str(md.center_name),
        "frame": str(md.ref_frame),
        "time_system": str(md.time_system),
        "comments": list(d.comment),
    }


# ----------------------------------------------------------------------------- CSV


def write_covariance_csv(path: str | os.PathLike, entries: list[dict]) -> Path:
    """The full augmented covariances of :func:`covariance_at` entries as one long CSV.

    One header row: ``event_index, event, time_s, epoch_tdb, covariance, row, row_unit``
    then one column per label, named ``label [unit]``; then, per event, one row per label
    (the matrix row of that label, in the units ``row_unit x column unit``).  Numbers in
    shortest round-trip form (``repr``), so the file reads back bit for bit."""
    dest = Path(path)
    if not entries:
        raise ResultsFileError(f"{dest}: no covariance chosen")
    labels, units = entries[0]["labels"], entries[0]["units"]
    header = [*CSV_FIXED_COLUMNS, *(f"{lab} [{u}]" for lab, u in zip(labels, units))]
    try:
        with atomic_path(dest) as tmp:
            with open(tmp, "w", newline="", encoding="utf-8") as fh:
                w = csv.writer(fh)
                w.writerow(header)
                for c in entries:
                    which = f"{c['which']} {'before' if c['before'] else 'after'}"
                    epoch = et_to_calendar(c["et_s"], 6)
                    for i, (lab, u) in enumerate(zip(labels, units)):
                        w.writerow(
                            [c["index"], c["event"], repr(c["time_s"]), epoch, which, lab, u]
                            + [repr(float(x)) for x in c["P"][i]]
                        )
    except OSError as exc:
        raise ResultsFileError(f"{dest}: cannot write the CSV: {exc.strerror or exc}") from None
    return dest


# ----------------------------------------------------------------------------- comparison


def compare_oem(trajectory: str | os.PathLike, oem_path: str | os.PathLike) -> dict:
    """Position/velocity differences (fracas - OEM) at the epochs a trajectory file and an OEM
    share (within 1 µs, same centre).

    Returns ``et_s`` (k,), ``t_s`` (k,) from the trajectory epoch, ``centre`` (k,),
    ``dr_km`` (k, 3), ``dv_km_s`` (k, 3), ``n_trajectory``, ``n_oem``, ``other_centre`` (epochs
    in common whose centres differ, not compared).  No epoch in common: ResultsFileError."""
    src = Path(trajectory)
    track = _from_trajectory(src)
    oem = read_oem(oem_path)
    et_o = np.concatenate([s.et_s for s in oem.segments])
    r_o = np.concatenate([s.r_km for s in oem.segments])
    v_o = np.concatenate([s.v_km_s for s in oem.segments])
    c_o = [s.centre for s in oem.segments for _ in range(s.et_s.size)]
    order = np.argsort(et_o, kind="stable")
    rows, other = [], 0
    for k, et in enumerate(track.et):
        j = int(np.searchsorted(et_o[order], et))
        for jj in (j - 1, j):
            if 0 <= jj < order.size and abs(et_o[order[jj]] - et) <= EPOCH_TOL_S:
                i = int(order[jj])
                if c_o[i] != track.primary[k]:
                    other += 1
                else:
                    rows.append((k, i))
                break
    if not rows:
        raise ResultsFileError(
            f"{oem_path}: no epoch in common with {src} (within 1 µs, same centre; {other} with another centre)"
        )
    kk = np.array([k for k, _ in rows])
    ii = np.array([i for _, i in rows])
    return {
        "et_s": track.et[kk],
        "t_s": track.et[kk] - track.et[0],
        "centre": [track.primary[k] for k in kk],
        "dr_km": track.r[kk] - r_o[ii],
        "dv_km_s": track.v[kk] - v_o[ii],
        "n_trajectory": int(track.et.size),
        "n_oem": int(et_o.size),
        "other_centre": other,
    }
