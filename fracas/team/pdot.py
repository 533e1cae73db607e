"""PDOT propagation: the covariance differential equations with the noise states augmented
(FRACAS DERY, PATH; Appendix 9.3 "PDOT").

The three Gauss-Markov thrust errors η (proportionality, in-plane, out-of-plane pointing)
become states appended after the study's parameters, with ṅ = −η/τ + q; the augmented
covariance obeys Ṗ = F P + P Fᵀ + Q_c with F = [[A, B, h], [0, 0, 0], [0, 0, −1/τ]]
evaluated along the reference trajectory (A, B, h by automatic differentiation of the
full force model).  Ṗ is integrated with RK4 on a uniform grid inside every interval
between events (step <= ``ertraj.pdot_step_hours``); measurement updates are the same
as in PHI mode.  The noise states are carried like ignore-block rows (their gains are
zero: they are considered, not estimated) but the filter knows them (the assumed
covariance has them too).  White acceleration noise ([process_noise], UNF s_q) adds
Q_c = B q D(x) Bᵀ on the velocity block at every node (D of the reference state there).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from functools import cache

import jax
import jax.numpy as jnp
import numpy as np

from fracas import _jax  # noqa: F401  (x64 before jax)
from fracas.constants import body_names_at
from fracas.filters.covariance import Layout
from fracas.filters.process_noise import pdot_propagate, white_direction, white_Qc
from fracas.integrate.propagate import propagate
from fracas.integrate.variational import THRUST_NOISE_LABELS, jacobians_at, saltation_at
from fracas.team.measure import MeasurementSet
from fracas.team.noise_base import EPS_T, bucket, primary_index
from fracas.team.pdot_step import PDOT_OMEGA_STEP, PDOT_TAU_STEP, pdot_step_bounds, pdot_steps
from fracas.team.reference import Reference
from fracas.team.result import NOISE_STATE_LABELS, TeamResult, finish
from fracas.team.scan import _scan
from fracas.team.study import Study
from fracas.team.white_acceleration import yaw_flip_times

__all__ = ["run_pdot", "pdot_step_bounds", "pdot_steps", "PDOT_OMEGA_STEP", "PDOT_TAU_STEP", "NOISE_STATE_LABELS"]


@cache
def _pdot_fn() -> Callable:
    return jax.jit(pdot_propagate)


def _pad_nodes(a: np.ndarray, extra: int) -> jax.Array:
    """The node array ``a`` with its last node repeated ``extra`` times (zero-length steps)."""
    return jnp.asarray(np.concatenate([a, np.repeat(a[-1:], extra, axis=0)]))


def _expand(P: np.ndarray, sig: np.ndarray) -> np.ndarray:
    n = P.shape[0]
    out = np.zeros((n + 3, n + 3))
    out[:n, :n] = P
    out[n:, n:] = np.diag(sig**2)  # stationary Gauss-Markov start
    return out


def _interval_pieces(t: np.ndarray, h_cap: np.ndarray, flips: np.ndarray) -> list[list[tuple[int, float, np.ndarray]]]:
    """For each interval, its pieces (the interval cut at the yaw flips inside it): each
    piece's step count N, length (s) and 2N+1 equally spaced nodes (ends nudged ``EPS_T``
    inside the piece, at most a quarter of it, so the thrust direction at an end node is
    the piece's own side of a switch or a flip)."""
    out = []
    for k in range(1, len(t)):
        cuts = [float(t[k - 1]), *(float(f) for f in flips if t[k - 1] < f < t[k]), float(t[k])]
        pieces = []
        for a, b in zip(cuts[:-1], cuts[1:], strict=True):
            dt = b - a
            N = max(1, int(math.ceil(dt / h_cap[k - 1] - 1e-9)))
            tt = a + dt * np.arange(2 * N + 1) / (2 * N)
            e = min(EPS_T, dt / 4)
            tt[0] += e
            tt[-1] -= e
            pieces.append((N, dt, tt))
        out.append(pieces)
    return out


def _flip_jumps(study: Study, ref: Reference, flips: np.ndarray) -> list[np.ndarray]:
    """The covariance jump at each yaw flip: the saltation matrix S of the state
    (``fracas.integrate.variational.saltation_at``) on the state block of the n + 3 augmented
    states (parameters and noise states do not jump), so P+ = S P- S^T."""
    if flips.size == 0:
        return []
    pr = study.problem
    nx, n = study.layout.nx, study.layout.n
    traj = propagate(
        pr.model, pr.params, pr.ephem, pr.epoch_et_s, ref.states[0], np.concatenate([[ref.times_s[0]], flips])
    )
    jumps = []
    for x, p, tf in zip(np.asarray(traj.x)[1:], np.asarray(traj.primary)[1:], flips, strict=True):
        S = np.asarray(saltation_at(pr.model, pr.params, pr.ephem, pr.epoch_et_s, tf, x, int(p)))
        J = np.eye(n + 3)
        J[:nx, :nx] = S[:nx, :nx]
        jumps.append(J)
    return jumps


