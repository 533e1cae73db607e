"""White acceleration noise in TEAM (UNF s_q, digest unf-apollo.md A.5.4;
``[process_noise]``; docs/process_noise.md): the exact integral
Q = int Phi(t_k, s) B q D(s) B^T Phi(t_k, s)^T ds over each schedule interval by
Gauss-Legendre quadrature (``WHITE_NODES`` points) on pieces of at most
``Study.white_step_s``, with the reference integrated through the nodes
(:func:`reference_through_nodes`, shared with the exact Gauss-Markov model).  Added to
either thrust-noise model's Q (:mod:`fracas.team.transitions`).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from fracas import _jax  # noqa: F401
from fracas.filters.process_noise import gauss_legendre, white_direction, white_q_nodes
from fracas.integrate.propagate import propagate, propagate_with_sensitivities
from fracas.team.noise_base import bucket
from fracas.team.noise_cells import _noise_cells, _union, map_cell_noise
from fracas.team.study import Study

__all__ = [
    "WHITE_NODES",
    "reference_through_nodes",
    "yaw_flip_times",
    "cut_at_flips",
    "white_unit_noise",
    "white_noise",
]

WHITE_NODES = 4  # Gauss-Legendre points per piece: exact to degree 7 in the piece's time


@jax.jit
def _white_pieces(phi_end, D, w):
    return jax.vmap(white_q_nodes, in_axes=(0, 0, 0, None))(phi_end, D, w, jnp.float64(1.0))


def reference_through_nodes(study: Study, x0: np.ndarray, U: np.ndarray, nodes: np.ndarray):
    """The reference integrated once from ``x0`` (7,) at U[0] through the pieces [U_p, U_p+1]
    and their interior ``nodes`` (M, n) (quadrature nodes; M = len(U) - 1), with its STM:
    (phi_end (M, n, nx, nx) Phi(U_p+1, node j), piece_phi (M, nx, nx) Phi(U_p+1, U_p), states
    (M, n, 7) and primary indices (M, n) at the nodes; NaN where the integration fails).
    Shared by white acceleration noise and the exact Gauss-Markov model (fracas.team.gm_exact)."""
    nx = study.nx
    M, n = nodes.shape
    V = np.concatenate([U[:1], np.concatenate([nodes, U[1:, None]], axis=1).ravel()])  # node..., piece end
    pr = study.problem
    nv = len(V)
    Vp = np.concatenate([V, np.repeat(V[-1:], bucket(nv) - nv)])  # a few sizes share one compile
    traj, sens = propagate_with_sensitivities(pr.model, pr.params, pr.ephem, pr.epoch_et_s, x0, Vp, ())
    step = np.asarray(sens.stm_step)[:nv, :nx, :nx]
    nn = n + 1
    st = step[1:].reshape(M, nn, nx, nx)  # st[p, j]: Phi over the j-th sub-step of piece p
    phi_end = np.empty((M, n, nx, nx))
    acc = np.broadcast_to(np.eye(nx), (M, nx, nx)).copy()
    for j in range(n - 1, -1, -1):  # Phi(end, node j) = Phi(end, node j+1) Phi(node j+1, node j)
        acc = acc @ st[:, j + 1]
        phi_end[:, j] = acc
    piece_phi = acc @ st[:, 0]
    xs = np.asarray(traj.x)[1:nv].reshape(M, nn, 7)[:, :n]
    prim = np.asarray(traj.primary)[1:nv].reshape(M, nn)[:, :n].astype(np.int32)
    return phi_end, piece_phi, xs, prim


def yaw_flip_times(study: Study, x0: np.ndarray, U: np.ndarray) -> np.ndarray:
    """The times (s) of the reference's yaw-switch flips in (U[0], U[-1]) (``ForceModel.yaw_switch``:
    empty without one), as the trajectory core locates them (``Trajectory.t_flip``): the
    reference integrated from ``x0`` (7,) at U[0] through the times ``U`` (increasing), each
    interval of U that holds two flips or more halved until none does (the noise pieces are
    shorter than 1/omega, half a revolution is pi/omega, so this rarely happens)."""
    pr = study.problem
    if not pr.model.yaw_switch or len(U) < 2:
        return np.zeros(0)
    V = np.asarray(U, np.float64)
    for _ in range(20):
        nv = len(V)
        Vp = np.concatenate([V, np.repeat(V[-1:], bucket(nv) - nv)])  # a few sizes share one compile
        traj = propagate(pr.model, pr.params, pr.ephem, pr.epoch_et_s, x0, Vp)
        n = np.asarray(traj.n_flips)[:nv]
        inc = np.diff(n)
        if np.all(inc <= 1):
            return np.asarray(traj.t_flip)[1:nv][inc == 1]
        many = np.flatnonzero(inc > 1)
        V = np.sort(np.concatenate([V, 0.5 * (V[many] + V[many + 1])]))
    raise RuntimeError("yaw flips: could not separate the flips of the reference")  # pragma: no cover


def cut_at_flips(study: Study, x0: np.ndarray, U: np.ndarray, merge_s: float) -> np.ndarray:
    """``U`` with the reference's yaw flips (:func:`yaw_flip_times`) added as piece ends (those
    within ``merge_s`` of a time of U move it): across a flip the STM jumps (the saltation
    matrix) and the thrust direction reverses out of plane, so a quadrature or an interpolated
    noise kernel must not straddle one."""
    flips = yaw_flip_times(study, x0, U)
    if flips.size == 0:
        return U
    U = np.asarray(U, np.float64).copy()
    extra = []
    for tf in flips:
        k = int(np.argmin(np.abs(U - tf)))
        if abs(U[k] - tf) <= merge_s:
            if 0 < k < len(U) - 1:
                U[k] = tf
        else:
            extra.append(tf)
    return np.sort(np.concatenate([U, np.asarray(extra, np.float64)]))


def white_unit_noise(study: Study, t: np.ndarray, x0: np.ndarray, directions) -> dict[str, np.ndarray]:
    """The white-acceleration noise of unit spectral density (q = 1 km^2/s^3) over each
    interval (t_{k-1}, t_k] of ``t`` (element 0 zero), for each name in ``directions``:
    {direction: (K, nx, nx)}.  The exact integral (UNF s_q, digest A.5.4) by
    :data:`WHITE_NODES`-point Gauss-Legendre quadrature on the pieces between the union of
    ``t`` and a grid of ``study.white_step_s`` anchored at the epoch (cut at the thrust
    switches); ``x0`` (7,), the reference state at t[0], is integrated through the nodes
    (NaN where that integration fails).  Each piece's Q (:func:`white_q_nodes`, with
    Phi(piece end, node) chained from the integration's steps) is mapped to the next time
    of ``t`` with the reference transitions, so the sum composes exactly."""
    t = np.asarray(t, dtype=np.float64)
    K, nx = len(t), study.nx
    out = {d: np.zeros((K, nx, nx)) for d in directions}
    if K < 2 or not out:
        return out
    cells = _noise_cells(study, float(t[0]), float(t[-1]), study.white_step_s)
    U = _union(cells, t)
    U = cut_at_flips(study, x0, U, 0.0)  # keeps every time of t (the schedule's rows)
    M = len(U)
    nodes, w = gauss_legendre(WHITE_NODES, U[:-1], U[1:])
    phi_end, piece_phi, xn, _ = reference_through_nodes(study, x0, U, nodes)
    step_phi = np.concatenate([np.eye(nx)[None], piece_phi])
    sched = {int(np.argmin(np.abs(U - tk))): k for k, tk in enumerate(t)}
    ci = {"U": U, "step_phi": step_phi, "cell_at": {i: i - 1 for i in range(1, M)}, "sched": sched}
    for d in directions:
        D = np.asarray(white_direction(jnp.asarray(xn[..., :3]), jnp.asarray(xn[..., 3:6]), d))
        qp = np.asarray(_white_pieces(jnp.asarray(phi_end), jnp.asarray(D), jnp.asarray(w)))
        out[d] = map_cell_noise(ci, qp, K)
    return out


def white_noise(study: Study, t: np.ndarray, x0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The white-acceleration noise (K, nx, nx) over each interval of ``t``, assumed and
    true (``study.white_q_*`` times :func:`white_unit_noise` of its direction); zeros
    without white noise."""
    K, nx = len(t), study.nx
    levels = [(study.white_q_assumed, study.white_direction_assumed)]
    levels.append((study.white_q_true, study.white_direction_true) if study.gencov else levels[0])
    dirs = sorted({d for q, d in levels if q > 0})
    unit = white_unit_noise(study, t, x0, dirs) if study.has_white_noise else {}
    return tuple(q * unit[d] if q > 0 else np.zeros((K, nx, nx)) for q, d in levels)
