"""The reference trajectory with its transition matrices (the STM file's contents, FRACAS
STMGEN) and :func:`chain`, which multiplies its step matrices over skipped times (FRACAS
STMRDR, CR-112256 section 3.2).  Numpy-only.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from fracas.constants import DAY_S
from fracas.errors import StmFileError

__all__ = ["SCHEMA_VERSION", "TIME_TOL_S", "ReferenceTrajectory", "chain", "time_indices"]

SCHEMA_VERSION = 2  # of the STM file that stores a ReferenceTrajectory
TIME_TOL_S = 1e-6  # a requested time matches a file time within this (s); the deck's eps_t


def _days(t: float) -> str:
    return f"{float(t) / DAY_S:.6f} d"


@dataclass
class ReferenceTrajectory:
    """A reference trajectory with its transition matrices: the contents of an STM file
    (numpy, canonical units, ICRF axes).  Any mode builds one (TEAM's STMGEN, TOM's
    converged trajectory) and any mode reads one (TEAM, TSIM).

    times_s (n,): s from the epoch (t = 0), non-decreasing; epoch_et_s: TDB s past J2000 of
    t = 0; event_types (n,): why each time is on the file ("initial", "measurement",
    "propagation", "eigenvector", "prediction", "thrust_on", "thrust_off", "final", "grid";
    several joined by "+"); states (n,7): r km, v km/s, m kg relative to primary[i];
    stm_step (n,7,7): Phi(t_i, t_{i-1}) (i = 0: from the epoch to times_s[0], the identity
    when times_s[0] == 0); par_step (n,7,np): Theta(t_i, t_{i-1}) = dx(t_i)/dp with
    x(t_{i-1}) fixed, element (r, p) in STATE_UNITS[r] / param_units[p];
    param_labels/param_units/param_values (np,): fracas.params labels, their units and
    nominal values; param_steps (np,): perturbations of a finite-difference generation
    (NaN for AD, see ``sensitivity_method``); deck_text/deck_hash/deck_path: the trajectory
    deck (TOML) the file was built from and its :func:`trajectory_hash`.
    ``source_path`` is the file it was read from ("" when built in memory).
    """

    times_s: np.ndarray
    epoch_et_s: float
    event_types: list[str]
    states: np.ndarray
    primary: list[str]
    stm_step: np.ndarray
    par_step: np.ndarray
    param_labels: list[str]
    param_units: list[str]
    param_values: np.ndarray
    param_steps: np.ndarray
    deck_text: str
    deck_hash: str
    deck_path: str | None = None
    title: str = ""
    centre: str = ""
    frame: str = "ICRF"
    fracas_version: str = ""
    schema_version: int = SCHEMA_VERSION
    sensitivity_method: str = "ad"
    provenance: dict[str, Any] = field(default_factory=dict)
    source_path: str = ""

    def __post_init__(self) -> None:
        if not self.fracas_version:
            from fracas import __version__

            self.fracas_version = __version__

    @property
    def n_times(self) -> int:
        return int(np.shape(self.times_s)[0])

    @property
    def where(self) -> str:
        """How messages name this data: the file path, or the deck it was built from."""
        return self.source_path or (f"STM data of {self.deck_path}" if self.deck_path else "STM data")


def _nearest_message(where: str, t_file: np.ndarray, events: Sequence[str], t_req: float) -> str:
    k = int(np.argmin(np.abs(t_file - t_req)))
    return (
        f"{where}: requested time {t_req:.6f} s ({_days(t_req)}) is not on the STM file "
        f"(tolerance {TIME_TOL_S:g} s); nearest file time is {t_file[k]:.6f} s ({_days(t_file[k])}, "
        f"{events[k] if k < len(events) else '?'}); the file has {t_file.shape[0]} times from "
        f"{_days(t_file[0])} to {_days(t_file[-1])}: regenerate it with this time in the schedule"
    )


def _indices(t_file: np.ndarray, events: Sequence[str], req: np.ndarray, where: str) -> np.ndarray:
    """Index of each requested time on the file (the last of equal file times)."""
    idx = np.searchsorted(t_file, req + TIME_TOL_S, side="right") - 1
    ok = (idx >= 0) & (np.abs(t_file[np.clip(idx, 0, None)] - req) <= TIME_TOL_S)
    if not np.all(ok):
        j = int(np.nonzero(~ok)[0][0])
        raise StmFileError(_nearest_message(where, t_file, events, float(req[j])))
    return idx


def time_indices(data: ReferenceTrajectory, times_s: Sequence[float]) -> np.ndarray:
    """Index into ``data.times_s`` of each requested time (within 1e-6 s; StmFileError otherwise).

    Equal file times resolve to the last of them (their step matrices are identities)."""
    t_file = np.asarray(data.times_s, np.float64)
    return _indices(t_file, data.event_types, np.atleast_1d(np.asarray(times_s, np.float64)), data.where)


def chain(data: ReferenceTrajectory, times_s: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
    """Transition matrices between consecutive requested times (FRACAS STMRDR + section 3.2).

    ``times_s`` (k,): s from the epoch, non-decreasing, each on the file.  Returns
    phi (k,7,7) and theta (k,7,np) (columns as ``data.param_labels``): element j maps from
    times_s[j-1] to times_s[j], element 0 from the epoch t = 0 to times_s[0]:

        Phi(t_b, t_a)   = Phi_b ... Phi_{a+1}
        Theta(t_b, t_a) = Phi_b Theta(t_{b-1}, t_a) + Theta_b

    over the file's step matrices.  All segments are reduced together by pairwise
    (log-depth) composition of neighbours within each segment: ~log2(longest segment)
    batched matrix products in all, about two products per file step.
    """
    idx = time_indices(data, times_s)
    k = idx.shape[0]
    if k and np.any(np.diff(idx) < 0):
        j = int(np.nonzero(np.diff(idx) < 0)[0][0]) + 1
        req = np.atleast_1d(np.asarray(times_s, np.float64))
        raise StmFileError(
            f"{data.where}: requested times must increase: times_s[{j}] = {_days(req[j])} "
            f"comes before times_s[{j - 1}] = {_days(req[j - 1])}"
        )
    stm_step = np.asarray(data.stm_step, np.float64)
    par_step = np.asarray(data.par_step, np.float64)
    n_p = par_step.shape[2]
    starts = np.concatenate([[0], idx[:-1] + 1]).astype(np.int64) if k else np.zeros(0, np.int64)
    lens = (idx - starts + 1).astype(np.int64)  # 0 where a time repeats: identity
    phi = np.broadcast_to(np.eye(7), (k, 7, 7)).copy()
    theta = np.zeros((k, 7, n_p))
    if k == 0 or lens.max() <= 0:
        return phi, theta
    live = lens > 0
    ls = lens[live]
    offs = np.cumsum(ls) - ls
    pos = np.arange(ls.sum()) - np.repeat(offs, ls)
    fi = np.repeat(starts[live], ls) + pos
    P, T = stm_step[fi], par_step[fi]
    while ls.max() > 1:
        offs = np.cumsum(ls) - ls
        pos = np.arange(P.shape[0]) - np.repeat(offs, ls)
        seglen = np.repeat(ls, ls)
        left = np.nonzero(pos % 2 == 0)[0]  # first of each pair (or a lone last element)
        has = pos[left] + 1 < seglen[left]
        a = left[has]  # earlier step of a pair; a + 1 is the later one
        b = a + 1
        Pb = P[b]
        newP, newT = P[left], T[left]
        newP[has] = Pb @ P[a]
        newT[has] = Pb @ T[a] + T[b]
        P, T = newP, newT
        ls = (ls + 1) // 2
    phi[live] = P
    theta[live] = T
    return phi, theta
