"""Stage products: frozen, labelled objects that pass from stage to stage.

A product holds arrays with their labels, units, epochs and provenance, and nothing that
points back at a deck or at engine state.  ``fracas.io`` serialises products and reads them
back; ``fracas.report`` reads the files.  This module is numpy-only (no jax, h5py or
pydantic), so every layer may import it.

* :class:`ReferenceTrajectory` -- a reference trajectory sampled at the times analyses need,
  with Phi and Theta between consecutive times (the STM file's contents, FRACAS STMGEN).
  :func:`chain` multiplies its step matrices over skipped times (STMRDR, section 3.2).
* :class:`TeamProduct` -- the covariance history of one TEAM run (``fracas.team.result``).
* :class:`TomProduct` -- one TOM run: controls, targets, final mass, iteration history.
* :class:`TrajectoryData` -- one propagation with its optional :class:`SensitivityData`
  (``fracas.build.trajectory_product.trajectory_data``; the trajectory file's contents).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from fracas.constants import DAY_S
from fracas.errors import StmFileError
from fracas.status import status_text

__all__ = [
    "ReferenceTrajectory",
    "TeamProduct",
    "GuidanceEvent",
    "ControlHistory",
    "ErrorBudget",
    "TrajectoryData",
    "SensitivityData",
    "TomProduct",
    "chain",
    "time_indices",
    "SCHEMA_VERSION",
    "TIME_TOL_S",
]

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


# --------------------------------------------------------------------------- describe


# --------------------------------------------------------------------------- TEAM


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
    the cutoff; gamma (M, n): the guidance law δU = −Γ δX̂; target_cov_before / after /
    knowledge (m, m): the dispersion before and after the correction and the knowledge
    mapped to the target; correction_cov, execution_cov (M, M); mean, 99 % and RMS |ΔV| km/s
    (low thrust: of the arc's ΔV change); propellant_sigma_kg (low thrust); status;
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


# --------------------------------------------------------------------------- propagation


@dataclass
class SensitivityData:
    """Labelled sensitivity matrices at the output times (state order x y z vx vy vz mass).

    stm_step (n,7,7) Phi(t_k, t_{k-1}); stm (n,7,7) Phi(t_k, t_0); par_step (n,7,np)
    dx(t_k)/dp with x(t_{k-1}) fixed; par (n,7,np) dx(t_k)/dp from t_0.  Element (i, j) has
    units ``STATE_UNITS[i] / col_units[j]``.
    """

    stm: np.ndarray
    stm_step: np.ndarray
    par: np.ndarray
    par_step: np.ndarray
    param_labels: tuple[str, ...] = ()
    param_units: tuple[str, ...] = ()


@dataclass
class TrajectoryData:
    """One propagation as stored in a trajectory file (numpy; canonical units; ICRF).

    t_s (n,) s from the epoch (NaN after an early stop); r_km (n,3), v_km_s (n,3),
    mass_kg (n,) relative to ``primary[k]`` (a body name, "" where undefined); status
    0 final time / 1 stop condition / 2 max steps / 3 non-finite (:class:`fracas.status.RunStatus`).
    """

    epoch_et_s: float
    t_s: np.ndarray
    r_km: np.ndarray
    v_km_s: np.ndarray
    mass_kg: np.ndarray
    primary: tuple[str, ...]
    bodies: tuple[str, ...]
    t_final_s: float
    r_final_km: np.ndarray
    v_final_km_s: np.ndarray
    mass_final_kg: float
    primary_final: str
    status: int
    n_steps: int
    n_rect: int
    centre: str = ""
    title: str = ""
    epoch_tdb: str = ""
    n_reject: int = 0  # steps rejected by the error control (tolerance step control)
    integrator: str = ""  # e.g. "dprkn12, cowell, tolerance 1e-12" (fracas.integrate.highorder)
    sensitivities: SensitivityData | None = None
    provenance: dict[str, Any] = field(default_factory=dict)

    @property
    def status_text(self) -> str:
        return status_text(self.status)

    def summary_dict(self) -> dict[str, Any]:
        """Plain-JSON summary of the end of the propagation."""
        return {
            "title": self.title,
            "epoch_et_s": float(self.epoch_et_s),
            "t_final_s": float(self.t_final_s),
            "r_km": [float(x) for x in self.r_final_km],
            "v_km_s": [float(x) for x in self.v_final_km_s],
            "mass_kg": float(self.mass_final_kg),
            "primary": self.primary_final,
            "status": int(self.status),
            "status_text": self.status_text,
            "n_steps": int(self.n_steps),
            "n_rect": int(self.n_rect),
        }


# --------------------------------------------------------------------------- TOM
@dataclass
class TomProduct:
    """The result of one TOM run (targeting and final-mass optimization), self-contained.

    Controls (M) and targets (N) are stored in deck units (``control_units``,
    ``target_units``: days, deg, km, km/s, 1); ``control_factor`` / ``target_factor`` give
    the canonical unit per deck unit.  u_start / u_final (M,) controls; lower / upper (M,)
    bounds; desired / tolerance / achieved (N,) targets, achieved from the plain-core
    re-propagation of u_final (the verification); final_mass_kg, initial_mass_kg.
    History (K iterations): iteration, submode, performance_kg, error_rms, angle_rad, gamma,
    n_trajectories, controls (K, M), targets (K, N).  stop_reason: why the search stopped;
    converged: the verified verdict (every target within tolerance on re-propagation and,
    when optimizing, the search's optimality test); search_converged: the optimizer's own
    claim (recorded, never trusted alone).  s_matrix (N, M), g_vector (M,) at u_final in
    deck units.  trials: every line-search trial trajectory (GENMIN/FUNCT) as rows (iteration,
    γ, F(γ), final mass kg, error index E, ok).  grid: GRID's tables (or None): ``{"single": (M, 2J) E, "single_gammas":
    (2J,), "pairs": {(a, b): (2J, 2J) E}}``.
    """

    title: str
    source: str
    submode: str
    optimizer: str
    sensitivities: str
    control_names: list[str]
    control_units: list[str]
    control_factor: np.ndarray
    u_start: np.ndarray
    u_final: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    target_names: list[str]
    target_bodies: list[str]
    target_units: list[str]
    target_factor: np.ndarray
    desired: np.ndarray
    tolerance: np.ndarray
    achieved_start: np.ndarray
    achieved: np.ndarray
    initial_mass_kg: float
    start_mass_kg: float
    final_mass_kg: float
    stop_reason: str
    converged: bool
    search_converged: bool
    targets_met: bool
    iteration: np.ndarray
    submodes: list[str]
    performance_kg: np.ndarray
    error_rms: np.ndarray
    angle_rad: np.ndarray
    gamma: np.ndarray
    n_trajectories: np.ndarray
    controls: np.ndarray
    targets: np.ndarray
    s_matrix: np.ndarray | None = None
    g_vector: np.ndarray | None = None
    grid: dict | None = None
    trials: np.ndarray | None = None  # (T, 6): iteration, gamma, cost F(gamma), mass kg, E, ok (1/0)
    reference_deck: str = ""
    timing: dict[str, float] = field(default_factory=dict)
    provenance: dict[str, Any] = field(default_factory=dict)
    # what was maximized: "final_mass" (kg) or a target kind ([tom] performance, its deck unit;
    # minimized when maximize = false); its value at the start and final controls, deck units;
    # performance_kg above then holds it per iteration in canonical units
    performance_name: str = "final_mass"
    performance_unit: str = "kg"
    performance_start: float = float("nan")
    performance_final: float = float("nan")

    @property
    def target_error(self) -> np.ndarray:
        """Achieved − desired (deck units; angles wrapped to ±180 deg)."""
        d = np.asarray(self.achieved, float) - np.asarray(self.desired, float)
        ang = np.array([u == "deg" for u in self.target_units], bool)
        if ang.any():
            d[ang] = -np.remainder(-d[ang] + 180.0, 360.0) + 180.0
        return d


# --------------------------------------------------------------------------- TSIM
@dataclass
class TsimManeuver:
    """One TSIM maneuver as flown, with TEAM's predictions for it.

    type: "impulsive" | "primary" | "vernier"; law: "linear" | "nonlinear"; time_s (s);
    control_labels / control_units (M,) (impulsive: dv_x, dv_y, dv_z km/s); target_names /
    target_units / target_time_s: its target set; team_correction_cov (M, M): TEAM's
    covariance of the commanded correction (P_ΔV or P_U); team_dv_mean_km_s, team_dv_99_km_s:
    TEAM's exact mean and 99 % |ΔV| (the Hoffman-Young stand-in, digest (G-9); low thrust:
    of the arc's ΔV change, Gaussian); team_target_cov_after (m, m): TEAM's target
    dispersion after this event; failures: missions it ended (hopeless); near: designs
    accepted within near_success_factor × tolerance."""

    name: str
    type: str
    law: str
    time_s: float
    control_labels: list[str]
    control_units: list[str]
    target_names: list[str]
    target_units: list[str]
    target_time_s: float
    team_correction_cov: np.ndarray
    team_dv_mean_km_s: float
    team_dv_99_km_s: float
    team_target_cov_after: np.ndarray
    failures: int = 0
    near: int = 0


@dataclass
class TsimProduct:
    """The result of one TSIM run (Monte Carlo with guidance in the loop), self-contained.

    table: the per-mission table, every array with a leading mission axis in mission-index
    order (:func:`fracas.tsim.engine.block_fields`: mission, status, failed_maneuver,
    iterations (J), initial_deviation (n), state_deviation (J, 7), knowledge_error (J, n),
    correction (J, M_max), execution_error (J, M_max), dv_km_s (J), dv_total_km_s,
    target_error (m), maneuver_status (J), linear_design_miss / design_miss (J, m), final_mass_kg).  labels (n): the
    augmented state (r, v, m, then parameters); n_state.  final_target_names / units /
    final_target_time_s and team_target_cov (m, m): TEAM's predicted final target
    dispersion (the last maneuver's "after").  statistics: name -> (count, mean, covariance)
    over the successful missions, merged with any a-priori statistics (STAT-1):
    "target_error", "dv_km_s[<maneuver>]", "correction[<maneuver>]", "dv_total_km_s",
    "final_mass_kg"; percentiles: name -> {q: value} from this run's missions; consistency:
    one row per compared output (see :mod:`fracas.tsim.summary`); counts: missions,
    ok, near, hopeless, failed (integration), a_priori (missions merged from earlier runs);
    settings: seed, first_mission, missions, scale, sampling, grid step, block, workers;
    provenance: deck text and path, versions."""

    title: str
    source: str
    epoch_et_s: float
    labels: list[str]
    n_state: int
    maneuvers: list[TsimManeuver]
    final_target_names: list[str]
    final_target_units: list[str]
    final_target_time_s: float
    team_target_cov: np.ndarray
    table: dict[str, np.ndarray]
    statistics: dict[str, tuple[int, np.ndarray, np.ndarray]]
    percentiles: dict[str, dict[float, float]]
    consistency: list[dict[str, Any]]
    counts: dict[str, int]
    settings: dict[str, Any] = field(default_factory=dict)
    timing: dict[str, float] = field(default_factory=dict)
    provenance: dict[str, Any] = field(default_factory=dict)


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
