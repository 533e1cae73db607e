"""PHI mode's exact Gauss-Markov thrust noise (``errcon.process_noise = "exact"``, the default;
issue 24).  FRACAS DYNO's effective Q̃ (``"grid"``, ``"interval"``) stays available.

The three thrust errors eta (proportionality, in-plane, out-of-plane pointing) are carried
by the filter as states appended after the parameters (the ignore block, like PDOT's: the
filter knows them, its gain leaves them alone).  Over each schedule interval the augmented
transition gains the exact blocks Gamma = int Phi(t_k, s) h(s) E(s, t_{k-1}) ds and
E = diag(exp(-dt / tau)), and the exact noise Q over [x, eta]
(:mod:`fracas.filters.gauss_markov`).  Both come from one integration of the reference
(with its STM) through the Gauss nodes of *pieces*: the union of the schedule times, the
thrust switches, the yaw-switch flips (where the STM jumps: ``white_acceleration.cut_at_flips``)
and a grid anchored at the epoch whose step is bounded by the dynamics
(:func:`piece_step`: omega L <= :data:`GM_PIECE_OMEGA`, L <= :data:`GM_PIECE_TAU` tau,
L <= :data:`GM_PIECE_MAX_S`).  The pieces compose exactly, so the answer does not depend
on the events (to the integration's round-off).  h = d xdot / d eta at the nodes comes
from the trajectory core's Jacobians (fracas.integrate.variational.jacobians_at).

The STM file is not read for the nodes (they are inside its grid steps); the integration
is the same one white acceleration noise makes (fracas.team.transitions.white_unit_noise),
so an STM file needs no new contents and no rebuild.  The x block of every transition is
still the STM file's (or the in-line reference's) Phi.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fracas.filters.gauss_markov import GM_NODES, compose, piece_nodes, piece_noise
from fracas.team.study import NOISE_STATE_LABELS, Study
from fracas.team.transitions import TIME_MERGE_S, noise_partials, reference_through_nodes
from fracas.team.white_acceleration import cut_at_flips

__all__ = [
    "GM_PIECE_OMEGA",
    "GM_PIECE_TAU",
    "GM_PIECE_MAX_S",
    "ExactNoise",
    "uses_exact",
    "piece_step",
    "exact_noise",
    "exact_pieces",
    "interval_blocks",
    "augment_transitions",
    "augment_noise",
    "augment_P0",
    "pad_H",
    "augmented_view",
    "augmented_P0",
]

#: Longest piece as a fraction of the orbital time scale 1/omega (omega^2 = mu / r^3 about
#: the primary): G = Phi(b, s) h(s) is interpolated by a degree-7 polynomial on the piece
#: (~4e-10 at omega L = 1; tests/filters/test_gauss_markov.py measures 1e-9 at 0.5).
GM_PIECE_OMEGA = 1.0
#: ... and as a multiple of the shortest correlation time (beta = L / tau <= 2: the kernel
#: weights are exact to round-off up to beta = 4).
GM_PIECE_TAU = 2.0
#: ... and at most a day (steering laws that follow the orbit, throttle ramps).
GM_PIECE_MAX_S = 86400.0


def uses_exact(study: Study) -> bool:
    """Whether the study runs the exact Gauss-Markov model (PHI, "exact", thrust noise on)."""
    return study.propagation == "phi" and study.noise_model == "exact" and study.has_noise


def _live_taus(study: Study) -> np.ndarray:
    taus = np.concatenate([np.ravel(study.noise_tau_assumed), np.ravel(study.noise_tau_true)])
    sig = np.concatenate([np.ravel(study.noise_sigma_assumed), np.ravel(study.noise_sigma_true)])
    return taus[np.isfinite(taus) & (taus > 0) & (sig > 0)]


def piece_step(study: Study, states: np.ndarray, primary) -> float:
    """The grid step of the pieces (s): :data:`GM_PIECE_MAX_S`, capped by GM_PIECE_OMEGA /
    omega at the fastest of ``states`` (7,) about their ``primary`` names and by
    GM_PIECE_TAU times the shortest live correlation time."""
    pr = study.problem
    bodies = list(pr.model.bodies)
    mu = np.asarray(pr.params.mu, float)
    st = np.atleast_2d(np.asarray(states, float))
    r = np.linalg.norm(st[:, :3], axis=1)
    mu_k = np.array([mu[bodies.index(p)] for p in primary])
    om = float(np.max(np.sqrt(mu_k / r**3))) if len(r) else 0.0
    step = GM_PIECE_MAX_S
    if om > 0:
        step = min(step, GM_PIECE_OMEGA / om)
    taus = _live_taus(study)
    if taus.size:
        step = min(step, GM_PIECE_TAU * float(taus.min()))
    return step


def _edges(study: Study, t: np.ndarray, step: float) -> np.ndarray:
    """The piece ends over [t[0], t[-1]]: ``t``, the thrust switches and the grid m * step."""
    t0, t1 = float(t[0]), float(t[-1])
    m0, m1 = int(np.floor(t0 / step)) + 1, int(np.ceil(t1 / step)) - 1
    pts = list(t) + [m * step for m in range(m0, m1 + 1)] + [s for s in study.thrust_switches_s if t0 < s < t1]
    pts = np.array(sorted(p for p in pts if t0 <= p <= t1))
    keep = np.concatenate([[True], np.diff(pts) > TIME_MERGE_S])
    return pts[keep]


@dataclass
class ExactNoise:
    """Per schedule interval (t_{k-1}, t_k] (element 0: none), for the assumed and the true
    levels: gamma (K, nx, 3), E (K, 3), Q (K, nx + 3, nx + 3) (module docstring); pieces:
    how many pieces the span was cut into; piece_step_s: their grid step (s)."""

    gamma_assumed: np.ndarray
    E_assumed: np.ndarray
    Q_assumed: np.ndarray
    gamma_true: np.ndarray
    E_true: np.ndarray
    Q_true: np.ndarray
    pieces: int
    piece_step_s: float


@dataclass
class ExactPieces:
    """What the exact blocks need, for any sigma and tau: the pieces' lengths L (M,) (s),
    G (M, n, nx, 3) = Phi(piece end, node) h(node), Phi over each piece (M, nx, nx), and the
    piece index of every time of ``t`` (its U index); step_s: the pieces' grid step."""

    L: np.ndarray
    G: np.ndarray
    piece_phi: np.ndarray
    where: np.ndarray
    step_s: float


