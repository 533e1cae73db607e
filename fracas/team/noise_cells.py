"""The fixed noise cells of TEAM's ``"grid"`` process-noise model (FRACAS DYNO on cells
that do not depend on the events; :mod:`fracas.team.transitions` describes the model).

The cell ends (a grid anchored at the epoch, cut at the thrust switches and the schedule's
first and last times), the cell step a deck's STM file supports, the reference at the cell
ends (from the file, or integrated), what DYNO needs over every cell, and the mapping of
each cell's Q̃ to the next schedule time.  Shared by :func:`fracas.team.transitions.grid_noise`,
the white acceleration noise (:mod:`fracas.team.white_noise`) and the batched sweeps.
"""

from __future__ import annotations

import numpy as np

from fracas.integrate.propagate import propagate_with_sensitivities
from fracas.products import TIME_TOL_S, ReferenceTrajectory, chain, time_indices
from fracas.team.noise_base import EPS_T, bucket, noise_partials
from fracas.team.study import Study

__all__ = [
    "TIME_MERGE_S",
    "noise_cell_step",
    "stm_cell_step",
    "cell_reference",
    "cell_inputs",
    "map_cell_noise",
]

TIME_MERGE_S = 1e-6  # s: a cell end and an event time closer than this are one point


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


def _stm_step(study: Study, data: ReferenceTrajectory, t: np.ndarray) -> float | None:
    """:func:`stm_cell_step` over ``t``'s span, or None when the file also lacks one of ``t``
    or a thrust switch inside the span."""
    t0, t1 = float(t[0]), float(t[-1])
    t_file = np.asarray(data.times_s, np.float64)
    sw = np.array([s for s in study.thrust_switches_s if t0 < s < t1])
    if not (_on_file(t_file, sw) and _on_file(t_file, t)):
        return None
    return stm_cell_step(study, data, t0, t1)
