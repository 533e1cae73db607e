"""The two-vehicle study and its record (Draper R-649; :mod:`fracas.team.two_vehicle`):
the measurement biases, resets and maneuvers a study carries, the per-role scan inputs and
a run's covariances, gains and maneuver covariances."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fracas.measurements.relative import RELATIVE_KINDS

__all__ = [
    "ROLES",
    "KIND_NAMES",
    "BiasSpec",
    "ResetSpec",
    "ManeuverSpec",
    "RendezvousStudy",
    "RoleCase",
    "RendezvousRun",
]

ROLES = ("solve_for", "consider", "ignore")
KIND_NAMES = tuple(RELATIVE_KINDS)


@dataclass(frozen=True)
class BiasSpec:
    """A measurement bias: name, kind (index into RELATIVE_KINDS), sigma (kind unit), role,
    tau_s (inf: constant)."""

    name: str
    kind: int
    sigma: float
    role: str
    tau_s: float = float("inf")


@dataclass(frozen=True)
class ResetSpec:
    """Assumed-covariance reset at event ``k``: chaser sigmas (6,) km, km/s; the roles it applies to."""

    k: int
    sigma: np.ndarray
    roles: tuple[str, ...]


@dataclass(frozen=True)
class ManeuverSpec:
    """An intercept at event ``k`` (time_s) arriving at arrival_s; M (3, 12) its sensitivity
    to [x_A; x_T]; dv_km_s (3,) on the reference; status 0 converged."""

    name: str
    k: int
    time_s: float
    arrival_s: float
    M: np.ndarray
    dv_km_s: np.ndarray
    status: int


@dataclass(frozen=True)
class RendezvousStudy:
    """Everything a two-vehicle run needs, in km, s, rad (module docstring).

    times_s (K,): event times from the chaser's epoch (times_s[0] is the a-priori time);
    x_chaser, x_target (K, 6); phi_chaser, phi_target (K, 6, 6) step matrices
    Phi(t_k, t_{k-1}) (identity at k = 0); marks (K, 4) bool: the kinds measured at event k;
    noise_assumed / noise_true (4, 3): [sigma, fraction, floor] per kind (kind units);
    axes (3, 3): the LOS-angle sensor frame; P0_true (n, n) the true a priori; chaser_load
    (6,) or None: the ignore role's diagonal filter load (sigmas); roles: the target roles
    to compute; reference_sources: where each vehicle's reference came from ("integrated",
    an STM file path); two_body: both references are point-mass ballistic about the centre (the
    nonlinear single runs fly the conics exactly)."""

    title: str
    source: str
    chaser_name: str
    target_name: str
    centre: str
    mu_km3_s2: float
    times_s: np.ndarray
    x_chaser: np.ndarray
    x_target: np.ndarray
    phi_chaser: np.ndarray
    phi_target: np.ndarray
    marks: np.ndarray
    noise_assumed: np.ndarray
    noise_true: np.ndarray
    axes: np.ndarray
    P0_true: np.ndarray
    chaser_load: np.ndarray | None
    biases: tuple[BiasSpec, ...]
    roles: tuple[str, ...]
    resets: tuple[ResetSpec, ...] = ()
    maneuvers: tuple[ManeuverSpec, ...] = ()
    length_unit: str = "km"
    km_per_unit: float = 1.0
    epoch_et_s: float = 0.0
    two_body: bool = False
    reference_sources: tuple[str, str] = ("integrated", "integrated")

    @property
    def nb(self) -> int:
        return len(self.biases)

    @property
    def n(self) -> int:
        return 12 + self.nb

    @property
    def labels(self) -> list[str]:
        st = ["x", "y", "z", "vx", "vy", "vz"]
        return (
            [f"{self.chaser_name}.{s}" for s in st]
            + [f"{self.target_name}.{s}" for s in st]
            + [b.name for b in self.biases]
        )

    @property
    def units(self) -> list[str]:
        u = ["km"] * 3 + ["km/s"] * 3
        kind_units = [RELATIVE_KINDS[k][1] for k in KIND_NAMES]
        return u + u + [kind_units[b.kind] for b in self.biases]


@dataclass
class RoleCase:
    """One role's inputs to the scan: est (n,) 0/1 mask, P0_assumed (n, n), Q_assumed
    (K, n, n), reset_flag (K,), reset_cov (K, 6, 6)."""

    role: str
    est: np.ndarray
    P0_assumed: np.ndarray
    Q_assumed: np.ndarray
    reset_flag: np.ndarray
    reset_cov: np.ndarray


@dataclass
class RendezvousRun:
    """A run's covariances per role (axis 0: role, in study.roles order): P_true / P_assumed
    (R, K, n, n) after each event's updates, P_true_minus / P_assumed_minus before them;
    gains (R, K, 4, n); H (K, 4, n) and r_true (K, 4) the marks' rows and true variances
    (what the single runs draw from); maneuver_cov_true / _assumed (R, J, 3, 3) the
    maneuver-solution covariances (km^2/s^2)."""

    study: RendezvousStudy
    P_true: np.ndarray
    P_assumed: np.ndarray
    P_true_minus: np.ndarray
    P_assumed_minus: np.ndarray
    gains: np.ndarray
    H: np.ndarray
    r_true: np.ndarray
    maneuver_cov_true: np.ndarray
    maneuver_cov_assumed: np.ndarray
