"""The TEAM event schedule (FRACAS SCHED, SETEVN): every time point of a study and what happens there.

Events at one time are processed in the order thrust switch, propagation, measurement,
eigenvector, prediction, punch, final; the covariance is propagated once to that time
first.  Times are seconds from the trajectory epoch, merged on a 1 ms grid.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from fracas.constants import DAY_S

__all__ = ["Schedule", "build_schedule", "merge_times", "EVENT_ORDER", "TIME_RESOLUTION_S"]

TIME_RESOLUTION_S = 1e-3
EVENT_ORDER = (
    "initial",
    "thrust_on",
    "thrust_off",
    "propagation",
    "reset",
    "measurement",
    "guidance",
    "eigenvector",
    "prediction",
    "punch",
    "final",
)


def _key(t_s: float) -> int:
    return int(round(t_s / TIME_RESOLUTION_S))


def merge_times(*groups) -> np.ndarray:
    """Sorted union of time arrays (s), merged on the 1 ms grid."""
    keys = set()
    for g in groups:
        keys.update(_key(float(t)) for t in np.atleast_1d(np.asarray(g, dtype=np.float64)))
    return np.array(sorted(keys), dtype=np.float64) * TIME_RESOLUTION_S


def range_times(start_s: float, stop_s: float, step_s: float) -> np.ndarray:
    """start, start + step, ... <= stop (s); a 1e-9 relative guard keeps the stop point."""
    n = int(np.floor((stop_s - start_s) / step_s * (1 + 1e-12) + 1e-9))
    return start_s + step_s * np.arange(n + 1)


@dataclass
class Schedule:
    """All time points of one study, in order.

    times_s (K,): s from the trajectory epoch; events[k]: event types at times_s[k] in
    processing order; tracking[k]: indices of the [[tracking]] entries observing at
    times_s[k]; predict_to_s[k]: prediction target times (s) of prediction events there.
    """

    times_s: np.ndarray
    events: list[list[str]]
    tracking: list[list[int]]
    predict_to_s: dict[int, list[float]] = field(default_factory=dict)

    @property
    def n(self) -> int:
        return len(self.times_s)

    def index_of(self, t_s: float) -> int:
        k = int(np.argmin(np.abs(self.times_s - t_s)))
        return k

    def count(self, kind: str) -> int:
        return sum(kind in ev for ev in self.events)

    def primary_type(self, k: int) -> str:
        """The main event type at index k (for the results file and printout)."""
        for kind in (
            "guidance",
            "measurement",
            "thrust_on",
            "thrust_off",
            "prediction",
            "eigenvector",
            "propagation",
            "punch",
            "final",
            "initial",
        ):
            if kind in self.events[k]:
                return kind
        return "grid"


def build_schedule(
    start_s: float,
    stop_s: float,
    tracking_times: list[np.ndarray],
    events: list[tuple[str, np.ndarray, float | None]],
    thrust_switches: list[tuple[float, str]],
    punch_times: np.ndarray | None = None,
    grid_times: np.ndarray | None = None,
) -> Schedule:
    """SCHED: merge tracking, user events, thrust switches and punch times inside [start, stop].

    tracking_times[j]: observation times (s) of tracking entry j; events: (type, times_s,
    predict_to_s or None); thrust_switches: (t_s, "thrust_on" | "thrust_off"); grid_times:
    extra output times of the reference that carry no event (the starts t_M - dt_c of
    one-way Doppler counts, whose state and transition the count's H row needs).
    """
    lo, hi = _key(start_s), _key(stop_s)
    per: dict[int, set[str]] = {lo: {"initial"}}
    trk: dict[int, list[int]] = {}
    pred: dict[int, list[float]] = {}

    def add(t: float, kind: str) -> int | None:
        k = _key(t)
        if k < lo or k > hi:
            return None
        per.setdefault(k, set()).add(kind)
        return k

    for j, ts in enumerate(tracking_times):
        for t in ts:
            k = add(float(t), "measurement")
            if k is not None:
                trk.setdefault(k, []).append(j)
    for kind, ts, to in events:
        for t in ts:
            k = add(float(t), kind)
            if k is not None and kind == "prediction":
                pred.setdefault(k, []).append(float(to))
    for t, kind in thrust_switches:
        add(float(t), kind)
    for t in np.atleast_1d(np.zeros(0) if punch_times is None else punch_times):
        add(float(t), "punch")
    for t in np.atleast_1d(np.zeros(0) if grid_times is None else grid_times):
        k = _key(float(t))
        if lo <= k <= hi:
            per.setdefault(k, set())
    add(stop_s, "final")
    keys = sorted(per)
    order = {e: i for i, e in enumerate(EVENT_ORDER)}
    sched = Schedule(
        times_s=np.array(keys, dtype=np.float64) * TIME_RESOLUTION_S,
        events=[sorted(per[k], key=order.__getitem__) for k in keys],
        tracking=[sorted(trk.get(k, [])) for k in keys],
    )
    for i, k in enumerate(keys):
        if k in pred:
            sched.predict_to_s[i] = pred[k]
    return sched


def days(t_s) -> np.ndarray:
    return np.asarray(t_s, dtype=np.float64) / DAY_S
