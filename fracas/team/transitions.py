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

Where the pieces live: :mod:`fracas.team.noise_base` (the padded sizes, the noise
partials, DYNO over a batch of intervals), :mod:`fracas.team.noise_cells` (the fixed
cells and the reference at their ends), :mod:`fracas.team.white_acceleration` (white
acceleration noise); this module puts them together and re-exports their names.
"""

from __future__ import annotations

import numpy as np

from fracas.products import ReferenceTrajectory
from fracas.team.noise_base import (
    EPS_T,
    bucket,
    dyno_levels,
    interval_inputs,
    noise_partials,
    pad_rows,
    primary_index,
)
from fracas.team.noise_cells import (
    TIME_MERGE_S,
    _stm_step,
    cell_inputs,
    cell_reference,
    map_cell_noise,
    noise_cell_step,
    stm_cell_step,
)
from fracas.team.pdot_step import pdot_steps
from fracas.team.study import Study
from fracas.team.white_acceleration import (
    WHITE_NODES,
    reference_through_nodes,
    white_noise,
    white_unit_noise,
)

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
    "TIME_MERGE_S",
    "cell_inputs",
    "cell_reference",
    "map_cell_noise",
]


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


def interval_noise(
    study: Study, t: np.ndarray, states: np.ndarray, primary: list[str], phi: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """DYNO's Q̃ (K, nx, nx) over each interval (t_{k-1}, t_k] (element 0 is zero), assumed and true.

    ``phi`` (K, 7, 7): Φ(t_k, t_{k-1}).  Thrust switches are schedule times, so no interval
    straddles one; h is evaluated just inside each interval's ends, which gives zero noise
    on coast intervals (:func:`fracas.team.noise_base.interval_inputs`).
    """
    K, nx = len(t), study.nx
    zeros = np.zeros((K, nx, nx))
    if not study.has_process_noise or K < 2:
        return zeros, zeros.copy()
    wa, wt = white_noise(study, t, np.asarray(states)[0])
    if not study.has_noise:
        return wa, wt
    m, args = interval_inputs(study, t, states, primary, phi)
    out = [np.concatenate([zeros[:1], q]) for q in dyno_levels(study, args, m)]
    return out[0] + wa, out[1] + wt


def grid_noise(
    study: Study, t: np.ndarray, x0: np.ndarray, product: ReferenceTrajectory | None = None
) -> tuple[np.ndarray, np.ndarray]:
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
    args = tuple(pad_rows(ci[key], mp) for key in ("phic", "h0", "h1", "dt"))
    out = [map_cell_noise(ci, qc, K) for qc in dyno_levels(study, args, nc)]
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


def process_noise(study: Study, ref) -> tuple[np.ndarray, np.ndarray]:
    """The effective process noise over the schedule's intervals, assumed and true levels:
    the fixed-cell model (``study.noise_model == "grid"``; from the STM file's grid when the
    reference came from one, :func:`grid_noise`) or FRACAS's per-interval DYNO."""
    if study.noise_model == "interval":
        return interval_noise(study, ref.times_s, ref.states, ref.primary, ref.phi)
    return grid_noise(study, ref.times_s, ref.states[0], getattr(ref, "product", None))


_bucket = bucket  # old private name
