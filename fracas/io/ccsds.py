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
"""

from __future__ import annotations

import csv
import dataclasses
import datetime as _dt
import math
import os
import re
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from fracas import constants
from fracas.errors import FracasError, ResultsFileError
from fracas.io.atomic import atomic_path
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


def _time(ets) -> Any:
    """astropy Time (TDB) of TDB seconds past J2000, through ISO strings rounded to 1 µs."""
    from astropy.time import Time

    return Time([et_to_calendar(float(t), 6) for t in ets], format="isot", scale="tdb", precision=6)


def _et_of(t) -> float:
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


# ----------------------------------------------------------------------------- sources


@dataclasses.dataclass
class _Track:
    """States and covariances gathered from fracas files (TDB s past J2000, km, km/s)."""

    et: np.ndarray
    r: np.ndarray
    v: np.ndarray
    primary: list[str]
    title: str
    cov_et: np.ndarray
    cov: np.ndarray  # (k, 6, 6)
    cov_primary: list[str]
    comments: list[str]


def file_kind(path: str | os.PathLike) -> str:
    """ "team" for a TEAM results file, "trajectory" for a trajectory file; else ResultsFileError
    (one line; the file's integrity is checked before it is decoded, :func:`fracas.io.hdf5.read_kind`)."""
    from fracas.io.hdf5 import read_kind

    p = Path(path)
    if not p.exists():
        raise ResultsFileError(f"{p}: no such file")
    kind = read_kind(p, ResultsFileError, "TEAM results file or trajectory file")
    if kind == "fracas-team-results":
        return "team"
    if kind == "fracas-trajectory":
        return "trajectory"
    raise ResultsFileError(f"{p}: file_kind/format = {kind!r}: expected a TEAM results file or a trajectory file")


def _history(team: dict, which: str, before: bool) -> np.ndarray:
    """(n, m, m) covariance history ``which`` ("true"/"assumed"), before or after the update."""
    if which not in team:
        raise ResultsFileError(
            f"{team['path']}: team/{which}: not in this results file (run with [gencov] for the true covariance)"
        )
    key = "P_minus" if before else "P_plus"
    if key not in team[which]:
        raise ResultsFileError(f"{team['path']}: team/{which}/{key}: missing")
    return np.asarray(team[which][key], dtype=np.float64)


def _state_block(team: dict) -> list[int]:
    """Indices of x, y, z, vx, vy, vz in the TEAM labels."""
    labels = list(team["labels"])
    try:
        return [labels.index(k) for k in STATE6_LABELS]
    except ValueError:
        raise ResultsFileError(
            f"{team['path']}: team/labels/names = {labels[:6]}: expected the state labels x, y, z, vx, vy, vz"
        ) from None


def default_covariance(team: dict) -> str:
    """The covariance written when none is asked for: "true" if the file has it, else "assumed"."""
    return "true" if "true" in team else "assumed"


def _from_trajectory(path: Path) -> _Track:
    from fracas.io.trajectory_file import read_trajectory_file
    from fracas.status import status_text

    try:
        data = read_trajectory_file(path)
    except FracasError as exc:
        raise ResultsFileError(str(exc)) from None
    t = np.asarray(data.t_s, dtype=np.float64)
    keep = np.isfinite(t)
    comments = [f"fracas trajectory file {path.name}: {data.title}".rstrip(": ")]
    if data.status != 0:
        comments.append(f"propagation status {data.status}: {status_text(data.status)}")
    return _Track(
        et=data.epoch_et_s + t[keep],
        r=np.asarray(data.r_km, dtype=np.float64)[keep],
        v=np.asarray(data.v_km_s, dtype=np.float64)[keep],
        primary=[p for p, k in zip(data.primary, keep) if k],
        title=data.title,
        cov_et=np.zeros(0),
        cov=np.zeros((0, 6, 6)),
        cov_primary=[],
        comments=comments,
    )


def _read_team(path: Path) -> dict:
    from fracas.io.team_results import read_team_results

    return read_team_results(path)


def _team_covariances(team: dict, which: str, before: bool) -> tuple[np.ndarray, np.ndarray]:
    """(n,) TDB epochs and (n, 6, 6) position/velocity blocks of one history (symmetrised)."""
    idx = _state_block(team)
    P = _history(team, which, before)[:, idx][:, :, idx]
    P = 0.5 * (P + np.swapaxes(P, 1, 2))
    et = float(team["attrs"]["epoch_et_s"]) + np.asarray(team["times_s"], dtype=np.float64)
    return et, P


def _covariance_comment(which: str, before: bool) -> str:
    when = "before the update (P-)" if before else "after the update (P+)"
    return f"covariance: TEAM {which} knowledge covariance {when}, position/velocity block"


def _from_team(path: Path, covariance: str | None, before: bool) -> _Track:
    team = _read_team(path)
    et = float(team["attrs"]["epoch_et_s"]) + np.asarray(team["times_s"], dtype=np.float64)
    states = np.asarray(team["states"], dtype=np.float64)
    title = str(team["attrs"].get("title", ""))
    comments = [f"fracas TEAM results file {path.name}: {title}".rstrip(": "), "states: the TEAM reference trajectory"]
    track = _Track(
        et, states[:, :3], states[:, 3:6], list(team["primary"]), title, np.zeros(0), np.zeros((0, 6, 6)), [], comments
    )
    if covariance != "none":
        which = covariance or default_covariance(team)
        track.cov_et, track.cov = _team_covariances(team, which, before)
        track.cov_primary = list(team["primary"])
        comments.append(_covariance_comment(which, before))
    return track


def _merge_team_covariances(track: _Track, team_path: Path, covariance: str | None, before: bool) -> None:
    """Covariances of a TEAM file added to a trajectory file's states (same epochs' primaries)."""
    if covariance == "none":
        return
    team = _read_team(team_path)
    which = covariance or default_covariance(team)
    track.cov_et, track.cov = _team_covariances(team, which, before)
    track.cov_primary = list(team["primary"])
    span = [(track.et[a], track.et[b - 1], track.primary[a]) for a, b in _segments(track.primary)]
    inside = [
        any(lo - EPOCH_TOL_S <= t <= hi + EPOCH_TOL_S and c == centre for lo, hi, centre in span)
        for t, c in zip(track.cov_et, track.cov_primary)
    ]
    if track.cov_et.size and not any(inside):
        raise ResultsFileError(
            f"{team_path}: none of its {track.cov_et.size} covariance epochs lies within the trajectory's span "
            "about the same centre (expected the TEAM results of this trajectory)"
        )
    track.comments.append(_covariance_comment(which, before) + f" from {team_path.name}")


# ----------------------------------------------------------------------------- OEM out


def _segments(primary: list[str]) -> list[tuple[int, int]]:
    """[start, stop) runs of one primary."""
    runs: list[tuple[int, int]] = []
    start = 0
    for k in range(1, len(primary) + 1):
        if k == len(primary) or primary[k] != primary[start]:
            runs.append((start, k))
            start = k
    return runs


def _build_oem(track: _Track, object_name: str, object_id: str, originator: str, where: Path):
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
    if p.is_dir():
        raise ResultsFileError(f"{p}: is a directory, expected an OEM file")
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


# ----------------------------------------------------------------------------- events


def _event_names(team: dict) -> list[str]:
    return sorted({e for ev in team["event_types"] for e in str(ev).split("+") if e})


def select_events(team: dict, specs: list[str] | tuple[str, ...]) -> list[int]:
    """Schedule indices of a TEAM results file chosen by ``specs``.

    Each spec: an event name ("final", "eigenvector", ...: every schedule time holding it),
    "all", "#K" (schedule index K, from 0), a number (days from the epoch) or an ISO TDB
    epoch (the schedule time within 1 ms).  Unknown names and times off the schedule:
    one-line ResultsFileError naming the file and ``--covariance-at``."""
    p = team["path"]
    times = np.asarray(team["times_s"], dtype=np.float64)
    epoch = float(team["attrs"]["epoch_et_s"])
    out: list[int] = []
    for spec in specs:
        text = str(spec).strip()
        if text == "all":
            out.extend(range(times.size))
            continue
        if text.startswith("#"):
            try:
                k = int(text[1:])
            except ValueError:
                k = -1
            if not 0 <= k < times.size:
                raise ResultsFileError(f"{p}: --covariance-at = {text!r}: schedule index 0 to {times.size - 1}")
            out.append(k)
            continue
        names = [set(str(ev).split("+")) for ev in team["event_types"]]
        hit = [k for k, ns in enumerate(names) if text in ns]
        if hit:
            out.extend(hit)
            continue
        t = None
        try:
            t = float(text) * constants.DAY_S
            if not np.isfinite(t):
                raise ResultsFileError(f"{p}: --covariance-at = {text!r}: expected a finite time in days")
        except ValueError:
            if re.match(r"^\s*[+-]?\d{4,}-\d", text):
                try:
                    t = calendar_to_et(text) - epoch
                except FracasError:
                    raise ResultsFileError(
                        f"{p}: --covariance-at = {text!r}: expected ISO 'YYYY-MM-DDTHH:MM:SS' (TDB)"
                    ) from None
        if t is None:
            raise ResultsFileError(
                f"{p}: --covariance-at = {text!r}: no such event in team/event_types "
                f"(events: {', '.join(_event_names(team))}; or a time in days, an ISO TDB epoch, #index, all)"
            )
        k = int(np.argmin(np.abs(times - t)))
        if abs(times[k] - t) > 1e-3:
            raise ResultsFileError(
                f"{p}: --covariance-at = {text!r}: no schedule time at t = {t / constants.DAY_S:.9g} d "
                f"(nearest {times[k] / constants.DAY_S:.9g} d, #{k})"
            )
        out.append(k)
    return sorted(set(out))


def covariance_at(team: dict, k: int, covariance: str | None = None, before_update: bool = False) -> dict:
    """The full augmented covariance of schedule entry ``k``: a dict with ``P`` (m, m),
    ``labels``, ``units``, ``which``, ``before``, ``event``, ``time_s``, ``et_s``, ``state``
    (r km, v km/s, m kg) and ``primary``."""
    which = covariance or default_covariance(team)
    P = _history(team, which, before_update)[k]
    return {
        "P": 0.5 * (P + P.T),
        "labels": list(team["labels"]),
        "units": list(team["units"]),
        "which": which,
        "before": before_update,
        "event": str(team["event_types"][k]),
        "index": int(k),
        "time_s": float(team["times_s"][k]),
        "et_s": float(team["attrs"]["epoch_et_s"]) + float(team["times_s"][k]),
        "state": np.asarray(team["states"][k], dtype=np.float64),
        "primary": str(team["primary"][k]),
    }


# ----------------------------------------------------------------------------- OPM


def _opm_model(c: dict, object_name: str, object_id: str, originator: str, comments: list[str]):
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
