"""Two-vehicle TEAM's covariance analysis (R-649; :mod:`fracas.team.two_vehicle`): the
augmented step matrices and bias noise, the marks' observation rows and variances, each
target role's assumed covariance and mask, the jitted scan over the events (time update,
assumed-covariance reset, scalar marks in turn with Joseph updates) and the RMS histories
of a run."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from fracas import _jax  # noqa: F401  (float64 before any array exists)
from fracas.filters.two_vehicle import masked_gain, scalar_joseph
from fracas.measurements.relative import noise_sigma, relative_measurement, vehicle_rows
from fracas.team.scan import reset_state_block as _reset
from fracas.team.two_vehicle.model import RendezvousRun, RendezvousStudy, RoleCase

__all__ = ["measurement_rows", "role_setup", "run_rendezvous_study", "rms_histories"]


# ----------------------------------------------------------------------------- setup
def _phi_aug(study: RendezvousStudy) -> tuple[np.ndarray, np.ndarray]:
    """Augmented step matrices (K, n, n) and the true bias process noise (K, n, n)."""
    K, n = len(study.times_s), study.n
    phi = np.zeros((K, n, n))
    phi[:, :6, :6] = study.phi_chaser
    phi[:, 6:12, 6:12] = study.phi_target
    Q = np.zeros((K, n, n))
    dt = np.diff(study.times_s, prepend=study.times_s[0])
    for j, b in enumerate(study.biases):
        i = 12 + j
        decay = np.exp(-dt / b.tau_s) if np.isfinite(b.tau_s) else np.ones(K)
        phi[:, i, i] = decay
        Q[:, i, i] = b.sigma**2 * (1.0 - decay**2)
    return phi, Q


#: every relative kind at every event, compiled once per process (one trace per event count)
_measurements_at = jax.jit(jax.vmap(relative_measurement, in_axes=(0, 0, None)))


def measurement_rows(study: RendezvousStudy) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """H (K, 4, n), r_assumed, r_true (K, 4) (kind units^2) and the nominal values q (K, 4)."""
    K, n = len(study.times_s), study.n
    vals, gs, _ = (np.asarray(a) for a in _measurements_at(study.x_chaser, study.x_target, study.axes))
    H = np.zeros((K, 4, n))
    bA, bT = vehicle_rows(gs)
    H[:, :, :6] = np.asarray(bA)
    H[:, :, 6:12] = np.asarray(bT)
    for j, b in enumerate(study.biases):
        H[:, b.kind, 12 + j] = 1.0
    ra = np.stack(
        [np.asarray(noise_sigma(vals[:, i], *study.noise_assumed[i])) ** 2 for i in range(4)],
        axis=1,
    )
    rt = np.stack([np.asarray(noise_sigma(vals[:, i], *study.noise_true[i])) ** 2 for i in range(4)], axis=1)
    # rows of kinds not measured at an event are never used: zero them (and give unit
    # variances) so that a degenerate geometry there (zero range at a separation) cannot
    # put NaN into the scan through 0 * NaN
    m = study.marks.astype(bool)
    H = np.where(m[:, :, None], H, 0.0)
    ra, rt = np.where(m, ra, 1.0), np.where(m, rt, 1.0)
    return H, ra, rt, vals


def role_setup(study: RendezvousStudy, role: str, Q_true: np.ndarray) -> RoleCase:
    """The assumed covariance, mask and resets of one target role (module docstring table)."""
    n, K = study.n, len(study.times_s)
    est = np.zeros(n)
    est[:6] = 1.0
    present = np.ones(n)
    if role == "solve_for":
        est[6:12] = 1.0
    elif role == "ignore":
        present[6:12] = 0.0
    for j, b in enumerate(study.biases):
        est[12 + j] = 1.0 if b.role == "solve_for" else 0.0
        present[12 + j] = 0.0 if b.role == "ignore" else 1.0
    P0a = study.P0_true * present[:, None] * present[None, :]
    if role == "ignore" and study.chaser_load is not None:
        P0a[:6, :] = 0.0
        P0a[:, :6] = 0.0
        P0a[:6, :6] = np.diag(study.chaser_load**2)
    Qa = Q_true * present[:, None] * present[None, :]
    flag = np.zeros(K)
    rcov = np.zeros((K, 6, 6))
    for r in study.resets:
        if role in r.roles:
            flag[r.k] = 1.0
            rcov[r.k] = np.diag(np.asarray(r.sigma) ** 2)
    return RoleCase(role, est, P0a, Qa, flag, rcov)


# ----------------------------------------------------------------------------- scans
@jax.jit
def _scan(P0a, P0t, est, phi, Qa, Qt, H, ra, rt, active, flag, rcov):
    def step(carry, inp):
        Pa, Pt = carry
        ph, qa, qt, h, r_a, r_t, act, fl, rc = inp
        Pa = ph @ Pa @ ph.T + qa
        Pt = ph @ Pt @ ph.T + qt
        Pa_m, Pt_m = Pa, Pt
        Pa = _reset(Pa, fl, rc)
        ks = []
        for j in range(4):
            k = masked_gain(Pa, h[j], r_a[j], est) * act[j]
            Pa = scalar_joseph(Pa, h[j], r_a[j], k)
            Pt = scalar_joseph(Pt, h[j], r_t[j], k)
            ks.append(k)
        return (Pa, Pt), (Pa_m, Pt_m, Pa, Pt, jnp.stack(ks))

    _, out = jax.lax.scan(step, (P0a, P0t), (phi, Qa, Qt, H, ra, rt, active, flag, rcov))
    return out


def run_rendezvous_study(study: RendezvousStudy) -> RendezvousRun:
    """TEAM for two vehicles: every role of the study (module docstring)."""
    phi, Qt = _phi_aug(study)
    H, ra, rt, _ = measurement_rows(study)
    active = study.marks.astype(np.float64)
    outs = []
    for role in study.roles:
        c = role_setup(study, role, Qt)
        # the a priori holds at times_s[0]: no time update or reset before the first marks
        o = _scan(
            c.P0_assumed, study.P0_true, c.est, phi, c.Q_assumed, Qt, H, ra, rt, active, c.reset_flag, c.reset_cov
        )
        outs.append([np.asarray(a) for a in o])
    Pa_m, Pt_m, Pa, Pt, K = (np.stack([o[i] for o in outs]) for i in range(5))
    J = len(study.maneuvers)
    mt = np.zeros((len(study.roles), J, 3, 3))
    ma = np.zeros_like(mt)
    for j, m in enumerate(study.maneuvers):
        M = np.asarray(m.M)
        mt[:, j] = M @ Pt[:, m.k, :12, :12] @ M.T
        ma[:, j] = M @ Pa[:, m.k, :12, :12] @ M.T
    return RendezvousRun(study, Pt, Pa, Pt_m, Pa_m, K, H, rt, mt, ma)


def rms_histories(run: RendezvousRun, which: str = "true") -> dict[str, np.ndarray]:
    """RMS magnitudes (R, K) (km, km/s) after each event: chaser, target and relative
    position and velocity (sqrt of the traces of E_A, E_T, E_R = E_A + E_T - G - G')."""
    P = run.P_true if which == "true" else run.P_assumed
    EA, ET, G = P[..., :6, :6], P[..., 6:12, 6:12], P[..., :6, 6:12]
    ER = EA + ET - G - np.swapaxes(G, -1, -2)  # R-649 Eq. 17 (fracas.filters.two_vehicle.relative_covariance)

    def rms(E, sl):
        return np.sqrt(np.maximum(np.trace(E[..., sl, sl], axis1=-2, axis2=-1), 0.0))

    p, v = slice(0, 3), slice(3, 6)
    return {
        "chaser_position_km": rms(EA, p),
        "chaser_velocity_km_s": rms(EA, v),
        "target_position_km": rms(ET, p),
        "target_velocity_km_s": rms(ET, v),
        "relative_position_km": rms(ER, p),
        "relative_velocity_km_s": rms(ER, v),
    }
