"""PDOT's RK4 step, bounded by the dynamics (issue 24; FRACAS PATH used the deck's step alone).

The covariance equation Pdot = F P + P F^T + Q_c is integrated with classical RK4 inside
every schedule interval (:mod:`fracas.team.pdot`); its step is the deck's
``ertraj.pdot_step_hours`` capped by the fastest time scale of F, so that a LEO arc gets
seconds and a heliocentric cruise keeps the deck's step.
"""

from __future__ import annotations

import numpy as np

from fracas.team.study import Study

__all__ = ["PDOT_OMEGA_STEP", "PDOT_TAU_STEP", "pdot_step_bounds", "pdot_steps"]


#: PDOT's RK4 step bound on an orbit: h <= PDOT_OMEGA_STEP / omega, omega^2 = mu / r^3 (the
#: gravity gradient's time scale).  RK4's error on the covariance equation grows like
#: C (omega h)^4 omega t; measured on a two-body LEO arc (e 0.03, white noise) against the
#: scipy covariance ODE: C ~ 11 (9e-3 after 6 h at 72 s steps, 3.3e-5 at 18 s: 4th order),
#: so omega h = 0.015 (14 s in LEO) keeps a day within ~5e-5 (1.1e-5 measured after 6 h;
#: tests/team/test_pdot_step.py).  A fixed 2.4 h step there is unstable (omega h = 4.6 is
#: past RK4's 2.8): the covariance grew by 1e9 in 6 h.
PDOT_OMEGA_STEP = 0.015
#: ... and h <= PDOT_TAU_STEP tau for the Gauss-Markov thrust noise (the decay exp(-t/tau):
#: relative error ~ (h/tau)^4 / 120 per tau, so 0.07 keeps 400 correlation times (a 100-day
#: cruise at tau = 0.25 d) within 1e-4).
PDOT_TAU_STEP = 0.07


def pdot_step_bounds(study: Study, ref) -> np.ndarray:
    """The RK4 step (s) PDOT uses over each schedule interval (K - 1,): the deck's
    ``pdot_step_hours`` capped by ``PDOT_OMEGA_STEP / omega`` (omega = sqrt(mu / r^3), the
    larger of the interval's two ends, about the reference's primary) and by
    ``PDOT_TAU_STEP`` times the smallest Gauss-Markov tau (assumed and true): the step
    follows the dynamics, a LEO arc gets seconds and a heliocentric cruise keeps the deck's
    step (FRACAS PATH used the deck's step alone)."""
    pr = study.problem
    bodies = list(pr.model.bodies)
    mu = np.asarray(pr.params.mu, float)
    t = np.asarray(ref.times_s, float)
    st = np.asarray(ref.states, float)
    r = np.linalg.norm(st[:, :3], axis=1)
    mu_k = np.array([mu[bodies.index(p)] for p in ref.primary])
    omega = np.sqrt(mu_k / r**3)
    omega_int = np.maximum(omega[1:], omega[:-1]) if len(t) > 1 else np.zeros(0)
    with np.errstate(divide="ignore"):
        h_dyn = np.where(omega_int > 0, PDOT_OMEGA_STEP / omega_int, np.inf)
    taus = np.concatenate([np.ravel(study.noise_tau_assumed), np.ravel(study.noise_tau_true)])
    sig = np.concatenate([np.ravel(study.noise_sigma_assumed), np.ravel(study.noise_sigma_true)])
    live = np.isfinite(taus) & (taus > 0) & (sig > 0)
    if np.any(live):
        h_dyn = np.minimum(h_dyn, PDOT_TAU_STEP * float(np.min(taus[live])))
    return np.minimum(float(study.pdot_step_s), h_dyn)


def pdot_steps(study: Study, ref) -> np.ndarray:
    """The RK4 step (s) PDOT takes in each schedule interval of nonzero length: the interval
    cut into ceil(dt / bound) equal steps (:func:`pdot_step_bounds`)."""
    t = np.asarray(ref.times_s, float)
    dt = np.abs(np.diff(t))
    h_cap = pdot_step_bounds(study, ref)
    keep = dt > 0
    n = np.maximum(1, np.ceil(dt[keep] / h_cap[keep] - 1e-9))
    return dt[keep] / n