def exact_pieces(study: Study, t: np.ndarray, x0: np.ndarray, states, primary) -> ExactPieces | None:
    """One integration of the reference from ``x0`` (7,) at t[0] through the Gauss nodes of
    every piece of ``t``'s span (``states`` (j, 7) / ``primary`` names along the span bound
    the piece step); None for a span of less than two times."""
    t = np.asarray(t, np.float64)
    step = piece_step(study, states, primary)
    if len(t) < 2 or t[-1] <= t[0]:
        return ExactPieces(np.zeros(0), np.zeros((0, GM_NODES, study.nx, 3)), np.zeros((0, study.nx, study.nx)),
                           np.zeros(len(t), int), step)  # fmt: skip
    U = cut_at_flips(study, x0, _edges(study, t, step), 0.0)  # yaw flips end pieces too
    nodes, L = piece_nodes(U[:-1], U[1:])
    phi_end, piece_phi, xs, prim = reference_through_nodes(study, x0, U, nodes)
    M, n = nodes.shape
    h = noise_partials(study, nodes.ravel(), xs.reshape(-1, 7), prim.ravel()).reshape(M, n, study.nx, 3)
    G = np.einsum("mjab,mjbi->mjai", phi_end, h)
    where = np.abs(U[None, :] - t[:, None]).argmin(axis=1)  # t are edges (merged within TIME_MERGE_S)
    return ExactPieces(L, G, piece_phi, where, step)


def interval_blocks(pieces: ExactPieces, sigma, tau_s):
    """Gamma (K, nx, 3), E (K, 3), Q (K, nx + 3, nx + 3) over each interval of the span's
    times (element 0: none) for noise levels ``sigma`` (3,) and ``tau_s`` (3,) s."""
    K, nx, k = len(pieces.where), pieces.G.shape[2], 3
    gam, E, Q = np.zeros((K, nx, k)), np.ones((K, k)), np.zeros((K, nx + k, nx + k))
    if len(pieces.L) == 0:
        return gam, E, Q
    gam_p, E_p, Q_p = piece_noise(pieces.G, pieces.L, sigma, tau_s)
    w = pieces.where
    for i in range(1, K):
        sl = slice(int(w[i - 1]), int(w[i]))
        if sl.stop > sl.start:
            _, gam[i], E[i], Q[i] = compose(pieces.piece_phi[sl], gam_p[sl], E_p[sl], Q_p[sl])
    return gam, E, Q


