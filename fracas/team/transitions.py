"""Event inputs of the TEAM filter (numpy): augmented transitions and DYNO's effective
process noise over the schedule's intervals (FRACAS PTRAN, PROP eq. 3, DYNO).

Shared by the PHI engine, PDOT and prediction events; jitted kernels are compiled once
per padded size (see :func:`bucket`).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from fracas import _jax  # noqa: F401
from fracas.filters.process_noise import dyno_q
from fracas.integrate.variational import THRUST_NOISE_LABELS, jacobians_at
from fracas.team.study import Study

__all__ = [
    "theta_columns",
    "augmented_transitions",
    "bucket",
    "noise_partials",
    "primary_index",
    "interval_noise",
    "process_noise",
    "EPS_T",
]

EPS_T = 1e-3  # s: interval ends are evaluated this far inside the interval (one-sided at thrust switches)


def theta_columns(study: Study, ref) -> np.ndarray:
    """Θ (K, nx, np) of ``ref``'s K intervals in the study's augmented column order (zero for
    non-dynamic labels)."""
    K, nx = ref.phi.shape[0], study.nx
    th = np.zeros((K, nx, len(study.labels)))
    col = {lab: i for i, lab in enumerate(ref.labels)}
    for j, lab in enumerate(study.labels):
        if study.dynamic[j]:
            th[:, :, j] = ref.theta[:, :nx, col[lab]]
    return th


def augmented_transitions(study: Study, ref) -> np.ndarray:
    """PTRAN/PROP eq. 3 for every interval of ``ref``: (K, n, n)."""
    K, nx, n = ref.phi.shape[0], study.nx, study.layout.n
    out = np.broadcast_to(np.eye(n), (K, n, n)).copy()
    out[:, :nx, :nx] = ref.phi[:, :nx, :nx]
    out[:, :nx, nx:] = theta_columns(study, ref)
    return out


def bucket(k: int, base: int = 64) -> int:
    """Pad sizes to a few buckets so schedules of similar length share compiled code."""
    b = base
    while b < k:
        b *= 2
    return b


def noise_partials(study: Study, t_nodes: np.ndarray, x_nodes: np.ndarray, prim_nodes: np.ndarray) -> np.ndarray:
    """h (k, nx, 3) = ∂ẋ/∂η of the three Gauss-Markov thrust components at the nodes."""
    pr = study.problem
    k = len(t_nodes)
    kp = bucket(k)
    pad = lambda a: np.concatenate([a, np.repeat(a[-1:], kp - k, axis=0)]) if kp > k else a  # noqa: E731
    _, B = jacobians_at(
        pr.model, pr.params, pr.ephem, pr.epoch_et_s, pad(t_nodes), pad(x_nodes), pad(prim_nodes), THRUST_NOISE_LABELS
    )
    return np.asarray(B)[:k, : study.nx, :]


def primary_index(study: Study, names: list[str]) -> np.ndarray:
    bodies = study.problem.model.bodies
    return np.array([bodies.index(b) for b in names], dtype=np.int32)


@jax.jit
def _dyno_batch(phi, h0, h1, sigma, tau, dt):
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
    prim = primary_index(study, primary)
    t_nodes = np.concatenate([t[:-1] + np.minimum(EPS_T, dt / 2), t[1:] - np.minimum(EPS_T, dt / 2)])
    x_nodes = np.concatenate([states[:-1], states[1:]])
    p_nodes = np.concatenate([prim[:-1], prim[1:]])
    h = noise_partials(study, t_nodes, x_nodes, p_nodes)
    h0, h1 = h[: K - 1], h[K - 1 :]
    ph = phi[1:, :nx, :nx]
    m, mp = K - 1, bucket(K - 1)  # pad to a bucket: schedules of similar length share one compile
    pad = lambda a: np.concatenate([a, np.zeros((mp - m,) + a.shape[1:])]) if mp > m else a  # noqa: E731
    args = (pad(ph), pad(h0), pad(h1))
    out = []
    for sig, tau in (
        (study.noise_sigma_assumed, study.noise_tau_assumed),
        (study.noise_sigma_true, study.noise_tau_true),
    ):
        q = np.asarray(_dyno_batch(*args, jnp.asarray(sig), jnp.asarray(tau), jnp.asarray(pad(dt))))[:m]
        out.append(np.concatenate([zeros[:1], q]))
    return out[0], out[1]


def process_noise(study: Study, ref) -> tuple[np.ndarray, np.ndarray]:
    """DYNO's Q̃ over the schedule's intervals, assumed and true levels."""
    return interval_noise(study, ref.times_s, ref.states, ref.primary, ref.phi)


_bucket = bucket  # old private name
