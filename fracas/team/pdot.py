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
from functools import cache

import jax
import jax.numpy as jnp
import numpy as np

from fracas import _jax  # noqa: F401  (x64 before jax)
from fracas.filters.covariance import Layout
from fracas.filters.process_noise import pdot_propagate, white_direction, white_Qc
from fracas.integrate.propagate import propagate
from fracas.integrate.variational import THRUST_NOISE_LABELS, jacobians_at
from fracas.team.pdot_step import PDOT_OMEGA_STEP, PDOT_TAU_STEP, pdot_step_bounds, pdot_steps
from fracas.team.result import NOISE_STATE_LABELS, TeamResult, finish
from fracas.team.scan import _scan
from fracas.team.study import Study
from fracas.team.transitions import EPS_T, bucket, primary_index

__all__ = ["run_pdot", "pdot_step_bounds", "pdot_steps", "PDOT_OMEGA_STEP", "PDOT_TAU_STEP", "NOISE_STATE_LABELS"]


@cache
def _pdot_fn():
    return jax.jit(pdot_propagate)


def _pad_nodes(a: np.ndarray, extra: int):
    """The node array ``a`` with its last node repeated ``extra`` times (zero-length steps)."""
    return jnp.asarray(np.concatenate([a, np.repeat(a[-1:], extra, axis=0)]))


def _expand(P: np.ndarray, sig: np.ndarray) -> np.ndarray:
    n = P.shape[0]
    out = np.zeros((n + 3, n + 3))
    out[:n, :n] = P
    out[n:, n:] = np.diag(sig**2)  # stationary Gauss-Markov start
    return out


def run_pdot(study: Study, ref, meas):
    """The TEAM run with PDOT time updates; returns a TeamResult over n + 3 augmented states."""
    import time

    if study.filter_kind == "wls" or study.square_root:  # refused when the study is built (fracas.build.team)
        raise ValueError("PDOT propagation supports the Kalman-Schmidt and user filters in covariance form only")
    L = study.layout
    nx, n = L.nx, L.n
    lay = Layout(L.nx, L.ns, L.nu, L.nv, L.nw + 3)
    sched = study.schedule
    K = sched.n
    t = ref.times_s
    h_cap = pdot_step_bounds(study, ref)
    # nodes: for each interval, 2N+1 equally spaced points (ends nudged inside the interval)
    Ns, nodes = [], []
    for k in range(1, K):
        dt = t[k] - t[k - 1]
        N = max(1, int(math.ceil(dt / h_cap[k - 1] - 1e-9)))
        tt = t[k - 1] + dt * np.arange(2 * N + 1) / (2 * N)
        e = min(EPS_T, dt / 4)
        tt[0] += e
        tt[-1] -= e
        Ns.append(N)
        nodes.append(tt)
    t0 = time.perf_counter()
    pr = study.problem
    all_t = np.concatenate(nodes) if nodes else np.zeros(0)
    order = np.argsort(all_t, kind="stable")
    t_sorted = np.concatenate([[t[0]], all_t[order]])
    traj = propagate(pr.model, pr.params, pr.ephem, pr.epoch_et_s, ref.states[0], t_sorted)
    xs = np.empty((all_t.size, 7))
    xs[order] = np.asarray(traj.x)[1:]
    prim_names = np.empty(all_t.size, dtype=object)
    bodies = pr.model.bodies
    prim_names[order] = [bodies[int(i)] for i in np.asarray(traj.primary)[1:]]
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
    t_nodes = time.perf_counter() - t0

    if study.P0_noise_states is not None:  # a punch with the noise states (issue 24)
        Pa, Pt = (jnp.asarray(p) for p in study.P0_noise_states)
    else:
        Pa = jnp.asarray(_expand(study.P0_assumed, study.noise_sigma_assumed))
        Pt = jnp.asarray(_expand(study.P0_true, study.noise_sigma_true))
    H = np.concatenate([meas.H, np.zeros(meas.H.shape[:2] + (3,))], axis=2)
    eye = jnp.eye(n + 3)[None]
    zq = jnp.zeros((1, nx, nx))
    pdot = _pdot_fn()
    out = {k: [] for k in ("am", "ap", "tm", "tp", "sig")}
    start = 0
    for k in range(K):
        if k > 0:
            N = Ns[k - 1]
            seg = slice(start, start + 2 * N + 1)
            start += 2 * N + 1
            # padded to a bucket of steps with zero-length steps: one compiled program per
            # bucket, not one per distinct N (intervals of every length in LEO)
            n_pad = bucket(N, 8)
            dts = np.zeros(n_pad)
            dts[:N] = (t[k] - t[k - 1]) / N

            extra = 2 * (n_pad - N)
            qa, qt = (_pad_nodes(q[seg], extra) if q.ndim == 3 else q for q in Qcs)
            Pa = pdot(Pa, _pad_nodes(Fs[0][seg], extra), qa, jnp.asarray(dts))
            if study.gencov:
                Pt = pdot(Pt, _pad_nodes(Fs[1][seg], extra), qt, jnp.asarray(dts))
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
    tm = {"pdot_nodes_s": t_nodes, "pdot_nodes": int(kk)}
    finish(res, tm)
    return res
