"""The product of one two-vehicle (rendezvous) navigation run: :class:`RendezvousProduct`.
Numpy-only.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["RendezvousProduct"]


@dataclass
class RendezvousProduct:
    """The result of one two-vehicle (rendezvous) navigation run, self-contained.

    roles (R,): the target roles computed ("solve_for" | "consider" | "ignore"); labels,
    units (n,): [chaser r, v; target r, v; biases]; times_s (K,): events from the chaser's
    epoch (epoch_et_s, TDB s past J2000); marks (K, 4): the kinds measured at each event
    (range, range_rate, los_beta, los_theta); x_chaser / x_target (K, 6) km, km/s about
    ``centre``; P_true / P_assumed (R, K, n, n) after each event's updates, P_true_minus /
    P_assumed_minus before them; maneuvers: names, time_s, arrival_s, dv_km_s (J, 3) on the
    reference, status (J,), cov_true / cov_assumed (R, J, 3, 3) the maneuver-solution
    covariances from knowledge errors (km^2/s^2); single runs: n_runs, seed, run_errors
    (R, keep, K, n) the kept runs' estimation errors, run_maneuver_errors (R, n_runs, J, 3)
    (km/s), envelope_1sigma / envelope_3sigma (R,) the fractions of single-run error
    components inside the true 1- and 3-sigma and their standard errors (_se, across
    runs); run_dynamics: "linear" | "two_body" (how the runs flew); reference_sources:
    where each vehicle's reference came from ("integrated" or its STM file); team_rms /
    assumed_rms (R, K, 6) the RMS magnitudes of the true and assumed covariances after each
    event in the same six groups as run_rms (km, km/s); run_rms (R, K, 6)
    the runs' sample RMS of chaser, target and relative position and velocity errors
    (km, km/s); length_unit / km_per_unit: the deck's unit
    for display; provenance: deck texts and versions."""

    title: str
    source: str
    epoch_et_s: float
    centre: str
    chaser_name: str
    target_name: str
    roles: list[str]
    labels: list[str]
    units: list[str]
    times_s: np.ndarray
    marks: np.ndarray
    x_chaser: np.ndarray
    x_target: np.ndarray
    P_true: np.ndarray
    P_assumed: np.ndarray
    P_true_minus: np.ndarray
    P_assumed_minus: np.ndarray
    maneuver_names: list[str]
    maneuver_time_s: np.ndarray
    maneuver_arrival_s: np.ndarray
    maneuver_dv_km_s: np.ndarray
    maneuver_status: np.ndarray
    maneuver_cov_true: np.ndarray
    maneuver_cov_assumed: np.ndarray
    reset_times_s: np.ndarray
    n_runs: int = 0
    seed: int = 0
    run_errors: np.ndarray | None = None
    run_maneuver_errors: np.ndarray | None = None
    envelope_1sigma: np.ndarray | None = None
    envelope_3sigma: np.ndarray | None = None
    envelope_1sigma_se: np.ndarray | None = None
    envelope_3sigma_se: np.ndarray | None = None
    run_dynamics: str = ""
    reference_sources: list[str] = field(default_factory=list)
    team_rms: np.ndarray | None = None
    assumed_rms: np.ndarray | None = None
    run_rms: np.ndarray | None = None
    length_unit: str = "km"
    km_per_unit: float = 1.0
    timing: dict[str, float] = field(default_factory=dict)
    provenance: dict[str, Any] = field(default_factory=dict)
