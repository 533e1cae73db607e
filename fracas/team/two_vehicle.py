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
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

from fracas import _jax  # noqa: F401  (float64 before any array exists)
from fracas.filters.two_vehicle import masked_gain, scalar_joseph
from fracas.measurements.relative import RELATIVE_KINDS, noise_sigma, relative_measurement, vehicle_rows
from fracas.team.scan import reset_state_block as _reset

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


@partial(jax.jit, static_argnames=("n_runs",))
def _runs(key, P0t, phi, Qt, H, rt, gains, n_runs):
    n = P0t.shape[0]

    def sqrt_psd(P):
        w, V = jnp.linalg.eigh(0.5 * (P + P.T))
        return V * jnp.sqrt(jnp.maximum(w, 0.0))[None, :]

    L0 = sqrt_psd(P0t)
    LQ = jax.vmap(sqrt_psd)(Qt)

    def one(i):
        k_init, k_steps = jax.random.split(jax.random.fold_in(key, i))
        e0 = L0 @ jax.random.normal(k_init, (n,), dtype=jnp.float64)

        def step(e, inp):
            kk, ph, lq, h, r_t, g = inp
            k1, k2 = jax.random.split(kk)
            e = ph @ e + lq @ jax.random.normal(k1, (n,), dtype=jnp.float64)
            noise = jnp.sqrt(r_t) * jax.random.normal(k2, (4,), dtype=jnp.float64)
            for j in range(4):
                e = e - g[j] * (h[j] @ e + noise[j])
            return e, e

        keys = jax.vmap(lambda t: jax.random.fold_in(k_steps, t))(jnp.arange(phi.shape[0]))
        _, es = jax.lax.scan(step, e0, (keys, phi, LQ, H, rt, gains))
        return es

    return jax.vmap(one)(jnp.arange(n_runs))


def single_runs(run: RendezvousRun, n_runs: int, seed: int) -> np.ndarray:
    """Estimation errors (R, n_runs, K, n) of ``n_runs`` single runs per role (module
    docstring); run i of a role draws from fold_in(PRNGKey(seed), i) whatever n_runs is.
    The first event's time update is the identity (k = 0 is the a-priori time)."""
    study = run.study
    phi, Qt = _phi_aug(study)
    phi[0] = np.eye(study.n)
    Qt[0] = 0.0
    key = jax.random.PRNGKey(seed)
    out = []
    for r in range(len(study.roles)):
        out.append(np.asarray(_runs(key, study.P0_true, phi, Qt, run.H, run.r_true, run.gains[r], int(n_runs))))
    return np.stack(out)


@partial(jax.jit, static_argnames=("n_runs",))
def _nonlinear_runs(
    key, P0t, P0a, est, Qa, flag, rcov, dt, xa, xt, phi_b, Lb, mu, bias_H, noise_a, noise_t, active, axes, n_runs
):
    from fracas.dynamics.kepler import kepler

    n = P0t.shape[0]
    nb = n - 12

    def sqrt_psd(P):
        w, V = jnp.linalg.eigh(0.5 * (P + P.T))
        return V * jnp.sqrt(jnp.maximum(w, 0.0))[None, :]

    L0 = sqrt_psd(P0t)

    def fly(x, tau):
        r, v = kepler(x[:3], x[3:6], tau, mu)
        return jnp.concatenate([r, v])

    def fly_phi(x, tau):
        return jax.jacfwd(lambda z: fly(z, tau))(x)

    def one(i):
        k_init, k_steps = jax.random.split(jax.random.fold_in(key, i))
        d0 = L0 @ jax.random.normal(k_init, (n,), dtype=jnp.float64)
        # true state = reference + d0 (the biases' true values d0); the estimate starts on the
        # reference with the filter's own a priori
        true0 = jnp.concatenate([xa[0] + d0[:6], xt[0] + d0[6:12], d0[12:]])
        est0 = jnp.concatenate([xa[0], xt[0], jnp.zeros(nb, dtype=jnp.float64)])

        def step(carry, inp):
            tr, es, Pa = carry
            kk, tau, pb, lb, qa, fl, rc, act = inp
            k1, k2 = jax.random.split(kk)
            wb = lb * jax.random.normal(k1, (nb,), dtype=jnp.float64)
            # the filter's covariance on its own estimate's conics (EKF); a reset as in TEAM
            ph = jnp.zeros((n, n), dtype=jnp.float64)
            ph = ph.at[:6, :6].set(fly_phi(es[:6], tau)).at[6:12, 6:12].set(fly_phi(es[6:12], tau))
            ph = ph.at[jnp.arange(12, n), jnp.arange(12, n)].set(pb)
            Pa = _reset(ph @ Pa @ ph.T + qa, fl, rc)
            tr = jnp.concatenate([fly(tr[:6], tau), fly(tr[6:12], tau), pb * tr[12:] + wb])
            es = jnp.concatenate([fly(es[:6], tau), fly(es[6:12], tau), pb * es[12:]])
            q_true = relative_measurement(tr[:6], tr[6:12], axes)[0] + bias_H @ tr[12:]
            sig_t = noise_sigma(q_true, noise_t[:, 0], noise_t[:, 1], noise_t[:, 2])
            y = q_true + sig_t * jax.random.normal(k2, (4,), dtype=jnp.float64)
            for j in range(4):  # scalar marks in turn, each linearized about the updated estimate
                vals, gs, _ = relative_measurement(es[:6], es[6:12], axes)
                q_hat = vals[j] + bias_H[j] @ es[12:]
                bA, bT = vehicle_rows(gs[j])
                h = jnp.concatenate([bA, bT, bias_H[j]])
                r_a = noise_sigma(q_hat, *noise_a[j]) ** 2
                resid = y[j] - q_hat
                if j >= 2:  # angles: the residual wrapped to (-pi, pi] (UNF section 4)
                    resid = jnp.arctan2(jnp.sin(resid), jnp.cos(resid))
                # an unmeasured kind contributes nothing, even where its geometry is degenerate
                on = act[j] > 0.0
                h = jnp.where(on, h, 0.0)
                r_a = jnp.where(on, r_a, 1.0)
                resid = jnp.where(on, resid, 0.0)
                g = jnp.where(on, masked_gain(Pa, h, r_a, est), 0.0)
                es = es + g * resid
                Pa = scalar_joseph(Pa, h, r_a, g)
            return (tr, es, Pa), es - tr

        keys = jax.vmap(lambda t: jax.random.fold_in(k_steps, t))(jnp.arange(dt.shape[0]))
        inputs = (keys, dt, phi_b, Lb, Qa, flag, rcov, active)
        _, errs = jax.lax.scan(step, (true0, est0, P0a), inputs)
        return errs

    return jax.vmap(one)(jnp.arange(n_runs))


