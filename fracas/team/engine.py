"""The TEAM executive: covariances through the event schedule (FRACAS TEAM, COVP, PROP, MEAS, FILTER).

The inputs of every event are assembled first (transition matrices, effective process
noise, observation matrices), then one jitted ``lax.scan`` runs the filter algebra of
:mod:`fracas.filters` over the whole schedule: a time update to the event time (PROP
eqs. 1-16 with DYNO's Q̃), then a measurement update (FILTER) whose gain comes from the
assumed covariance (KSGAIN, WLSGAN or a user gain) and is applied to the true covariance
too (generalized covariance).  Non-measurement events have zero H rows, which leave the
covariances unchanged.  PDOT mode integrates the covariance differential equations with
the Gauss-Markov noise states augmented (DERY) instead of mapping with transition matrices.
Eigenvector, prediction and punch events are evaluated afterwards from the history.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import partial

import numpy as np

from fracas import _jax  # noqa: F401
import jax
import jax.numpy as jnp

from fracas.errors import ConfigError, NumericalError
from fracas.filters import covariance as cov
from fracas.filters import square_root as sqr
from fracas.team.measure import MeasurementSet, assemble_measurements
from fracas.team.reference import Reference
from fracas.team.setup import THRUST_NOISE_LABELS, Study

__all__ = ["TeamResult", "run_study", "process_noise", "augmented_transitions"]

EPS_T = 1e-3  # s: interval ends are evaluated this far inside the interval (one-sided at thrust switches)


@dataclass
class TeamResult:
    """The covariance history of a study (assumed and, with generalized covariance, true).

    P_minus / P_plus (K, n, n): before / after the event at each schedule time; Q_assumed,
    Q_true (K, nx, nx): effective process noise over the interval ending at each time;
    innovation_sigma (K, m): sqrt(diag J) of the assumed filter; predictions: per schedule
    index, list of (t_to_s, P_assumed, P_true); psd: list of (k, event, which, min eig).
    """

    study: Study
    ref: Reference
    meas: MeasurementSet
    Pa_minus: np.ndarray
    Pa_plus: np.ndarray
    Pt_minus: np.ndarray | None
    Pt_plus: np.ndarray | None
    Q_assumed: np.ndarray
    Q_true: np.ndarray
    innovation_sigma: np.ndarray
    predictions: dict[int, list[tuple[float, np.ndarray, np.ndarray | None]]] = field(default_factory=dict)
    psd_problems: list[tuple[int, str, str, float]] = field(default_factory=list)
    timing: dict[str, float] = field(default_factory=dict)
    noise_states: bool = False  # PDOT: the three Gauss-Markov states follow the parameters

    @property
    def times_s(self) -> np.ndarray:
        return self.study.schedule.times_s

    @property
    def labels(self) -> list[str]:
        """Row/column labels of the covariances: state, parameters [, PDOT noise states]."""
        from fracas.team.pdot import NOISE_STATE_LABELS

        st = self.study
        return st.state_labels + st.labels + (NOISE_STATE_LABELS if self.noise_states else [])

    @property
    def units(self) -> list[str]:
        st = self.study
        return st.state_units + st.units + (["1", "rad", "rad"] if self.noise_states else [])

    @property
    def roles(self) -> list[str]:
        st = self.study
        return ["state"] * st.nx + st.roles + (["noise_state"] * 3 if self.noise_states else [])


# ------------------------------------------------------------------- event inputs (numpy)
def theta_columns(study: Study, ref: Reference) -> np.ndarray:
    """Θ (K, nx, np) of ``ref``'s K intervals in the study's augmented column order (zero for
    non-dynamic labels)."""
    K, nx = ref.phi.shape[0], study.nx
    th = np.zeros((K, nx, len(study.labels)))
    col = {lab: i for i, lab in enumerate(ref.labels)}
    for j, lab in enumerate(study.labels):
        if study.dynamic[j]:
            th[:, :, j] = ref.theta[:, :nx, col[lab]]
    return th


def augmented_transitions(study: Study, ref: Reference) -> np.ndarray:
    """PTRAN/PROP eq. 3 for every interval of ``ref``: (K, n, n)."""
    K, nx, n = ref.phi.shape[0], study.nx, study.layout.n
    out = np.broadcast_to(np.eye(n), (K, n, n)).copy()
    out[:, :nx, :nx] = ref.phi[:, :nx, :nx]
    out[:, :nx, nx:] = theta_columns(study, ref)
    return out


def _bucket(k: int, base: int = 64) -> int:
    """Pad sizes to a few buckets so schedules of similar length share compiled code."""
    b = base
    while b < k:
        b *= 2
    return b


def noise_partials(study: Study, t_nodes: np.ndarray, x_nodes: np.ndarray, prim_nodes: np.ndarray) -> np.ndarray:
    """h (k, nx, 3) = ∂ẋ/∂η of the three Gauss-Markov thrust components at the nodes."""
    from fracas.dynamics.variational import jacobians_at

    pr = study.problem
    k = len(t_nodes)
    kp = _bucket(k)
    pad = lambda a: np.concatenate([a, np.repeat(a[-1:], kp - k, axis=0)]) if kp > k else a  # noqa: E731
    _, B = jacobians_at(pr.model, pr.params, pr.ephem, pr.epoch_et_s, pad(t_nodes), pad(x_nodes), pad(prim_nodes),
                        THRUST_NOISE_LABELS)
    return np.asarray(B)[:k, : study.nx, :]


def _primary_index(study: Study, names: list[str]) -> np.ndarray:
    bodies = study.problem.model.bodies
    return np.array([bodies.index(b) for b in names], dtype=np.int32)


@jax.jit
def _dyno_batch(phi, h0, h1, sigma, tau, dt):
    from fracas.filters.process_noise import dyno_q

    return jax.vmap(dyno_q, in_axes=(0, 0, 0, None, None, 0))(phi, h0, h1, sigma, tau, dt)


def interval_noise(study: Study, t: np.ndarray, states: np.ndarray, primary: list[str], phi: np.ndarray):
    """DYNO's Q̃ (K, nx, nx) over each interval (t_{k-1}, t_k] (element 0 is zero), assumed and true.

    ``phi`` (K, 7, 7): Φ(t_k, t_{k-1}).  Thrust switches are schedule times, so no interval
    straddles one; h is evaluated just inside each interval's ends, which gives zero noise
    on coast intervals.
    """
    K, nx = len(t), study.nx
    zeros = np.zeros((K, nx, nx))
    if not study.has_noise or K < 2:
        return zeros, zeros.copy()
    dt = np.diff(t)
    prim = _primary_index(study, primary)
    t_nodes = np.concatenate([t[:-1] + np.minimum(EPS_T, dt / 2), t[1:] - np.minimum(EPS_T, dt / 2)])
    x_nodes = np.concatenate([states[:-1], states[1:]])
    p_nodes = np.concatenate([prim[:-1], prim[1:]])
    h = noise_partials(study, t_nodes, x_nodes, p_nodes)
    h0, h1 = h[: K - 1], h[K - 1:]
    ph = phi[1:, :nx, :nx]
    m, mp = K - 1, _bucket(K - 1)  # pad to a bucket: schedules of similar length share one compile
    pad = lambda a: np.concatenate([a, np.zeros((mp - m,) + a.shape[1:])]) if mp > m else a  # noqa: E731
    args = (pad(ph), pad(h0), pad(h1))
    out = []
    for sig, tau in ((study.noise_sigma_assumed, study.noise_tau_assumed), (study.noise_sigma_true, study.noise_tau_true)):
        q = np.asarray(_dyno_batch(*args, jnp.asarray(sig), jnp.asarray(tau), jnp.asarray(pad(dt))))[:m]
        out.append(np.concatenate([zeros[:1], q]))
    return out[0], out[1]


def process_noise(study: Study, ref: Reference) -> tuple[np.ndarray, np.ndarray]:
    """DYNO's Q̃ over the schedule's intervals, assumed and true levels."""
    return interval_noise(study, ref.times_s, ref.states, ref.primary, ref.phi)


# ------------------------------------------------------------------- the filter scan (jax)
def _gain(kind, user_gain, layout, Pa, Pnc, H, R):
    if kind == "kalman_schmidt":
        return cov.kalman_schmidt_gain(Pa, H, R, layout), Pnc
    if kind == "wls":
        K, Pnc1 = cov.wls_gain(Pnc, H, R, layout)
        return K, Pnc1
    Kest = jnp.asarray(user_gain(Pa, H, R, layout))
    K = jnp.zeros((layout.n, H.shape[0])).at[: layout.n_est].set(Kest)
    return K, Pnc


@partial(jax.jit, static_argnames=("layout", "kind", "gencov", "square_root", "user_gain"))
def _scan(P0a, P0t, phi_aug, Qa, Qt, H, Ra, Rt, *, layout, kind, gencov, square_root, user_gain=None):
    n_est = layout.n_est

    def step(carry, ev):
        A, T, Pnc = carry
        phi, qa, qt, h, ra, rt = ev
        if kind == "wls":
            Pnc = cov.wls_time_update(Pnc, phi, layout)
        if square_root:
            Wa = sqr.sqrt_time_update(A, phi, qa)
            Pa_m = Wa @ Wa.T
            if kind == "kalman_schmidt":
                K = sqr.sqrt_kalman_schmidt_gain(Wa, h, ra, layout)
            else:
                K, Pnc = _gain(kind, user_gain, layout, Pa_m, Pnc, h, ra)
            Wa1 = sqr.sqrt_joseph_update(Wa, h, ra, K)
            Pa_p = Wa1 @ Wa1.T
            A1 = Wa1
        else:
            Pa_m = cov.time_update(A, phi, qa)
            K, Pnc = _gain(kind, user_gain, layout, Pa_m, Pnc, h, ra)
            Pa_p = cov.joseph_update(Pa_m, h, ra, K)
            A1 = Pa_p
        _, J = cov.innovation(Pa_m, h, ra)
        if gencov:
            if square_root:
                Wt = sqr.sqrt_time_update(T, phi, qt)
                Wt1 = sqr.sqrt_joseph_update(Wt, h, rt, K)
                Pt_m, Pt_p, T1 = Wt @ Wt.T, Wt1 @ Wt1.T, Wt1
            else:
                Pt_m = cov.time_update(T, phi, qt)
                Pt_p = cov.joseph_update(Pt_m, h, rt, K)
                T1 = Pt_p
        else:
            Pt_m = Pt_p = T1 = T
        return (A1, T1, Pnc), (Pa_m, Pa_p, Pt_m, Pt_p, jnp.sqrt(jnp.diagonal(J)))

    if square_root:
        A0, T0 = sqr.factor(P0a), sqr.factor(P0t)
    else:
        A0, T0 = P0a, P0t
    Pnc0 = P0a[:n_est, :n_est]
    _, outs = jax.lax.scan(step, (A0, T0, Pnc0), (phi_aug, Qa, Qt, H, Ra, Rt))
    return outs


def _pad_events(K: int, Kp: int, arrays):
    """Append neutral events (identity Φ, zero Q and H, unit R) up to Kp."""
    out = []
    for name, a in arrays:
        if Kp == K:
            out.append(a)
            continue
        extra = np.zeros((Kp - K,) + a.shape[1:])
        if name in ("phi", "R"):
            extra[:] = np.eye(a.shape[-1])
        out.append(np.concatenate([a, extra]))
    return out


def run_filter(study: Study, phi_aug, Qa, Qt, meas: MeasurementSet):
    """Run the jitted scan over the schedule (padded to a bucket size); numpy outputs."""
    K = study.schedule.n
    Kp = _bucket(K)
    phi_aug, Qa, Qt, H, Ra, Rt = _pad_events(K, Kp, [("phi", phi_aug), ("Q", Qa), ("Q", Qt), ("H", meas.H),
                                                    ("R", meas.R_assumed), ("R", meas.R_true)])
    try:
        outs = _scan(jnp.asarray(study.P0_assumed), jnp.asarray(study.P0_true), jnp.asarray(phi_aug), jnp.asarray(Qa),
                     jnp.asarray(Qt), jnp.asarray(H), jnp.asarray(Ra), jnp.asarray(Rt), layout=study.layout,
                     kind=study.filter_kind, gencov=study.gencov, square_root=study.square_root,
                     user_gain=study.user_gain)
    except (TypeError, ValueError, jax.errors.JAXTypeError) as exc:
        if study.filter_kind == "user":
            raise ConfigError(f"{study.source}: filter.user_gain = \"{study.deck.filter.user_gain}\" failed: "
                              f"{type(exc).__name__}: {str(exc).splitlines()[0]} (it is called as "
                              "gain(P_assumed, H, R, layout) -> K (n_est, m) under jax tracing)") from None
        raise
    Pa_m, Pa_p, Pt_m, Pt_p, sig = (np.asarray(o)[:K] for o in outs)
    return Pa_m, Pa_p, Pt_m, Pt_p, sig


# ------------------------------------------------------------------- checks and post-processing
_psd_batch = jax.jit(jax.vmap(cov.psd_check))


def psd_problems(study: Study, P: np.ndarray, which: str) -> list[tuple[int, str, str, float]]:
    """Schedule indices where a covariance lost positive semi-definiteness or is not finite
    (:func:`fracas.filters.covariance.psd_check` on every event): (k, event, which, smallest
    eigenvalue in the covariance's mixed units).

    Fast path for the usual healthy history: psd_check's scale-free criterion (smallest
    eigenvalue of D^-1/2 P D^-1/2 >= -PSD_TOLERANCE) holds exactly when D^-1/2 P D^-1/2 +
    PSD_TOLERANCE I has a Cholesky factor, which numpy does for the whole history in a few ms
    (JAX's batched eigendecomposition on the CPU takes ~0.1 s); only a failing history goes
    through psd_check event by event.
    """
    d = np.einsum("kii->ki", P)
    if np.all(np.isfinite(P)) and np.all(d >= -cov.PSD_TOLERANCE * np.max(np.abs(d), axis=1, keepdims=True)):
        sc = np.sqrt(np.where(d > 0, d, 1.0))
        S = P / sc[:, :, None] / sc[:, None, :]
        try:
            np.linalg.cholesky(0.5 * (S + S.transpose(0, 2, 1)) + cov.PSD_TOLERANCE * np.eye(P.shape[1]))
            return []
        except np.linalg.LinAlgError:
            pass
    min_eig, ok = (np.asarray(a) for a in _psd_batch(jnp.asarray(P)))
    return [(int(k), study.schedule.primary_type(int(k)), which, float(min_eig[k])) for k in np.nonzero(~ok)[0]]


def run_study(study: Study, ref: Reference, progress=None) -> TeamResult:
    """The whole TEAM run on a prepared study and reference."""
    import time

    stage = progress or (lambda _t: None)
    tm = {}
    t0 = time.perf_counter()
    stage("assembling observation matrices")
    meas = assemble_measurements(study, ref)
    tm["measurements_s"] = time.perf_counter() - t0
    t1 = time.perf_counter()
    if study.propagation == "pdot":
        from fracas.team.pdot import run_pdot

        stage("integrating the covariance equations (PDOT)")
        res = run_pdot(study, ref, meas)
        res.timing.update(tm)
        return res
    stage("process noise and transitions")
    Qa, Qt = process_noise(study, ref)
    phi_aug = augmented_transitions(study, ref)
    tm["noise_transitions_s"] = time.perf_counter() - t1
    t2 = time.perf_counter()
    stage("filtering")
    Pa_m, Pa_p, Pt_m, Pt_p, sig = run_filter(study, phi_aug, Qa, Qt, meas)
    tm["filter_s"] = time.perf_counter() - t2
    res = TeamResult(study, ref, meas, Pa_m, Pa_p, Pt_m if study.gencov else None, Pt_p if study.gencov else None,
                     Qa, Qt, sig)
    finish(res, tm)
    return res


def finish(res: TeamResult, tm: dict) -> None:
    """Positive-definiteness checks and prediction events (shared by PHI and PDOT)."""
    import time

    study = res.study
    res.psd_problems = psd_problems(study, res.Pa_plus, "assumed")
    if res.Pt_plus is not None:
        res.psd_problems += psd_problems(study, res.Pt_plus, "true")
    t3 = time.perf_counter()
    if study.schedule.predict_to_s:
        from fracas.team.predict import predictions

        res.predictions = predictions(res)
    tm["predictions_s"] = time.perf_counter() - t3
    res.timing.update(tm)


def check_psd(res: TeamResult) -> None:
    """NumericalError naming the first event where a covariance stopped being PSD."""
    if res.psd_problems:
        k, ev, which, e = res.psd_problems[0]
        t = res.times_s[k] / 86400.0
        raise NumericalError(f"{res.study.source}: the {which} covariance lost positive-definiteness at "
                             f"t = {t:.6g} d ({ev} event; smallest eigenvalue {e:.3g})")
