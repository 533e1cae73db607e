"""The product of one TEAM run (FRACAS TEAM, ``fracas.team.result``): :class:`TeamProduct`
and its parts -- covariance histories with their eigenvector events (SETEVN), the
measurement log, predictions (PRED), guidance events (GUIDM), the control covariance and
the error budget.  Numpy-only.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = [
    "EigenEvents",
    "CovarianceHistory",
    "MeasurementLog",
    "Prediction",
    "GuidanceEvent",
    "ControlHistory",
    "ErrorBudget",
    "TeamProduct",
]


@dataclass(frozen=True)
class EigenEvents:
    """Eigenvector events (FRACAS SETEVN) of one covariance history: at schedule indices
    ``index`` (k,), the position/velocity block eigenvalues (k, 3) km^2 and km^2/s^2
    (ascending), eigenvectors (k, 3, 3) as columns (sign: largest entry positive) and the
    correlation matrices (k, n, n)."""

    index: np.ndarray
    position_eigenvalues: np.ndarray
    position_eigenvectors: np.ndarray
    velocity_eigenvalues: np.ndarray
    velocity_eigenvectors: np.ndarray
    correlations: np.ndarray


@dataclass(frozen=True)
class CovarianceHistory:
    """One covariance history (assumed or true) over a schedule of K events.

    P_minus / P_plus (K, n, n): before / after the event at each time (rows and columns as
    the product's labels and units); process_noise (K, nx, nx): DYNO's Q̃ over the interval
    ending at each time; sigma (K, n): 1σ after each event; a_priori_sigma (n,): 1σ of the
    a-priori covariance; eigen: the eigenvector events; event_status (K,) int: the
    :class:`fracas.status.RunStatus` of P_plus at each event (0 OK, 6 not positive-definite,
    7 non-finite; None when not computed).
    """

    P_minus: np.ndarray
    P_plus: np.ndarray
    process_noise: np.ndarray
    sigma: np.ndarray
    a_priori_sigma: np.ndarray
    eigen: EigenEvents
    event_status: np.ndarray | None = None


@dataclass(frozen=True)
class MeasurementLog:
    """Every scheduled observation (m of them), used or skipped below the elevation mask.

    index (m,): schedule index; tracking (m,): [[tracking]] entry; kind, stations (m,);
    value (m,): computed observable (km, km/s or rad); elevation_deg (m,) (NaN where not
    defined); used (m,) bool; sigma (m,): assumed noise; innovation_sigma (m,):
    sqrt(H P- H^T + R) of the assumed filter (NaN where skipped).
    """

    index: np.ndarray
    tracking: np.ndarray
    kind: list[str]
    stations: list[str]
    value: np.ndarray
    elevation_deg: np.ndarray
    used: np.ndarray
    sigma: np.ndarray
    innovation_sigma: np.ndarray


@dataclass(frozen=True)
class Prediction:
    """A prediction event (FRACAS PRED): the knowledge at schedule index ``from_index``
    mapped to ``time_to_s``; ``true`` is None without generalized covariance; ``status``:
    a :class:`fracas.status.RunStatus` value (non-zero: the matrices are NaN)."""

    from_index: int
    time_from_s: float
    time_to_s: float
    assumed: np.ndarray
    true: np.ndarray | None
    status: int = 0


@dataclass
class GuidanceEvent:
    """One TEAM guidance event's results (GUIDM's printout, digest B.10).

    index: schedule index of time_s (guidance epoch or initiation, s); cutoff_s, target_time_s
    (s); target_body; estimate_model: the P̃ model; rank: of the targeting matrix; targets
    (m) and controls (M) with units (impulsive: dv_x, dv_y, dv_z in km/s); psi (m, n): Ψ at
    the cutoff; gamma (M, n): the guidance law δU = −Γ δX̂; target_cov_before / after
    (m, m): the dispersion AT THE TARGET TIME without and with the correction: the control
    covariance at the cutoff mapped by Ψ plus the process noise from the cutoff to the
    target time (``target_noise_cov``), what the spacecraft arrives with;
    target_cov_knowledge (m, m): the knowledge at the event mapped by Ψ (no noise after
    it); target_noise_cov (m, m): A_T Q(t_c → t_f) A_Tᵀ, the true process noise from the
    cutoff to the target time mapped to the targets (included in before and after; None
    in files written before it existed, whose before/after lack it); correction_cov,
    execution_cov (M, M); mean, 99 % and RMS |ΔV| km/s (low thrust: of the arc's ΔV
    change); propellant_sigma_kg (low thrust); status;
    dv_jacobian (M,): the arc's ΔV change per unit of each control (low thrust; TSIM's |ΔV|);
    control_matrix (m, M): K = Ψ(t_c) S, the targets' change per unit of each control (low thrust)."""

    name: str
    type: str
    index: int
    time_s: float
    cutoff_s: float
    target_time_s: float
    target_body: str
    estimate_model: str
    rank: int
    target_names: list[str]
    target_units: list[str]
    control_labels: list[str]
    control_units: list[str]
    psi: np.ndarray
    gamma: np.ndarray
    target_cov_before: np.ndarray
    target_cov_after: np.ndarray
    target_cov_knowledge: np.ndarray
    correction_cov: np.ndarray
    execution_cov: np.ndarray
    dv_mean_km_s: float = float("nan")
    dv_99_km_s: float = float("nan")
    dv_rms_km_s: float = float("nan")
    propellant_sigma_kg: float = float("nan")
    status: int = 0
    dv_variance_km2_s2: float = float("nan")  # E|ΔV|² unclipped (linear in the error sources)
    dv_jacobian: np.ndarray | None = None  # (M,) low thrust: the arc's ΔV change per control (km/s per unit)
    control_matrix: np.ndarray | None = None  # (m, M) low thrust: K = Ψ(t_c) S, targets per control
    target_noise_cov: np.ndarray | None = None  # (m, m) process noise cutoff -> target time, at the targets