def nonlinear_single_runs(run: RendezvousRun, n_runs: int, seed: int) -> np.ndarray:
    """Single runs of the filter as flown (R-649's single runs; TSIM's nonlinear check of the
    linear analysis): estimation errors (R, n_runs, K, n).  Each run draws its true initial
    errors from the true a priori (the seed scheme of :func:`single_runs`), flies the true
    and the estimated states on their conics about the centre (Kepler's equation), computes
    each mark from the nonlinear models at the true states (y = h(x) + beta + noise, the
    noise sigma from the TRUE value), and updates like an extended Kalman filter: the
    filter's own covariance is propagated with the conic STMs of ITS estimate, each scalar
    mark is linearized about the current estimate, the assumed noise sigma is taken from
    the ESTIMATED value (R-649: "percentages of the estimated range"), angle residuals are
    wrapped, and resets and role masks are those of the covariance analysis.  Only for
    two-body references (``study.two_body``); ValueError otherwise (the build refuses such a
    deck first with a one-line message)."""
    study = run.study
    if not study.two_body:
        raise ValueError("nonlinear single runs need point-mass ballistic references (study.two_body)")
    phi, Qt = _phi_aug(study)
    K, nb = len(study.times_s), study.nb
    dt = np.diff(study.times_s, prepend=study.times_s[0])
    phi_b = np.stack([np.diag(phi[k])[12:] for k in range(K)]) if nb else np.zeros((K, 0))
    Lb = np.sqrt(np.stack([np.diag(Qt[k])[12:] for k in range(K)])) if nb else np.zeros((K, 0))
    phi_b[0] = 1.0
    Lb[0] = 0.0
    bias_H = np.zeros((4, nb))
    for j, b in enumerate(study.biases):
        bias_H[b.kind, j] = 1.0
    key = jax.random.PRNGKey(seed)
    out = []
    for role in study.roles:
        c = role_setup(study, role, Qt)
        Qa = c.Q_assumed.copy()
        Qa[0] = 0.0
        out.append(
            np.asarray(
                _nonlinear_runs(
                    key,
                    study.P0_true,
                    c.P0_assumed,
                    c.est,
                    Qa,
                    c.reset_flag,
                    c.reset_cov,
                    dt,
                    study.x_chaser,
                    study.x_target,
                    phi_b,
                    Lb,
                    study.mu_km3_s2,
                    bias_H,
                    study.noise_assumed,
                    study.noise_true,
                    study.marks.astype(np.float64),
                    study.axes,
                    int(n_runs),
                )
            )
        )
    return np.stack(out)


def envelope_rates(run: RendezvousRun, errors: np.ndarray, k_sigma: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """(rate (R,), se (R,)): the fraction of single-run error components inside +-k_sigma x
    the true sigma, over every run, event and state (chaser and target r, v), and its
    standard error.  0.6827 (1 sigma) or 0.9973 (3 sigma) is expected for Gaussian errors of
    the true covariance.  A run's components are correlated over time, so the standard error
    is taken across runs (each run's own fraction is one independent sample)."""
    sig = np.sqrt(np.maximum(np.einsum("rkii->rki", run.P_true[..., :12, :12]), 0.0))
    inside = np.abs(errors[..., :12]) <= k_sigma * sig[:, None]
    per_run = inside.mean(axis=(2, 3))
    n = per_run.shape[1]
    se = per_run.std(axis=1, ddof=1) / np.sqrt(n) if n > 1 else np.full(per_run.shape[0], np.nan)
    return per_run.mean(axis=1), se


#: the six RMS groups of the reports: (name, unit)
RMS_GROUPS = (
    ("chaser_position", "km"),
    ("chaser_velocity", "km/s"),
    ("target_position", "km"),
    ("target_velocity", "km/s"),
    ("relative_position", "km"),
    ("relative_velocity", "km/s"),
)


def sample_rms(errors: np.ndarray) -> np.ndarray:
    """Sample RMS magnitudes (R, K, 6) over the runs of ``errors`` (R, N, K, n), in
    RMS_GROUPS order: sqrt(mean |e|^2) of the chaser, target and relative (target - chaser)
    position and velocity errors."""
    e = errors
    rel = e[..., 6:12] - e[..., 0:6]
    parts = (e[..., 0:3], e[..., 3:6], e[..., 6:9], e[..., 9:12], rel[..., 0:3], rel[..., 3:6])
    return np.stack([np.sqrt(np.mean(np.sum(p**2, axis=-1), axis=1)) for p in parts], axis=-1)


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
