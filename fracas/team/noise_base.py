"""The shared pieces of TEAM's process-noise models (FRACAS DYNO): the padded sizes, the
noise partials h = ∂ẋ/∂η at interval ends, DYNO's Q̃ over a batch of intervals, and the
inputs of the per-interval model (nodes, partials, transitions), which both
:func:`fracas.team.transitions.interval_noise` and the batched sweeps
(:mod:`fracas.team.batch`) feed to DYNO.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from fracas import _jax  # noqa: F401
from fracas.filters.process_noise import dyno_q
from fracas.integrate.variational import THRUST_NOISE_LABELS, jacobians_at
from fracas.team.study import Study

__all__ = ["EPS_T", "bucket", "noise_partials", "primary_index", "pad_rows", "interval_inputs", "dyno_levels"]

EPS_T = 1e-3  # s: interval ends are evaluated this far inside the interval (one-sided at thrust switches)


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


def pad_rows(a: np.ndarray, n: int) -> np.ndarray:
    """``a`` with zero rows appended up to ``n`` rows (a bucket: sizes that share one compile)."""
    return np.concatenate([a, np.zeros((n - len(a),) + a.shape[1:])]) if n > len(a) else a


def interval_inputs(
    study: Study, t: np.ndarray, states: np.ndarray, primary: list[str], phi: np.ndarray
) -> tuple[int, tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
    """What DYNO needs over each interval (t_{k-1}, t_k] of ``t`` for any sigma and tau: the
    interval count m = K - 1 and (Φ (nx, nx), h0, h1, dt), each padded with zero rows to
    :func:`bucket` (m).  h is evaluated just inside each interval's ends (``EPS_T``), which
    gives zero noise on coast intervals; ``phi`` (K, 7, 7): Φ(t_k, t_{k-1})."""
    K, nx = len(t), study.nx
    dt = np.diff(t)
    prim = primary_index(study, primary)
    t_nodes = np.concatenate([t[:-1] + np.minimum(EPS_T, dt / 2), t[1:] - np.minimum(EPS_T, dt / 2)])
    x_nodes = np.concatenate([states[:-1], states[1:]])
    p_nodes = np.concatenate([prim[:-1], prim[1:]])
    h = noise_partials(study, t_nodes, x_nodes, p_nodes)
    m, mp = K - 1, bucket(K - 1)  # pad to a bucket: schedules of similar length share one compile
    return m, tuple(pad_rows(a, mp) for a in (phi[1:, :nx, :nx], h[: K - 1], h[K - 1 :], dt))


def dyno_levels(study: Study, args: tuple[np.ndarray, ...], m: int) -> list[np.ndarray]:
    """DYNO's Q̃ (m, nx, nx) over the first ``m`` of the padded intervals ``args`` (Φ, h0,
    h1, dt), for the assumed and then the true noise level."""
    phi, h0, h1, dt = args
    out = []
    for sig, tau in (
        (study.noise_sigma_assumed, study.noise_tau_assumed),
        (study.noise_sigma_true, study.noise_tau_true),
    ):
        out.append(np.asarray(_dyno_batch(phi, h0, h1, jnp.asarray(sig), jnp.asarray(tau), jnp.asarray(dt)))[:m])
    return out
