"""A TEAM study as the core sees it (FRACAS DATA's output): arrays and core objects in
canonical units, nothing that refers back to a deck.

:func:`fracas.build.team.build_study` makes one from a validated TEAM deck (the one place
where its days, hours, degrees and deck sigmas become s, rad, km and km/s); a sweep or TSIM
may build or vary one in memory (``dataclasses.replace``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from fracas.filters.covariance import Layout
from fracas.integrate.problem import Problem
from fracas.measurements import trakm
from fracas.measurements.stations import Station
from fracas.params import STATE_LABELS, STATE_UNITS
from fracas.team.schedule import Schedule

__all__ = ["Study", "TrackingSpec", "GuidanceSpec", "NOISE_COMPONENTS", "NOISE_STATE_LABELS"]

NOISE_COMPONENTS = ("proportionality", "in_plane", "out_of_plane")  # Gauss-Markov thrust errors, in this order
#: the labels of the three thrust-error states when exact Gauss-Markov carries them (NOISE_COMPONENTS' order)
NOISE_STATE_LABELS = ["eta_proportionality", "eta_in_plane_rad", "eta_out_of_plane_rad"]


@dataclass(frozen=True)
class TrackingSpec:
    """One [[tracking]] entry: measurement kind, stations, observed body, star direction.

    star_unit (3,): unit vector to the star of a star-planet angle (ICRF), else None.
    """

    kind: str
    stations: tuple[str, ...]
    body: str | None = None
    star_unit: np.ndarray | None = None


@dataclass(frozen=True)
class GuidanceSpec:
    """One guidance event (GUIDM §5.3.6, XGUID §5.3.25) in canonical units.

    type: "impulsive" | "primary" | "vernier" | "none"; time_s: guidance epoch t_G or
    initiation t_I (s); cutoff_s: t_c (the corrected arc's end for low thrust, = time_s
    otherwise); target_time_s: t_f where the targets are evaluated; targets: names of
    :data:`fracas.guidance.target_kinds.TARGET_KINDS`; target_body: "" for the central body
    at t_f; arc: the corrected thrust arc (low thrust); controls / control_labels /
    control_units: low-thrust controls and the parameter labels they vary; weights (per
    control or ΔV component) and tolerances (per target), None for ones; sigma_p (fraction),
    sigma_pointing_rad (each of two angles), sigma_res_km_s: execution errors;
    verniers_follow: a later vernier corrects the same arc (GUIDM's reset rule).
    """

    name: str
    type: str
    time_s: float
    cutoff_s: float
    target_time_s: float
    targets: tuple[str, ...]
    target_body: str = ""
    arc: int = -1
    controls: tuple[str, ...] = ()
    control_labels: tuple[str, ...] = ()
    control_units: tuple[str, ...] = ()
    weights: tuple[float, ...] | None = None
    tolerances: tuple[float, ...] | None = None
    sigma_p: float = 0.01
    sigma_pointing_rad: float = 7.0e-3
    sigma_res_km_s: float = 1.0e-5
    verniers_follow: bool = False

    @property
    def low_thrust(self) -> bool:
        return self.type in ("primary", "vernier")


@dataclass
class Study:
    """Everything a TEAM run needs, in km, s, kg, rad (ICRF).

    problem: the reference trajectory's propagation (its parameter columns are the study's
    dynamic labels); labels: augmented parameter labels in layout order [s, u, v, w];
    dynamic[i]: whether the trajectory depends on labels[i] (its column is in the STM file);
    P0_assumed / P0_true (n, n): a-priori covariances (the assumed one has zero ignore
    rows/columns); noise_sigma_* (3,), noise_tau_* (3,) s: Gauss-Markov thrust noise
    (proportionality, in-plane rad, out-of-plane rad), assumed and true; tracking[j],
    observations[j], true_sigma[j]: tracking entry j, its observation and the real-world
    noise sigma (km, km/s or rad); thrust_switches_s: the thrust on/off times of the
    trajectory (sorted, s); trajectory_end_s: where the reference trajectory ends (s);
    pdot_step_s: the largest RK4 step of PDOT propagation (s); noise_model: PHI mode's
    thrust-noise model, "exact" (the noise states augmented; fracas.team.gm_exact),
    "grid" (DYNO on fixed cells of noise_step_s, s) or "interval" (FRACAS's DYNO per
    schedule interval; fracas.team.transitions); resets: (t_s, six
    sigmas km, km/s) of the assumed-covariance reset events; source: where the study came
    from (a deck path, for messages); user_gain_spec: the "module:function" of a user gain;
    white_q_assumed / white_q_true (km^2/s^3), white_direction_* ("full", "crosstrack",
    "radial", "along"): white acceleration process noise on the velocity (UNF s_q, digest
    unf-apollo.md A.5.4), assumed and true; white_step_s: its quadrature pieces' longest
    length (s; fracas.team.transitions.white_unit_noise).
    """

    source: str
    title: str
    problem: Problem
    layout: Layout
    labels: list[str]
    roles: list[str]
    units: list[str]
    dynamic: np.ndarray
    P0_assumed: np.ndarray
    P0_true: np.ndarray
    noise_sigma_assumed: np.ndarray
    noise_tau_assumed: np.ndarray
    noise_sigma_true: np.ndarray
    noise_tau_true: np.ndarray
    stations: dict[str, Station]
    tracking: list[TrackingSpec]
    observations: list[trakm.Observation]
    true_sigma: np.ndarray
    schedule: Schedule
    start_s: float
    stop_s: float
    gencov: bool
    filter_kind: str
    square_root: bool
    user_gain: Callable | None
    min_elevation_deg: float
    propagation: str
    thrust_switches_s: tuple[float, ...] = ()
    trajectory_end_s: float = 0.0
    pdot_step_s: float = 3600.0
    noise_model: str = "exact"
    P0_noise_states: tuple | None = None  # (assumed, true, control or None) (n + 3, n + 3), punched
    gm_states: bool = False  # the last three states are the exact model's eta (fracas.team.gm_exact.augmented_view)
    noise_step_s: float = 3600.0
    user_gain_spec: str = ""
    trajectory_hash: str = ""
    trajectory_source: str = ""
    punched: dict | None = None
    guidance: tuple[GuidanceSpec, ...] = ()
    resets: tuple[tuple[float, tuple[float, ...]], ...] = ()
    guidance_model: str = "report"
    guidance_reset: str = "state"
    guidance_estimates: str = "state"
    P0_control: np.ndarray | None = None
    budget: bool = False
    budget_at_s: tuple[float, ...] = ()
    white_q_assumed: float = 0.0
    white_q_true: float = 0.0
    white_direction_assumed: str = "full"
    white_direction_true: str = "full"
    white_step_s: float = 3600.0

    @property
    def nx(self) -> int:
        return self.layout.nx

    @property
    def dynamic_labels(self) -> list[str]:
        return [lab for lab, d in zip(self.labels, self.dynamic) if d]

    @property
    def state_labels(self) -> list[str]:
        return list(STATE_LABELS[: self.nx])

    @property
    def state_units(self) -> list[str]:
        return list(STATE_UNITS[: self.nx])

    @property
    def has_noise(self) -> bool:
        """Whether there is Gauss-Markov thrust noise (assumed, or true with gencov)."""
        return bool(np.any(self.noise_sigma_assumed > 0) or (self.gencov and np.any(self.noise_sigma_true > 0)))

    @property
    def has_white_noise(self) -> bool:
        """Whether there is white acceleration noise (assumed, or true with gencov)."""
        return bool(self.white_q_assumed > 0 or (self.gencov and self.white_q_true > 0))

    @property
    def has_process_noise(self) -> bool:
        """Whether there is any process noise (Gauss-Markov thrust or white acceleration)."""
        return self.has_noise or self.has_white_noise