def exact_noise(study: Study, t: np.ndarray, x0: np.ndarray, states, primary) -> ExactNoise:
    """The exact Gauss-Markov blocks over every interval of ``t`` (s, increasing), assumed and
    true levels: :func:`exact_pieces` (one integration) then :func:`interval_blocks`."""
    pc = exact_pieces(study, t, x0, states, primary)
    a = interval_blocks(pc, study.noise_sigma_assumed, study.noise_tau_assumed)
    b = interval_blocks(pc, study.noise_sigma_true, study.noise_tau_true)
    return ExactNoise(*a, *b, len(pc.L), pc.step_s)


def augmented_view(study: Study, P0_assumed: np.ndarray, P0_true: np.ndarray) -> Study:
    """The study with the three noise states appended as its own (``gm_states``): layout
    (ignore block + 3), labels, units, roles ``noise_state``, dynamic False, the augmented a
    priori and control a priori (eta stationary at the true sigma).  What guidance events
    and the error budget run on, so their n x n algebra carries the noise states."""
    import dataclasses

    from fracas.filters.covariance import Layout

    L = study.layout
    labels = list(NOISE_STATE_LABELS)
    pc = study.P0_control if study.P0_control is not None else study.P0_true
    pc_aug = augment_P0(pc, study.noise_sigma_true if study.gencov else study.noise_sigma_assumed)
    if study.P0_noise_states is not None:  # punched with the noise states
        got = study.P0_noise_states[2] if len(study.P0_noise_states) > 2 else None
        if got is not None:
            pc_aug = np.array(got)
        elif study.P0_control is None:
            pc_aug = np.array(P0_true)
    return dataclasses.replace(
        study,
        layout=Layout(L.nx, L.ns, L.nu, L.nv, L.nw + 3),
        labels=list(study.labels) + labels,
        roles=list(study.roles) + ["noise_state"] * 3,
        units=list(study.units) + ["1", "rad", "rad"],
        dynamic=np.concatenate([np.asarray(study.dynamic, bool), np.zeros(3, bool)]),
        P0_assumed=np.asarray(P0_assumed),
        P0_true=np.asarray(P0_true),
        P0_control=pc_aug,
        gm_states=True,
    )


def augment_transitions(phi_aug: np.ndarray, gamma: np.ndarray, E: np.ndarray, nx: int) -> np.ndarray:
    """(K, n + 3, n + 3): the study's augmented transitions ``phi_aug`` (K, n, n) with the
    noise states appended: Gamma in the x rows, diag E on their diagonal."""
    K, n = phi_aug.shape[0], phi_aug.shape[1]
    k = gamma.shape[-1]
    out = np.zeros((K, n + k, n + k))
    out[:, :n, :n] = phi_aug
    out[:, :nx, n:] = gamma
    out[:, np.arange(n, n + k), np.arange(n, n + k)] = E
    return out


def augment_noise(Q_gm: np.ndarray, Q_white: np.ndarray, n: int) -> np.ndarray:
    """(K, n + 3, n + 3): the exact Gauss-Markov noise ``Q_gm`` (K, nx + 3, nx + 3) placed on
    the state and noise-state blocks, plus white acceleration noise ``Q_white`` (K, nx, nx)."""
    K, nxk = Q_gm.shape[:2]
    nx = Q_white.shape[-1]
    k = nxk - nx
    out = np.zeros((K, n + k, n + k))
    sel = np.r_[np.arange(nx), np.arange(n, n + k)]
    out[:, sel[:, None], sel[None, :]] = Q_gm
    out[:, :nx, :nx] += Q_white
    return out


def augmented_P0(study: Study, which: int) -> np.ndarray:
    """The study's a priori over n + 3 states (``which`` 0 assumed, 1 true): punched with
    its noise states when the punch file has them, else the noise states appended
    stationary and uncorrelated."""
    if study.P0_noise_states is not None:
        return np.asarray(study.P0_noise_states[which], np.float64)
    P0, sig = (study.P0_assumed, study.noise_sigma_assumed) if which == 0 else (study.P0_true, study.noise_sigma_true)
    return augment_P0(P0, sig)


def augment_P0(P0: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """The a priori with the noise states appended, stationary (diag sigma^2)."""
    n, k = P0.shape[0], len(sigma)
    out = np.zeros((n + k, n + k))
    out[:n, :n] = P0
    out[n:, n:] = np.diag(np.asarray(sigma, float) ** 2)
    return out


def pad_H(H: np.ndarray, k: int = 3) -> np.ndarray:
    """H (K, m, n) with k zero columns for the noise states (no measurement sees them)."""
    return np.concatenate([H, np.zeros(H.shape[:2] + (k,))], axis=2)
