"""OEM files (CCSDS Orbit Ephemeris Message) out and in, through the ``oem`` library
(python-oem): :func:`write_oem` of a trajectory file or a TEAM results file, one segment
per primary body; :func:`read_oem` into arrays; :func:`sample_oem` at a record or
interpolated.  COMMENT lines are added to the KVN text by hand (python-oem cannot write
them).  Conventions: :mod:`fracas.io.ccsds` (``docs/exchange.md``).

Every failure is a one-line :class:`fracas.errors.ResultsFileError` naming the file.
Everything public here is re-exported by :mod:`fracas.io.ccsds`.
"""

from __future__ import annotations

import datetime as _dt
import os
import re
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from fracas.errors import FracasError, ResultsFileError
from fracas.io.atomic import atomic_path
from fracas.io.ccsds_common import (
    EPOCH_TOL_S,
    OEM_FRAMES,
    OEM_VERSION,
    TIME_SYSTEM,
    WRITE_FRAME,
    OemFile,
    OemSegment,
    _centre_name,
    _et_of,
    _fracas_centre,
    _time,
)
from fracas.io.ccsds_sources import (
    _from_team,
    _from_trajectory,
    _merge_team_covariances,
    _segments,
    _Track,
    file_kind,
)
from fracas.io.inputs import check_regular
from fracas.timescales import calendar_to_et, et_to_calendar

# ----------------------------------------------------------------------------- OEM out


def _build_oem(track: _Track, object_name: str, object_id: str, originator: str, where: Path) -> Any:
    from oem import OrbitEphemerisMessage
    from oem.components import EphemerisSegment, HeaderSection, MetaDataSection

    if track.et.size == 0:
        raise ResultsFileError(f"{where}: no states to write")
    header = HeaderSection(
        {
            "CCSDS_OEM_VERS": OEM_VERSION,
            "CREATION_DATE": _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%S.%f"),
            "ORIGINATOR": originator,
        }
    )
    segments = []
    for a, b in _segments(track.primary):
        et, r, v = track.et[a:b], track.r[a:b], track.v[a:b]
        # one record per microsecond (the OEM's resolution): a later duplicate is dropped
        keep = np.concatenate([[True], np.diff(np.round(et * 1e6)) > 0])
        if np.any(np.diff(et[keep]) <= 0):
            raise ResultsFileError(f"{where}: epochs not increasing within the {track.primary[a]} segment")
        et, r, v = et[keep], r[keep], v[keep]
        n = et.size
        centre = track.primary[a]
        meta = {
            "OBJECT_NAME": object_name,
            "OBJECT_ID": object_id,
            "CENTER_NAME": _centre_name(centre),
            "REF_FRAME": WRITE_FRAME,
            "TIME_SYSTEM": TIME_SYSTEM,
            "START_TIME": et_to_calendar(et[0], 6),
            "STOP_TIME": et_to_calendar(et[-1], 6),
        }
        if n >= 2 and _dense_enough(et, r, v):
            meta["INTERPOLATION"] = "HERMITE"
            meta["INTERPOLATION_DEGREE"] = str(min(7, 2 * n - 1))
        epochs = _time(et)
        state_data = (tuple(epochs), *(tuple(float(x) for x in col) for col in np.column_stack([r, v]).T))
        # covariances whose epoch lies in this segment's span and whose primary is this one
        sel = [
            k
            for k in range(track.cov_et.size)
            if track.cov_primary[k] == centre and et[0] - EPOCH_TOL_S <= track.cov_et[k] <= et[-1] + EPOCH_TOL_S
        ]
        cov_data = None
        if sel:
            cepochs = _time(track.cov_et[sel])
            tri = [[float(track.cov[k][i, j]) for i in range(6) for j in range(i + 1)] for k in sel]
            cov_data = (tuple(cepochs), tuple(WRITE_FRAME for _ in sel), *(tuple(c) for c in zip(*tri)))
        md = MetaDataSection(meta, version=OEM_VERSION)
        segments.append(EphemerisSegment(md, state_data, cov_data, version=OEM_VERSION))
    return OrbitEphemerisMessage(header, segments)


def _comment_lines(comments: list[str]) -> str:
    out = ""
    for c in comments:
        for line in str(c).splitlines():
            out += f"COMMENT {line}\n"
    return out


#: the largest record spacing, as a fraction of 2 pi r / |v| (an orbital period on a circular
#: orbit), at which the OEM advertises Hermite interpolation.  Measured on Kepler orbits
#: (degree-7 Hermite through python-oem, midpoints): at 0.05 the position error is 9e-10
#: relative for e = 0 but 3e-8 at e = 0.3 and 6e-8 at e = 0.7 (at 0.02 it is ~1e-9 for all,
#: the floor of the OEM's microsecond epochs: sample eccentric orbits that densely for 1e-9).
#: A coarser file (a TEAM run's measurement times, say) would be interpolated wildly by a
#: reader, so it gets no INTERPOLATION at all.
DENSE_FRACTION = 0.05
#: the largest OEM read (a typo naming a disk image is refused before it is read)
MAX_OEM_BYTES = 1 << 30


