"""Two-vehicle TEAM: rendezvous navigation covariance analysis and single runs (Draper R-649).

The augmented state is [x_A (6); x_T (6); beta (nb)] (chaser r km, v km/s; target; radar
biases in their measurement units).  Each vehicle has its own reference trajectory and
step transition matrices; the biases are constant or first-order Gauss-Markov.  The target
and each bias take a ROLE (FRACAS augmentation vocabulary; digest ``unf-apollo.md`` §C.1):

=============  ============================  ==========================================
role           filter (assumed covariance)   R-649
=============  ============================  ==========================================
solve_for      estimated; a priori = truth   optimum two-vehicle filter (Eq. 20)
consider       not estimated; its covariance Schmidt: omega_T = 0, the gain uses E_T, G
               and correlations in the gain
ignore         absent (zero blocks)          the Apollo filter (Eq. 26): its 6x6 W W'
                                             taken as E_R; evaluated by generalized
                                             covariance (the true covariance carries E_T)
=============  ============================  ==========================================

Per event k (times from the chaser's epoch): time update P <- Phi P Phi' + Q (both the
assumed and the true covariance), the assumed-covariance reset when one is scheduled
(UNF/Apollo W reinitialization: the chaser block of the ASSUMED covariance is set to
diag(sigma^2) and its correlations to zero; the true covariance continues), then each
scalar mark in turn (range, range rate, beta, theta; no extrapolation between them,
UNF §A.4.1): gain k = mask * Pa h / (h'Pa h + r_a) from the assumed covariance, Joseph
update of the assumed covariance with r_a and of the true one with r_t.

Single runs (the R-649 figures' "single run"; TSIM's linear engine): the estimation error
e = x_hat - x of every state is drawn from the true a priori and carried with the SAME
gains, e <- Phi e + w, e <- e - k (h'e + n) with n ~ N(0, r_t), so its sample covariance
tests the covariance recursion by an independent path (sampling instead of Joseph).

Maneuvers (R-649 Fig. II-18): an intercept solved from the estimated states errs by
M (x_hat - x) (:mod:`fracas.guidance.intercept`); its covariance is M E M' with E the true
knowledge covariance at the maneuver time.

Pure numpy/JAX; the scans are jitted once per shape; nothing raises inside them.

The package: :mod:`.model` (the study, its specs and the run's record),
:mod:`.covariance` (the augmented matrices, the marks' rows, the covariance scan of every
role, the RMS histories), :mod:`.single_runs` (linear and nonlinear single runs and their
statistics).
"""

from fracas.team.two_vehicle.covariance import _phi_aug as _phi_aug  # benchmarks/bench_rendezvous.py
from fracas.team.two_vehicle.covariance import (
    measurement_rows,
    rms_histories,
    role_setup,
    run_rendezvous_study,
)
from fracas.team.two_vehicle.model import (
    KIND_NAMES,
    ROLES,
    BiasSpec,
    ManeuverSpec,
    RendezvousRun,
    RendezvousStudy,
    ResetSpec,
    RoleCase,
)
from fracas.team.two_vehicle.single_runs import (
    RMS_GROUPS,
    envelope_rates,
    nonlinear_single_runs,
    sample_rms,
    single_runs,
)

__all__ = [
    "ROLES",
    "BiasSpec",
    "ResetSpec",
    "ManeuverSpec",
    "RendezvousStudy",
    "RoleCase",
    "RendezvousRun",
    "role_setup",
    "run_rendezvous_study",
    "single_runs",
    "nonlinear_single_runs",
    "envelope_rates",
    "rms_histories",
    "sample_rms",
    "RMS_GROUPS",
    "KIND_NAMES",
    "measurement_rows",
]
