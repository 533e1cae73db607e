"""Two-vehicle single runs (R-649's "single run"; TSIM's linear and nonlinear engines;
:mod:`fracas.team.two_vehicle`): estimation errors drawn from the true a priori and carried
with the covariance analysis's gains, or flown on conics with an extended Kalman filter,
and their statistics (envelope rates, sample RMS)."""

from __future__ import annotations

from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

from fracas import _jax  # noqa: F401  (float64 before any array exists)
from fracas.filters.two_vehicle import masked_gain, scalar_joseph
from fracas.measurements.relative import noise_sigma, relative_measurement, vehicle_rows
from fracas.team.scan import reset_state_block as _reset
from fracas.team.two_vehicle.covariance import _phi_aug, role_setup
from fracas.team.two_vehicle.model import RendezvousRun

__all__ = ["single_runs", "nonlinear_single_runs", "envelope_rates", "sample_rms", "RMS_GROUPS"]


def _sqrt_psd(P: jax.Array) -> jax.Array:
    """A square root L (L L' = P) of a symmetric positive semi-definite P (traced inside the runs)."""
    w, V = jnp.linalg.eigh(0.5 * (P + P.T))
    return V * jnp.sqrt(jnp.maximum(w, 0.0))[None, :]


@partial(jax.jit, static_argnames=("n_runs",))
def _runs(key, P0t, phi, Qt, H, rt, gains, n_runs):
    n = P0t.shape[0]

    L0 = _sqrt_psd(P0t)
    LQ = jax.vmap(_sqrt_psd)(Qt)

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

    L0 = _sqrt_psd(P0t)

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