def _dense_enough(et: np.ndarray, r: np.ndarray, v: np.ndarray) -> bool:
    """True when every record spacing is at most DENSE_FRACTION of 2 pi r/|v| at its ends."""
    scale = 2.0 * np.pi * np.linalg.norm(r, axis=1) / np.maximum(np.linalg.norm(v, axis=1), 1e-300)
    limit = DENSE_FRACTION * np.minimum(scale[:-1], scale[1:])
    return bool(np.all(np.diff(et) <= limit))


def write_oem(
    path: str | os.PathLike,
    source: str | os.PathLike,
    *,
    team: str | os.PathLike | None = None,
    covariance: str | None = None,
    before_update: bool = False,
    xml: bool = False,
    object_name: str | None = None,
    object_id: str = "UNKNOWN",
    originator: str = "FRACAS",
) -> Path:
    """Write an OEM (KVN, or XML with ``xml``) of a trajectory file or a TEAM results file.

    ``source``: a trajectory file (states at its output times) or a TEAM results file (its
    reference states at every schedule time and, unless ``covariance = "none"``, the 6x6
    position/velocity block of a knowledge covariance at each of them); ``team``: a TEAM
    results file whose covariances go with a trajectory file's states.  ``covariance``:
    "true" | "assumed" | "none" (default: the true covariance when the file has it, else the
    assumed one); ``before_update``: P- instead of P+.  One segment per primary body.
    Written atomically; returns the path."""
    dest = Path(path)
    src = Path(source)
    if covariance not in (None, "true", "assumed", "none"):
        raise ResultsFileError(f"{dest}: covariance = {covariance!r}: expected true, assumed or none")
    kind = file_kind(src)
    if kind == "team":
        if team is not None:
            raise ResultsFileError(f"{src}: is a TEAM results file already; --team is for a trajectory file")
        track = _from_team(src, covariance, before_update)
    else:
        track = _from_trajectory(src)
        if team is not None:
            if file_kind(team) != "team":
                raise ResultsFileError(f"{team}: not a TEAM results file")
            _merge_team_covariances(track, Path(team), covariance, before_update)
        elif covariance in ("true", "assumed"):
            raise ResultsFileError(
                f"{src}: a trajectory file holds no covariance (covariance = {covariance}); give a TEAM results file"
            )
    name = object_name or track.title or "SPACECRAFT"
    name = re.sub(r"\s+", " ", name).strip()
    try:
        msg = _build_oem(track, name, object_id, originator, src)
    except (ValueError, KeyError) as exc:
        raise ResultsFileError(f"{src}: cannot form an OEM: {exc}") from None
    try:
        with atomic_path(dest) as tmp:
            msg.save_as(tmp, file_format="xml" if xml else "kvn")
            if not xml and track.comments:  # python-oem writes no COMMENT lines: add them after the version line
                text = tmp.read_text(encoding="utf-8")
                first, rest = text.split("\n", 1)
                tmp.write_text(first + "\n" + _comment_lines(track.comments) + rest, encoding="utf-8")
    except OSError as exc:
        raise ResultsFileError(f"{dest}: cannot write the OEM: {exc.strerror or exc}") from None
    return dest


# ----------------------------------------------------------------------------- OEM in