@dataclass
class ControlHistory:
    """The control covariance (actual − reference, GUIDM's P_c) over the schedule: P_plus
    (K, n, n) after each event, sigma (K, n), epoch_index (K,) the schedule index of its last
    reset (a guidance event), a_priori (n, n) the initial control covariance."""

    P_plus: np.ndarray
    sigma: np.ndarray
    epoch_index: np.ndarray
    a_priori: np.ndarray


@dataclass
class ErrorBudget:
    """outputs / units (n_out,); sources (n_src,); variance (n_out, n_src): each source's
    contribution to each output's variance (unit²); total (n_out,): the full run's
    variance; sum_check: max |Σ_s variance − total| / total (fracas.team.budget)."""

    outputs: list[str]
    units: list[str]
    sources: list[str]
    variance: np.ndarray
    total: np.ndarray
    sum_check: float


@dataclass(frozen=True)
class TeamProduct:
    """The result of one TEAM run, labelled and self-contained (no deck, no engine state).

    times_s (K,) s from the trajectory epoch ``epoch_et_s`` (TDB s past J2000); event_types
    (K,): the events at each time joined by "+"; states (K, 7) and primary (K,): the
    reference; labels / units / roles (n,): rows and columns of every covariance (state,
    parameters [, PDOT noise states]); n_state: 6 or 7; assumed / true: the histories (true
    is None without generalized covariance); tracking: (kind, stations joined by "+") of
    each [[tracking]] entry; psd_problems: (schedule index, event, "assumed" | "true",
    smallest eigenvalue in the covariance's mixed units); punch_indices: schedule indices
    of the punch events; status: a :class:`fracas.status.RunStatus` value; settings: how
    the run was made (filter, propagation, square root, generalized covariance, reference
    source, print options); provenance: deck text and path, versions.
    """

    title: str
    source: str
    epoch_et_s: float
    times_s: np.ndarray
    event_types: list[str]
    states: np.ndarray
    primary: list[str]
    labels: list[str]
    units: list[str]
    roles: list[str]
    n_state: int
    assumed: CovarianceHistory
    true: CovarianceHistory | None
    measurements: MeasurementLog
    tracking: list[tuple[str, str]]
    predictions: list[Prediction]
    psd_problems: list[tuple[int, str, str, float]]
    punch_indices: list[int]
    status: int
    settings: dict[str, Any] = field(default_factory=dict)
    timing: dict[str, float] = field(default_factory=dict)
    provenance: dict[str, Any] = field(default_factory=dict)
    guidance: list[GuidanceEvent] = field(default_factory=list)
    control: ControlHistory | None = None
    budget: ErrorBudget | None = None

    @property
    def n_events(self) -> int:
        return int(np.shape(self.times_s)[0])
