"""The sources of the CCSDS exchange files (:mod:`fracas.io.ccsds`): states and
covariances gathered from a fracas trajectory file or a TEAM results file (TDB s past
J2000, km, km/s), and the TEAM schedule entries chosen for an OPM or a CSV
(:func:`select_events`, :func:`covariance_at`).

Every failure is a one-line :class:`fracas.errors.ResultsFileError` naming the file.
Everything public here is re-exported by :mod:`fracas.io.ccsds`.
"""

from __future__ import annotations

import dataclasses
import os
import re
from pathlib import Path

import numpy as np

from fracas import constants
from fracas.errors import FracasError, ResultsFileError
from fracas.io.ccsds_common import EPOCH_TOL_S, STATE6_LABELS
from fracas.timescales import calendar_to_et

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


def _segments(primary: list[str]) -> list[tuple[int, int]]:
    """[start, stop) runs of one primary."""
    runs: list[tuple[int, int]] = []
    start = 0
    for k in range(1, len(primary) + 1):
        if k == len(primary) or primary[k] != primary[start]:
            runs.append((start, k))
            start = k
    return runs


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