def read_oem(path: str | os.PathLike) -> OemFile:
    """Read an OEM (KVN or XML) with the ``oem`` library into arrays.

    Epochs -> TDB s past J2000; states km, km/s; covariances km², km²/s, km²/s².  Refused
    with a one-line ResultsFileError naming the file: missing, unreadable or malformed,
    TIME_SYSTEM other than TDB, REF_FRAME (or COV_REF_FRAME) other than ICRF/EME2000/J2000,
    CENTER_NAME not a fracas body."""
    p = Path(path)
    if not p.exists():
        raise ResultsFileError(f"{p}: no such OEM file")
    check_regular(p, ResultsFileError, "an OEM file", limit=MAX_OEM_BYTES)  # a FIFO would block, a device never end
    try:
        from oem import OrbitEphemerisMessage

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # an unsupported TIME_SYSTEM warns, then is refused below
            msg = OrbitEphemerisMessage.open(p)
    except (ValueError, KeyError, IndexError, TypeError, UnicodeDecodeError, OSError, SyntaxError) as exc:
        why = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ResultsFileError(f"{p}: not a readable CCSDS OEM: {why}") from None
    except Exception as exc:  # noqa: BLE001 - lxml and astropy raise their own types on corrupt files
        why = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ResultsFileError(f"{p}: not a readable CCSDS OEM: {type(exc).__name__}: {why}") from None
    segments = []
    for k, seg in enumerate(msg.segments):
        where = f"{p}: segment {k + 1}"
        md = seg.metadata
        ts = str(md["TIME_SYSTEM"]).strip()
        if ts.upper() != TIME_SYSTEM:
            raise ResultsFileError(f"{where}: TIME_SYSTEM = {ts!r}: fracas reads TDB only")
        frame = str(md["REF_FRAME"]).strip()
        if frame.upper() not in OEM_FRAMES:
            raise ResultsFileError(
                f"{where}: REF_FRAME = {frame!r}: fracas reads {', '.join(OEM_FRAMES)} (ICRF axes) only"
            )
        centre = _fracas_centre(str(md["CENTER_NAME"]), where)
        states = list(seg.states)
        et = np.array([_et_of(s.epoch) for s in states], dtype=np.float64)
        r = np.array([s.position for s in states], dtype=np.float64).reshape(-1, 3)
        v = np.array([s.velocity for s in states], dtype=np.float64).reshape(-1, 3)
        covs = list(seg.covariances)
        for c in covs:
            if str(c.frame).strip().upper() not in OEM_FRAMES:
                raise ResultsFileError(
                    f"{where}: COV_REF_FRAME = {c.frame!r}: fracas reads {', '.join(OEM_FRAMES)} (ICRF axes) only"
                )
        if not (np.all(np.isfinite(r)) and np.all(np.isfinite(v))):
            raise ResultsFileError(f"{where}: non-finite state values")
        segments.append(
            OemSegment(
                centre=centre,
                frame=frame,
                time_system=ts.upper(),
                et_s=et,
                r_km=r,
                v_km_s=v,
                cov_et_s=np.array([_et_of(c.epoch) for c in covs], dtype=np.float64),
                cov=np.array([c.matrix for c in covs], dtype=np.float64).reshape(-1, 6, 6),
                cov_frames=tuple(str(c.frame) for c in covs),
                interpolation=str(md["INTERPOLATION"]).strip().upper() if "INTERPOLATION" in md else "",
                interpolation_degree=int(md["INTERPOLATION_DEGREE"]) if "INTERPOLATION_DEGREE" in md else 0,
                object_name=str(md["OBJECT_NAME"]),
                object_id=str(md["OBJECT_ID"]),
                _library_segment=seg,
            )
        )
    return OemFile(
        path=str(p),
        version=str(msg.version),
        originator=str(msg.header["ORIGINATOR"]),
        segments=tuple(segments),
    )


def sample_oem(oem: OemFile, at: str | float) -> tuple[float, np.ndarray, np.ndarray, OemSegment, str]:
    """The state of ``oem`` at ``at``: "start" (the first record), "end" (the last), an ISO TDB
    epoch string or TDB seconds past J2000.

    Returns (et_s, r_km (3,), v_km_s (3,), segment, how) with ``how`` "record k of segment s" or
    "interpolated (HERMITE 7)".  An epoch within 1 µs of a record takes the record exactly;
    between records it is interpolated with the segment's INTERPOLATION metadata, refused
    when the segment has none.  Outside every segment: refused.  ResultsFileError naming
    the file."""
    p = oem.path
    if not oem.segments:
        raise ResultsFileError(f"{p}: holds no segment")
    if isinstance(at, str) and at.strip().lower() in ("start", "end"):
        first = at.strip().lower() == "start"
        s = oem.segments[0] if first else oem.segments[-1]
        k = 0 if first else s.et_s.size - 1
        j = 0 if first else len(oem.segments) - 1
        return float(s.et_s[k]), s.r_km[k].copy(), s.v_km_s[k].copy(), s, f"record {k + 1} of segment {j + 1}"
    if isinstance(at, str):
        try:
            et = calendar_to_et(at)
        except FracasError:
            raise ResultsFileError(f'{p}: at = {at!r}: expected "start", "end" or an ISO TDB epoch') from None
    else:
        et = float(at)
    for j, s in enumerate(oem.segments):
        d = np.abs(s.et_s - et)
        k = int(np.argmin(d))
        if d[k] <= EPOCH_TOL_S:
            return float(s.et_s[k]), s.r_km[k].copy(), s.v_km_s[k].copy(), s, f"record {k + 1} of segment {j + 1}"
    for j, s in enumerate(oem.segments):
        if s.et_s[0] <= et <= s.et_s[-1]:
            if not s.interpolation:
                raise ResultsFileError(
                    f"{p}: segment {j + 1}: epoch {et_to_calendar(et, 6)} TDB falls between records and the "
                    "segment gives no INTERPOLATION: use an epoch of a record"
                )
            seg = s._library_segment
            t = _time([et])[0]
            try:
                state = seg(t)
            except (ValueError, KeyError, np.linalg.LinAlgError) as exc:
                raise ResultsFileError(f"{p}: segment {j + 1}: cannot interpolate: {exc}") from None
            how = f"interpolated ({s.interpolation} {s.interpolation_degree}) in segment {j + 1}"
            return et, np.asarray(state.position, float), np.asarray(state.velocity, float), s, how
    lo, hi = oem.segments[0].et_s[0], oem.segments[-1].et_s[-1]
    raise ResultsFileError(
        f"{p}: epoch {et_to_calendar(et, 6)} TDB outside the OEM ({et_to_calendar(lo, 6)} to {et_to_calendar(hi, 6)})"
    )