def _node_states(study: Study, ref: Reference, all_t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The reference state (kk, 7) and primary name at every node, one integration from the
    first schedule time through the nodes in time order."""
    pr = study.problem
    t = ref.times_s
    order = np.argsort(all_t, kind="stable")
    t_sorted = np.concatenate([[t[0]], all_t[order]])
    traj = propagate(pr.model, pr.params, pr.ephem, pr.epoch_et_s, ref.states[0], t_sorted)
    xs = np.empty((all_t.size, 7))
    xs[order] = np.asarray(traj.x)[1:]
    prim_names = np.empty(all_t.size, dtype=object)
    prim_names[order] = body_names_at(pr.model.bodies, np.asarray(traj.primary)[1:])
    return xs, prim_names


def _node_jacobian(study: Study, all_t: np.ndarray, xs: np.ndarray, prim_names: np.ndarray) -> np.ndarray:
    """F (kk, n + 3, n + 3) at every node without the noise states' decay: A, B of the
    dynamic parameters and h of the three thrust-noise components (AD of the force model)."""
    pr = study.problem
    nx, n = study.layout.nx, study.layout.n
    labels = list(dict.fromkeys(list(study.dynamic_labels) + list(THRUST_NOISE_LABELS)))  # a bias may be both
    kk = all_t.size
    kp = bucket(kk)
    pad = lambda a: np.concatenate([a, np.repeat(a[-1:], kp - kk, axis=0)]) if kp > kk else a  # noqa: E731
    A, B = jacobians_at(
        pr.model,
        pr.params,
        pr.ephem,
        pr.epoch_et_s,
        pad(all_t),
        pad(xs),
        pad(primary_index(study, list(prim_names))),
        labels,
    )
    A, B = np.asarray(A)[:kk, :nx, :nx], np.asarray(B)[:kk, :nx, :]
    B_dyn = B[:, :, [labels.index(lab) for lab in study.dynamic_labels]]
    h = B[:, :, [labels.index(lab) for lab in THRUST_NOISE_LABELS]]
    # F at every node (assumed and true differ only in the noise correlation times)
    F = np.zeros((kk, n + 3, n + 3))
    F[:, :nx, :nx] = A
    dyn_cols = [nx + j for j, d in enumerate(study.dynamic) if d]
    F[:, :nx, dyn_cols] = B_dyn
    F[:, :nx, n:] = h
    return F


def _noise_models(study: Study, F: np.ndarray, xs: np.ndarray) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """([F_assumed, F_true], [Qc_assumed, Qc_true]): the noise states' decay -1/tau in F and
    their white driving noise 2 sigma^2 / tau, plus white acceleration at every node."""
    n = study.layout.n
    Fs, Qcs = [], []
    white_true = (study.white_q_true, study.white_direction_true) if study.gencov else None
    for (sig, tau), (wq, wd) in zip(
        (
            (study.noise_sigma_assumed, study.noise_tau_assumed),
            (study.noise_sigma_true, study.noise_tau_true),
        ),
        ((study.white_q_assumed, study.white_direction_assumed), white_true or (0.0, "full")),
    ):
        Fx = F.copy()
        Fx[:, np.arange(n, n + 3), np.arange(n, n + 3)] = -1.0 / tau
        Qc = np.zeros((n + 3, n + 3))
        Qc[np.arange(n, n + 3), np.arange(n, n + 3)] = 2.0 * sig**2 / tau
        if wq > 0:  # white acceleration (UNF s_q): Qc = B q D(x) B^T at every node
            Qc = Qc[None] + np.asarray(white_Qc(wq, white_direction(xs[:, :3], xs[:, 3:6], wd), n + 3))
        Fs.append(Fx)
        Qcs.append(Qc)
    return Fs, Qcs


def _initial(study: Study) -> tuple[jax.Array, jax.Array]:
    """The assumed and true a priori over n + 3 states."""
    if study.P0_noise_states is not None:  # a punch with the noise states (issue 24)
        return tuple(jnp.asarray(p) for p in study.P0_noise_states)
    Pa = jnp.asarray(_expand(study.P0_assumed, study.noise_sigma_assumed))
    Pt = jnp.asarray(_expand(study.P0_true, study.noise_sigma_true))
    return Pa, Pt


def _propagate_interval(
    study: Study, Pa: jax.Array, Pt: jax.Array, N: int, dt_k: float, seg: slice, Fs: list, Qcs: list
) -> tuple[jax.Array, jax.Array]:
    """Pa, Pt propagated over one interval of N RK4 steps (``seg``: its nodes), padded to a
    bucket of steps with zero-length steps: one compiled program per bucket, not one per
    distinct N (intervals of every length in LEO)."""
    pdot = _pdot_fn()
    n_pad = bucket(N, 8)
    dts = np.zeros(n_pad)
    dts[:N] = dt_k / N

    extra = 2 * (n_pad - N)
    qa, qt = (_pad_nodes(q[seg], extra) if q.ndim == 3 else q for q in Qcs)
    Pa = pdot(Pa, _pad_nodes(Fs[0][seg], extra), qa, jnp.asarray(dts))
    if study.gencov:
        Pt = pdot(Pt, _pad_nodes(Fs[1][seg], extra), qt, jnp.asarray(dts))
    return Pa, Pt


def run_pdot(study: Study, ref: Reference, meas: MeasurementSet) -> TeamResult:
    """The TEAM run with PDOT time updates; returns a TeamResult over n + 3 augmented states."""
    import time

    if study.filter_kind == "wls" or study.square_root:  # refused when the study is built (fracas.build.team)
        raise ValueError("PDOT propagation supports the Kalman-Schmidt and user filters in covariance form only")
    L = study.layout
    nx, n = L.nx, L.n
    lay = Layout(L.nx, L.ns, L.nu, L.nv, L.nw + 3)
    K = study.schedule.n
    t = ref.times_s
    # nodes: for each interval, 2N+1 equally spaced points (ends nudged inside the interval),
    # on pieces cut at the yaw flips, where the covariance jumps (P+ = S P- S^T)
    flips = yaw_flip_times(study, np.asarray(ref.states[0]), np.asarray(t, np.float64))
    pieces = _interval_pieces(t, pdot_step_bounds(study, ref), flips)
    t0 = time.perf_counter()
    nodes = [tt for piece in pieces for _, _, tt in piece]
    all_t = np.concatenate(nodes) if nodes else np.zeros(0)
    jumps = iter(_flip_jumps(study, ref, flips))
    xs, prim_names = _node_states(study, ref, all_t)
    Fs, Qcs = _noise_models(study, _node_jacobian(study, all_t, xs, prim_names), xs)
    t_nodes = time.perf_counter() - t0

    Pa, Pt = _initial(study)
    H = np.concatenate([meas.H, np.zeros(meas.H.shape[:2] + (3,))], axis=2)
    eye = jnp.eye(n + 3)[None]
    zq = jnp.zeros((1, nx, nx))
    out = {k: [] for k in ("am", "ap", "tm", "tp", "sig")}
    start = 0
    for k in range(K):
        for j, (N, dt_piece, _) in enumerate(pieces[k - 1] if k > 0 else []):
            if j > 0:  # a yaw flip between this piece and the last
                J = jnp.asarray(next(jumps))
                Pa, Pt = J @ Pa @ J.T, J @ Pt @ J.T
            seg = slice(start, start + 2 * N + 1)
            start += 2 * N + 1
            Pa, Pt = _propagate_interval(study, Pa, Pt, N, dt_piece, seg, Fs, Qcs)
        am, ap, tm, tp, sg = _scan(
            Pa,
            Pt,
            eye,
            zq,
            zq,
            jnp.asarray(H[k : k + 1]),
            jnp.asarray(meas.R_assumed[k : k + 1]),
            jnp.asarray(meas.R_true[k : k + 1]),
            layout=lay,
            kind=study.filter_kind,
            gencov=study.gencov,
            square_root=False,
            user_gain=study.user_gain,
        )
        Pa, Pt = ap[0], tp[0]
        for key, v in (("am", am), ("ap", ap), ("tm", tm), ("tp", tp), ("sig", sg)):
            out[key].append(np.asarray(v[0]))
    zeros = np.zeros((K, nx, nx))
    res = TeamResult(
        study,
        ref,
        meas,
        np.array(out["am"]),
        np.array(out["ap"]),
        np.array(out["tm"]) if study.gencov else None,
        np.array(out["tp"]) if study.gencov else None,
        zeros,
        zeros.copy(),
        np.array(out["sig"]),
        noise_states=True,
    )
    tm = {"pdot_nodes_s": t_nodes, "pdot_nodes": int(all_t.size)}
    finish(res, tm)
    return res
