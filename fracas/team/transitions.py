"""Event inputs of the TEAM filter (numpy): augmented transitions and DYNO's effective
process noise over the schedule's intervals (FRACAS PTRAN, PROP eq. 3, DYNO).

Two thrust-noise models for PHI mode (``errcon.process_noise``, ``Study.noise_model``):

- ``"interval"`` (FRACAS): DYNO's Q̃ over each schedule interval (:func:`interval_noise`).
  DYNO's Q̃ is not additive over sub-intervals (Q̃(a, c) != Φ(c, b) Q̃(a, b) Φᵀ + Q̃(b, c)),
  so every event time (eigenvector, prediction, print) changes the answer (by ~1e-3 in σ
  on tests/data/team_small.toml).
- ``"grid"`` (default; :func:`grid_noise`): the noise is computed once on fixed *noise
  cells* that do not depend on the events: a grid of ``noise_step_s`` (or of a multiple of
  it on an STM file's grid, below) anchored at the epoch
  (t = 0), cut at the thrust switches and at the schedule's first and last times.  Each
  cell's DYNO Q̃_c is injected at the cell's end b and mapped to the event times with the
  reference transitions, so the noise over a schedule interval (t_{k-1}, t_k] is
  Q_k = sum over cells ending in it of Φ(t_k, b) Q̃_c Φ(t_k, b)ᵀ.  That sum composes
  exactly (Φ(t_c, t_b) Q(t_a, t_b) Φᵀ + Q(t_b, t_c) = Q(t_a, t_c)), so adding event times
  changes the covariances only at integration round-off (tests/team/test_noise_invariance.py).
  Where the reference, Φ and h at the cell ends come from:

  The study's ``noise_step_s`` is already the deck's cell step (:func:`noise_cell_step`:
  the smallest multiple of ``noise_step_hours`` on the deck's ``[stm] grid_hours``, e.g.
  2 h for a 1 h noise step and a 2 h file grid), so a deck's in-line runs and its runs
  from its own STM file use the same cells.  The reference at the cell ends and event
  times is read from ``Reference.product`` -- the STM file's contents, or the in-line
  reference, which :func:`fracas.team.reference.integrate_reference` integrates once
  through the cell ends -- without integrating (:func:`stm_cell_step` checks that the
  product holds the grid, or takes the first multiple of the step it does hold); states,
  Φ (chained steps, :func:`fracas.products.chain`) and primaries at those times.  Only a
  product without such a grid (another deck's file without ``grid_hours``), or no product,
  integrates the reference again at the union of the cell ends and the event times.
  :func:`noise_settings` says which.

  h is evaluated with the state at each cell end and the time ``EPS_T`` inside the cell
  (as :func:`interval_noise` does): the thrust program is a function of time, so a cell
  that starts at thrust-on or ends at thrust-off sees the thrust on, a coast cell gets
  zero noise; the state itself is continuous at a switch, and moving it by ``EPS_T``
  (~1e-10 relative) is neglected.  Both sources give the same cells for the same step, and
  the same covariances (bit for bit on team_small: the same output times;
  tests/team/test_noise_invariance.py).  The cell step is a modelling choice: DYNO puts a
  cell's noise at its start, so the position part of Q̃ grows with the cell length
  squared (2 h and 1 h cells differ by ~5e-3 in scaled covariance on team_small, by up to
  40 % in early position sigma on Earth-Mars against 4 h intervals), but it is fixed for
  a deck, whatever the events.  Between cell ends the covariance lacks the current cell's noise (at most one
  cell of it).  Chosen over carrying the three noise states through the PHI filter
  (exact, as PDOT does) because it keeps the filter's state, layout and products
  unchanged; PDOT remains the exact model (``errcon.propagation = "pdot"``).

White acceleration noise (UNF s_q, digest unf-apollo.md A.5.4; ``[process_noise]``,
:func:`white_noise`; docs/process_noise.md) is added to either model's Q: the exact
integral Q = int Phi(t_k, s) B q D(s) B^T Phi(t_k, s)^T ds over each interval, by
Gauss-Legendre quadrature (``WHITE_NODES`` points) on pieces of at most
``Study.white_step_s`` (a grid anchored at the epoch, cut at the thrust switches and the
schedule times) with the reference integrated through the nodes.  The integral composes
exactly, so it does not depend on the event times beyond quadrature error.

Shared by the PHI engine, PDOT and prediction events; jitted kernels are compiled once
per padded size (see :func:`bucket`).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from fracas import _jax  # noqa: F401
from fracas.filters.process_noise import dyno_q, gauss_legendre, white_direction, white_q_nodes
from fracas.integrate.propagate import propagate_with_sensitivities
from fracas.integrate.variational import THRUST_NOISE_LABELS, jacobians_at
from fracas.products import TIME_TOL_S, ReferenceTrajectory, chain, time_indices
from fracas.team.pdot_step import pdot_steps
from fracas.team.study import Study

__all__ = [
    "theta_columns",
    "augmented_transitions",
    "bucket",
    "noise_partials",
    "primary_index",
    "interval_noise",
    "grid_noise",
    "stm_cell_step",
    "noise_cell_step",
    "noise_settings",
    "process_noise",
    "white_noise",
    "white_unit_noise",
    "WHITE_NODES",
    "EPS_T",
    "reference_through_nodes",
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
    if not study.has_process_noise or K < 2:
        return zeros, zeros.copy()
    wa, wt = white_noise(study, t, np.asarray(states)[0])
    if not study.has_noise:
        return wa, wt
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
    return out[0] + wa, out[1] + wt


def _noise_cells(study: Study, t0: float, t1: float, step_s: float | None = None) -> np.ndarray:
    """The noise-cell ends in [t0, t1]: t0, the grid m * step_s (default noise_step_s), the
    thrust switches, t1."""
    step = float(study.noise_step_s if step_s is None else step_s)
    m0, m1 = int(np.floor(t0 / step)) + 1, int(np.ceil(t1 / step)) - 1
    pts = [t0, t1] + [m * step for m in range(m0, m1 + 1)] + [s for s in study.thrust_switches_s if t0 < s < t1]
    pts = np.array(sorted(p for p in pts if t0 <= p <= t1))
    keep = np.concatenate([[True], np.diff(pts) > TIME_MERGE_S])
    out = pts[keep]
    out[-1] = t1
    return out


TIME_MERGE_S = 1e-6  # s: a cell end and an event time closer than this are one point


def _on_file(t_file: np.ndarray, pts: np.ndarray) -> bool:
    """Whether every time in ``pts`` is a file time (within TIME_TOL_S)."""
    if pts.size == 0:
        return True
    i = np.clip(np.searchsorted(t_file, pts), 1, len(t_file) - 1)
    d = np.minimum(np.abs(t_file[i] - pts), np.abs(t_file[i - 1] - pts))
    return bool(np.all(d <= TIME_TOL_S))


def _cap(base: float, taus) -> float:
    """The longest cell step considered: the shortest finite correlation time (DYNO's
    alpha = 0 regime), or ``base`` when that is shorter."""
    taus = np.asarray(taus, np.float64).ravel()
    taus = taus[np.isfinite(taus) & (taus > 0)]
    return max(base, float(taus.min())) if taus.size else base


def noise_cell_step(noise_step_s: float, grid_s: float | None, taus_s=()) -> float:
    """A deck's noise-cell step (s): the smallest multiple j * noise_step_s that is a whole
    multiple of its STM file's grid step ``grid_s`` ([stm] grid_hours), so that the deck's
    in-line runs and its runs from its own STM file use the same cells (2 h for a 1 h noise
    step on a 2 h file grid); ``noise_step_s`` itself without a grid, or when no multiple up
    to the shortest correlation time in ``taus_s`` fits (such a file's runs integrate)."""
    base = float(noise_step_s)
    if not grid_s:
        return base
    for j in range(1, max(1, int(np.floor(_cap(base, taus_s) / base * (1 + 1e-12)))) + 1):
        r = j * base / float(grid_s)
        if abs(r - round(r)) <= 1e-9 * max(1.0, r):
            return j * base
    return base


def stm_cell_step(study: Study, data: ReferenceTrajectory, t0: float, t1: float) -> float | None:
    """The noise-cell step an STM file supports over [t0, t1] (s), or None.

    The smallest multiple j * noise_step_s (j = 1, 2, ...; at most the shortest correlation
    time, or noise_step_s when that is shorter) whose every grid point m * j * noise_step_s
    inside (t0, t1) is a file time.  It depends on the file's times and noise_step_s only,
    not on the study's events: a file with a uniform grid ([stm] grid_hours, anchored at
    t = 0 like the noise grid) gives noise_step_s when that is a multiple of the file's
    step, else the first multiple of noise_step_s on the file's grid (Earth-Mars: 2 h file
    grid, 1 h noise step -> 2 h cells).  None (no such grid: the caller integrates) for a
    file without a usable grid.
    """
    t_file = np.asarray(data.times_s, np.float64)
    base = float(study.noise_step_s)
    cap = _cap(base, np.concatenate([np.asarray(study.noise_tau_assumed), np.asarray(study.noise_tau_true)]))
    for j in range(1, max(1, int(np.floor(cap / base * (1 + 1e-12)))) + 1):
        step = j * base
        m = np.arange(np.floor(t0 / step) + 1, np.ceil(t1 / step))
        pts = m * step
        pts = pts[(pts > t0 + TIME_MERGE_S) & (pts < t1 - TIME_MERGE_S)]
        if _on_file(t_file, pts):
            return step
    return None


def _stm_nodes(study: Study, data: ReferenceTrajectory, t: np.ndarray):
    """The noise cells of ``t``'s span on an STM file and the union of cell ends and ``t``
    with the reference at every union time, from the file alone (no integration):
    (cells, U, step_phi (M, nx, nx) Φ(U_i, U_{i-1}), states (M, 7), primary (M,)), or None
    when the file has no usable grid or lacks a thrust switch or one of ``t``."""
    step = _stm_step(study, data, t)
    if step is None:
        return None
    cells = _noise_cells(study, float(t[0]), float(t[-1]), step)
    U = _union(cells, t)
    phi, _ = chain(data, U)
    idx = time_indices(data, U)
    bodies = study.problem.model.bodies
    prim = np.array([bodies.index(data.primary[int(i)]) for i in idx], dtype=np.int32)
    return cells, U, phi[:, : study.nx, : study.nx], np.asarray(data.states, np.float64)[idx], prim


def _union(cells: np.ndarray, t: np.ndarray) -> np.ndarray:
    """The cell ends and the times of ``t`` not within TIME_MERGE_S of one, sorted."""
    near = np.abs(t[:, None] - cells[None, :]).min(axis=1) <= TIME_MERGE_S
    return np.array(sorted(set(cells.tolist()) | set(t[~near].tolist())))


def cell_reference(study: Study, t: np.ndarray, x0: np.ndarray, product: ReferenceTrajectory | None = None):
    """The fixed-cell model's reference: (cells, U, step_phi, xs, prim) — the cell ends, the
    union U of the cell ends and ``t``, Φ over each step of U (nx, nx), the states and
    primary indices at U.  From ``product`` when its grid supports the cells (no
    integration), else ``x0`` (the state at t[0]) integrated over U on cells of noise_step_s."""
    nx = study.nx
    got = _stm_nodes(study, product, t) if product is not None else None
    if got is not None:
        return got
    cells = _noise_cells(study, float(t[0]), float(t[-1]))
    U = _union(cells, t)
    pr = study.problem
    M = len(U)
    Up = np.concatenate([U, np.repeat(U[-1:], bucket(M) - M)])  # a few sizes share one compile
    traj, sens = propagate_with_sensitivities(pr.model, pr.params, pr.ephem, pr.epoch_et_s, x0, Up, ())
    step_phi = np.array(sens.stm_step)[:M, :nx, :nx]
    xs = np.asarray(traj.x)[:M]
    prim = np.asarray(traj.primary)[:M].astype(np.int32)
    return cells, U, step_phi, xs, prim


def cell_inputs(study: Study, t, cells, U, step_phi, xs, prim) -> dict:
    """What DYNO needs over every cell (a, b] and where its noise goes, for any sigma:
    ``phic`` (nc, nx, nx) Φ(b, a) from the union steps, ``h0``/``h1`` the partials just
    inside the ends (the state at the end, the time EPS_T inside: one-sided at the thrust
    switches), ``dt`` (nc,), ``cell_at`` {U index of a cell end: cell}, ``sched`` {U index:
    index in ``t``}.  Shared by :func:`grid_noise` and the batched sweeps."""
    nx = study.nx
    iu = {float(u): i for i, u in enumerate(U)}
    ic = np.array([iu[float(c)] for c in cells])
    nc = len(cells) - 1
    phic = np.broadcast_to(np.eye(nx), (nc, nx, nx)).copy()
    for j in range(nc):
        for i in range(ic[j] + 1, ic[j + 1] + 1):
            phic[j] = step_phi[i] @ phic[j]
    dt = np.diff(cells)
    e = np.minimum(EPS_T, dt / 2)
    t_nodes = np.concatenate([cells[:-1] + e, cells[1:] - e])
    x_nodes = np.concatenate([xs[ic[:-1]], xs[ic[1:]]])
    p_nodes = np.concatenate([prim[ic[:-1]], prim[ic[1:]]])
    h = noise_partials(study, t_nodes, x_nodes, p_nodes)
    sched = {int(np.argmin(np.abs(U - tk))): k for k, tk in enumerate(t)}
    return {
        "nc": nc,
        "phic": phic,
        "h0": h[:nc],
        "h1": h[nc:],
        "dt": dt,
        "U": U,
        "step_phi": step_phi,
        "cell_at": {int(ic[j + 1]): j for j in range(nc)},
        "sched": sched,
    }


def map_cell_noise(ci: dict, qc: np.ndarray, K: int) -> np.ndarray:
    """Q (..., K, nx, nx): the cells' Q̃ ``qc`` (..., nc, nx, nx) mapped from each cell's end
    to the next time of the schedule and summed there (any leading batch shape)."""
    U, step_phi, cell_at, sched = ci["U"], ci["step_phi"], ci["cell_at"], ci["sched"]
    lead, nx = qc.shape[:-3], qc.shape[-1]
    Q = np.zeros(lead + (K, nx, nx))
    acc = np.zeros(lead + (nx, nx))
    for i in range(1, len(U)):
        acc = step_phi[i] @ acc @ step_phi[i].T
        j = cell_at.get(i)
        if j is not None:
            acc = acc + qc[..., j, :, :]
        if i in sched:
            Q[..., sched[i], :, :] = 0.5 * (acc + np.swapaxes(acc, -1, -2))
            acc = np.zeros(lead + (nx, nx))
    return Q


def grid_noise(study: Study, t: np.ndarray, x0: np.ndarray, product: ReferenceTrajectory | None = None):
    """Q (K, nx, nx) over each interval (t_{k-1}, t_k] of the fixed-cell model (element 0 is
    zero), assumed and true: every cell's DYNO Q̃ mapped from its end to t_k (module docstring).

    With ``product`` (the study's STM file) whose grid supports the cells
    (:func:`stm_cell_step`), the cells are that grid's and the states, Φ and primaries at
    the cell ends and ``t`` come from the file: no integration.  Otherwise ``x0`` (7,),
    the reference state at t[0], is integrated afresh over the union of the cell ends and
    ``t`` (NaN where that integration fails) on cells of noise_step_s.
    """
    t = np.asarray(t, dtype=np.float64)
    K, nx = len(t), study.nx
    zeros = np.zeros((K, nx, nx))
    if not study.has_process_noise or K < 2:
        return zeros, zeros.copy()
    wa, wt = white_noise(study, t, x0)
    if not study.has_noise:
        return wa, wt
    cells, U, step_phi, xs, prim = cell_reference(study, t, x0, product)
    ci = cell_inputs(study, t, cells, U, step_phi, xs, prim)
    nc = ci["nc"]
    mp = bucket(nc)
    pad = lambda a: np.concatenate([a, np.zeros((mp - nc,) + a.shape[1:])]) if mp > nc else a  # noqa: E731
    args = (pad(ci["phic"]), pad(ci["h0"]), pad(ci["h1"]))
    out = []
    for sig, tau in (
        (study.noise_sigma_assumed, study.noise_tau_assumed),
        (study.noise_sigma_true, study.noise_tau_true),
    ):
        qc = np.asarray(_dyno_batch(*args, jnp.asarray(sig), jnp.asarray(tau), jnp.asarray(pad(ci["dt"]))))[:nc]
        out.append(map_cell_noise(ci, qc, K))
    return out[0] + wa, out[1] + wt


def noise_settings(study: Study, ref) -> dict:
    """How the run's process noise was made, for the product's settings: the model and, for
    the fixed cells, their step (s) and where the reference at their ends came from:
    "stm_file" (read from the study's STM file), "reference" (the in-line reference,
    integrated once through the cell ends, :func:`fracas.team.reference.integrate_reference`)
    or "integrated" (integrated again for the noise: a file without a usable grid)."""
    white = {}
    if study.has_white_noise:
        white = {
            "white_noise_direction": study.white_direction_assumed,
            "white_noise_step_s": float(study.white_step_s),
        }
        if study.gencov:
            white["white_noise_direction_true"] = study.white_direction_true
    # the noise actually applied, for the printout and the results file (issue 24)
    white["thrust_noise_sigma"] = [float(x) for x in np.ravel(study.noise_sigma_assumed)]
    white["thrust_noise_tau_s"] = [float(x) for x in np.ravel(study.noise_tau_assumed)]
    white["white_noise_km2_s3"] = float(study.white_q_assumed) if study.has_white_noise else 0.0
    if study.propagation == "pdot":
        h = pdot_steps(study, ref)
        if h.size:
            white["pdot_step_min_s"], white["pdot_step_max_s"] = float(h.min()), float(h.max())
        return {"process_noise": "pdot", **white}
    if study.noise_model == "exact":  # its pieces: fracas.team.result adds gm_piece_step_s
        return {"process_noise": "exact", **white}
    if study.noise_model == "interval":
        return {"process_noise": "interval", **white}
    if not study.has_noise and study.has_white_noise:
        return {"process_noise": "grid", **white}
    t = np.asarray(ref.times_s, np.float64)
    product = getattr(ref, "product", None)
    step = _stm_step(study, product, t) if product is not None and len(t) > 1 else None
    if step is not None:
        where = "reference" if ref.source == "integrated" else "stm_file"
        return {"process_noise": "grid", "noise_cells": where, "noise_cell_s": float(step), **white}
    return {"process_noise": "grid", "noise_cells": "integrated", "noise_cell_s": float(study.noise_step_s), **white}


def _stm_step(study: Study, data: ReferenceTrajectory, t: np.ndarray) -> float | None:
    """:func:`stm_cell_step` over ``t``'s span, or None when the file also lacks one of ``t``
    or a thrust switch inside the span."""
    t0, t1 = float(t[0]), float(t[-1])
    t_file = np.asarray(data.times_s, np.float64)
    sw = np.array([s for s in study.thrust_switches_s if t0 < s < t1])
    if not (_on_file(t_file, sw) and _on_file(t_file, t)):
        return None
    return stm_cell_step(study, data, t0, t1)


def process_noise(study: Study, ref) -> tuple[np.ndarray, np.ndarray]:
    """The effective process noise over the schedule's intervals, assumed and true levels:
    the fixed-cell model (``study.noise_model == "grid"``; from the STM file's grid when the
    reference came from one, :func:`grid_noise`) or FRACAS's per-interval DYNO."""
    if study.noise_model == "interval":
        return interval_noise(study, ref.times_s, ref.states, ref.primary, ref.phi)
    return grid_noise(study, ref.times_s, ref.states[0], getattr(ref, "product", None))


# ----------------------------------------------------------------------------- white acceleration noise
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


_bucket = bucket  # old private name
